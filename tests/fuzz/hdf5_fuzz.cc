// libFuzzer target: the HDF5 readers (robomimic's layout: data::ReadTrajectories, ReadStateSet
// on a .h5 file; issue 34), through the guard users run (secure/data/hdf5_guard.cc: each read in
// a child process with a memory limit). Any input must read or throw secure::Error; a crash of
// this process, another exception, a hang (-timeout) or an allocation over -rss_limit_mb here is a
// defect. libhdf5's own crashes on malformed files happen in the child and are errors.
//
// The child's coverage does not reach libFuzzer (it lives in the child's copy of the counters),
// and a sanitizer report in the child becomes an error too: SECURE_FUZZ_HDF5_IN_PROCESS=1 fuzzes
// the readers in this process instead (coverage-guided, every finding reported; libhdf5's SEGVs
// included, so it is for a person at the keyboard, not for `make check`).
//
// The corpus holds a small valid file, the 2e9-row bomb and the three libhdf5 findings.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/data/data.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  // An input limit of 64 MiB: a declared size within it is legal, so an allocation of more
  // (libFuzzer's -rss_limit_mb) can only be one that escaped the check. The child may map
  // 512 MiB beyond this process.
  static const bool in_process = [] {
    InputLimits limits = GetInputLimits();
    limits.max_input_bytes = 64u << 20;
    limits.max_hdf5_memory_bytes = 512u << 20;
    SetInputLimits(limits);
    const char* mode = std::getenv("SECURE_FUZZ_HDF5_IN_PROCESS");
    return mode != nullptr && std::string(mode) == "1";
  }();
  const std::string& path =
      fuzz::WriteScratch(std::string(reinterpret_cast<const char*>(data), size), ".h5");
  try {
    const data::TrajectorySet set =
        in_process ? data::internal::ReadHdf5TrajectoriesInProcess(path, {}, {})
                   : data::ReadTrajectories(path, {}, {});
    if (set.episode_begin.empty() || set.episode_begin.back() != set.num_steps() ||
        set.states.cols() != set.actions.cols())
      __builtin_trap();
  } catch (const Error&) {
  }
  try {
    if (in_process) {
      data::internal::ReadHdf5StateSetInProcess(path, {}, "");
    } else {
      data::ReadStateSet(path, {});
    }
  } catch (const Error&) {
  }
  return 0;
}
