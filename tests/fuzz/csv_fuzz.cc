// libFuzzer target: the CSV readers (data::ReadCsv, ReadStateSet, ReadTrajectories).
// Any input must either parse or throw secure::Error; anything else (another exception, a
// sanitizer finding, a crash) is a defect.
#include <cstddef>
#include <cstdint>
#include <string>

#include "secure/common/error.h"
#include "secure/data/data.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  const std::string& path =
      fuzz::WriteScratch(std::string(reinterpret_cast<const char*>(data), size), ".csv");
  try {
    const data::NumericTable table = data::ReadCsv(path);
    // A successful read must be self-consistent.
    if (table.values.rows() != static_cast<long>(table.columns.size()) ||
        table.values.cols() != static_cast<long>(table.lines.size()))
      __builtin_trap();
  } catch (const Error&) {
  }
  try {
    data::ReadStateSet(path, {"x", "y"});
  } catch (const Error&) {
  }
  try {
    const data::TrajectorySet set = data::ReadTrajectories(path, {"x", "y"}, {"ax"});
    if (set.episode_begin.empty() || set.episode_begin.back() != set.num_steps())
      __builtin_trap();
  } catch (const Error&) {
  }
  return 0;
}
