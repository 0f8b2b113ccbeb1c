// libFuzzer target: the HDF5 readers (robomimic's layout: data::ReadTrajectories, ReadStateSet
// on a .h5 file; issue 34). Any input must read or throw secure::Error; a crash, another
// exception, or an allocation over libFuzzer's -rss_limit_mb (a declared size that escaped the
// check before allocation; the input limit is 64 MiB here) is a defect. The corpus holds a small valid file and the 2e9-row bomb.
#include <cstddef>
#include <cstdint>
#include <string>

#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/data/data.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  // An input limit of 64 MiB: a declared size within it is legal, so an allocation of more
  // (libFuzzer's -rss_limit_mb, 2 GB) can only be one that escaped the check.
  static const bool limited = [] {
    InputLimits limits = GetInputLimits();
    limits.max_input_bytes = 64u << 20;
    SetInputLimits(limits);
    return true;
  }();
  (void)limited;
  const std::string& path =
      fuzz::WriteScratch(std::string(reinterpret_cast<const char*>(data), size), ".h5");
  try {
    const data::TrajectorySet set = data::ReadTrajectories(path, {}, {});
    if (set.episode_begin.empty() || set.episode_begin.back() != set.num_steps())
      __builtin_trap();
  } catch (const Error&) {
  }
  try {
    data::ReadStateSet(path, {});
  } catch (const Error&) {
  }
  return 0;
}
