// The cost of the HDF5 readers' guard (secure/data/hdf5_guard.cc): reading a file of
// demonstrations through the guard (a child process per read, the arrays back through a pipe)
// against the same reader in this process (internal::ReadHdf5TrajectoriesInProcess). Files of
// 20 demos x 100 steps and 200 demos x 500 steps (4 observation features, 2 actions), written
// by data::WriteTrajectories. Figures: docs/PERFORMANCE.md.
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <filesystem>
#include <string>

#include <Eigen/Core>

#include "secure/data/data.h"

namespace {

// A demonstrations file of `demos` x `steps` in the temporary directory (written once).
std::string DemoFile(long demos, long steps) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("secure-hdf5-bench-" + std::to_string(::getpid()) + "-" +
                             std::to_string(demos) + "x" + std::to_string(steps) + ".h5"))
                               .string();
  if (std::filesystem::exists(path)) return path;
  secure::data::TrajectorySet set;
  set.state_features = {"x", "y", "vx", "vy"};
  set.action_features = {"ax", "ay"};
  set.states = Eigen::MatrixXf::Random(4, demos * steps);
  set.actions = Eigen::MatrixXf::Random(2, demos * steps);
  for (long d = 0; d <= demos; ++d) set.episode_begin.push_back(d * steps);
  secure::data::WriteTrajectories(path, set);
  return path;
}

void BM_ReadGuarded(benchmark::State& state) {
  const std::string path = DemoFile(state.range(0), state.range(1));
  for (auto _ : state) benchmark::DoNotOptimize(secure::data::ReadTrajectories(path, {}, {}));
  state.counters["file_bytes"] = static_cast<double>(std::filesystem::file_size(path));
}

void BM_ReadInProcess(benchmark::State& state) {
  const std::string path = DemoFile(state.range(0), state.range(1));
  for (auto _ : state)
    benchmark::DoNotOptimize(secure::data::internal::ReadHdf5TrajectoriesInProcess(path, {}, {}));
  state.counters["file_bytes"] = static_cast<double>(std::filesystem::file_size(path));
}

BENCHMARK(BM_ReadGuarded)->Args({20, 100})->Args({200, 500})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ReadInProcess)->Args({20, 100})->Args({200, 500})->Unit(benchmark::kMillisecond);

}  // namespace
