#pragma once
// The experiment driver's task files (task_store.cc): seed-K/task.json, one per finished seed,
// with the experiment's identity and a checksum; reused by a rerun, merged across shards.
// INTERNAL: include only from secure/experiments/*.cc.
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "secure/experiments/experiment.h"
#include "secure/experiments/internal/seed_pipeline.h"

namespace secure::experiments::internal {

constexpr const char* kTaskFile = "task.json";
constexpr int kTaskFormat = 1;

/// A seed's method result as its JSON (eval::SeedResult::ToJson) holds it; an error naming the
/// missing field.
eval::SeedResult SeedResultFromJson(const nlohmann::json& j);

/// <run_dir>/seed-<seed>.
std::string SeedDir(const std::string& run_dir, std::uint64_t seed);

/// What makes two task files tasks of the same experiment (everything that determines a seed's
/// numbers): version, kind, domain and its options, methods, variants, options but `threads`,
/// and the data's counts.
nlohmann::json ExperimentIdentity(const ExperimentResult& r);

/// The task file of a finished seed (with its checksum).
nlohmann::json TaskJson(const nlohmann::json& identity, std::uint64_t seed, int threads,
                        double data_seconds, const SeedOutcome& outcome);

/// The seed's task file when there is one for this experiment (nullopt when there is none); an
/// error naming the file and the first difference when it is a task of another experiment.
std::optional<SeedOutcome> ReusableTask(const std::string& run_dir, std::uint64_t seed,
                                        const nlohmann::json& identity, std::size_t variants);

/// A task file's results and summary; an error naming the file when a count is out of range.
SeedOutcome OutcomeFromTask(const nlohmann::json& task, const std::string& path,
                            std::size_t variants);

/// The task files of the run directories of one experiment's shards, by seed.
struct TaskSet {
  std::map<std::uint64_t, std::pair<std::string, nlohmann::json>> tasks;  // seed -> (path, task)
  std::string first_path;   // the first file read
  nlohmann::json identity;  // its experiment
};
/// Every task file of `run_dirs` (a directory given twice counts once); an error when two are of
/// different experiments, a seed is there twice, there is none, or they are of another format or
/// version.
TaskSet ReadTaskFiles(const std::vector<std::string>& run_dirs);

/// The result's header (kind, domain, methods, variants, data counts, options) from the tasks'
/// experiment, checked to have every one of its seeds exactly once.
ExperimentResult ResultFromTasks(const TaskSet& tasks);

}  // namespace secure::experiments::internal
