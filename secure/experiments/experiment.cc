// The experiment driver (experiment.h): validation, the shared data, the seeds on parallel
// workers (each reused from its task file or run by seed_pipeline.cc), and the result assembled
// across seeds; shards and their merge.
#include "secure/experiments/experiment.h"

#include <algorithm>
#include <filesystem>
#include <memory>
#include <optional>
#include <ostream>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/option_check.h"
#include "secure/common/timer.h"
#include "secure/experiments/internal/numbers.h"
#include "secure/experiments/internal/seed_pipeline.h"
#include "secure/experiments/internal/seed_runner.h"
#include "secure/experiments/internal/task_store.h"
#include "secure/nn/torch_threads.h"

namespace secure::experiments {
namespace {

using internal::Any;
using internal::ExperimentIdentity;
using internal::kTaskFile;
using internal::NeedsBarrier;
using internal::Progress;
using internal::ReusableTask;
using internal::SeedDir;
using internal::SeedOutcome;
using internal::SeedUnits;
using internal::SharedData;
using internal::TaskJson;
using internal::UsesAirlPolicy;

constexpr const char* kOptions = "ExperimentOptions";

// The shared state of a run: validated options, the data (written to output_dir), the result's
// header and the experiment's identity.
struct Prepared {
  ExperimentResult result;
  SharedData shared;
  std::unique_ptr<domains::Environment> env;
  nlohmann::json identity;
};

void Prepare(ExperimentKind kind, const Domain& domain, const ExperimentOptions& o,
             const std::vector<int>& indices, Progress& progress, const Stopwatch& clock,
             Prepared* p) {
  ExperimentResult& result = p->result;
  const std::vector<eval::Method>& methods = result.methods;
  result.kind = kind;
  result.domain = domain.name();
  result.domain_title = domain.Title();
  result.domain_options = domain.OptionsJson();
  result.options = o;
  result.options_json = o.ToJson();

  // 1. Data.
  SharedData& shared = p->shared;
  shared.data = domain.GenerateData(o.data_seed);
  shared.check = o.check_enabled && domain.HasCheck() && Any(methods, NeedsBarrier);
  if (shared.check) {
    domain.CheckHeldOut(o.data_seed, o.check_held_out, &shared.check_safe,
                        &shared.check_near_dangerous);
  }
  const DomainData& data = shared.data;
  result.demonstrations = data.demonstrations.num_episodes();
  result.discarded_demonstrations = data.discarded_demonstrations;
  result.demonstration_steps = data.demonstrations.num_steps();
  result.safe_states = data.safe.size();
  result.near_dangerous_states = data.near_dangerous.size();
  result.data_seconds = clock.Seconds();
  result.variants = kind == ExperimentKind::kSensitivity
                        ? SensitivityVariants(o.data_fractions, o.imbalance_ratios, o.label_noise)
                        : std::vector<BarrierDataVariant>{{"baseline", 1.0, 1, 0.0}};
  p->env = domain.MakeEnvironment();
  p->identity = ExperimentIdentity(result);
  // Task files of another experiment fail before anything is written.
  for (int i : indices)
    ReusableTask(o.output_dir, o.first_seed + static_cast<std::uint64_t>(i), p->identity,
                 result.variants.size());
  // The data, by one shard only: shards may share the directory (on several hosts).
  if (!o.output_dir.empty() && o.shard == 0) {
    data::WriteTrajectories(o.output_dir + "/demos.csv", data.demonstrations);
    data::WriteStateSet(o.output_dir + "/safe.csv", data.safe);
    data::WriteStateSet(o.output_dir + "/near_dangerous.csv", data.near_dangerous);
    if (shared.check) {
      data::WriteStateSet(o.output_dir + "/check_safe.csv", shared.check_safe);
      data::WriteStateSet(o.output_dir + "/check_near_dangerous.csv", shared.check_near_dangerous);
    }
  }
  progress.Line([&](std::ostream& line) {
    line << "data: " << result.demonstrations << " expert demonstrations ("
         << result.discarded_demonstrations << " discarded), " << result.demonstration_steps
         << " steps; " << result.safe_states << " safe and " << result.near_dangerous_states
         << " near-dangerous states (" << clock.Seconds() << " s)";
  });
}

// Validation shared by RunExperiment and RunExperimentShard; returns the methods.
std::vector<eval::Method> CheckRun(ExperimentKind kind, const Domain& domain,
                                   const ExperimentOptions& o) {
  domain.Validate();
  o.Validate();
  CheckExperimentOptions(domain, o);
  const std::vector<eval::Method> methods = o.methods.empty() ? DefaultMethods(kind) : o.methods;
  SECURE_CHECK(
      kind != ExperimentKind::kSensitivity ||
          std::find(methods.begin(), methods.end(), eval::Method::kSecure) != methods.end(),
      "the sensitivity experiment reports SECURE: its methods must include secure");
  SECURE_CHECK(!o.closed_loop.enabled || (Any(methods, UsesAirlPolicy) && Any(methods, NeedsBarrier)),
               "closed_loop.enabled checks SECURE (the AIRL policy under the shield): the methods "
               "must include AIRL and a shielded method");
  // Before any work, so that an unusable --out (a file, a read-only place) fails at once.
  CreateDirectories(o.output_dir);
  return methods;
}

// 2. The seeds of `indices`, on `threads` workers taking the next one: each reused from its task
// file, or computed and its task file written. Returns the outcomes in the order of `indices`.
std::vector<SeedOutcome> RunSeeds(const Domain& domain, const ExperimentOptions& o,
                                  const Prepared& p, const std::vector<int>& indices,
                                  Progress& progress, ShardReport* report) {
  std::vector<SeedOutcome> outcomes(indices.size());
  std::vector<char> reused(indices.size(), 0);
  const int count = static_cast<int>(indices.size());
  const long seed_units = SeedUnits(o, p.result.methods, p.shared, p.result.variants.size());
  progress.Start(count * seed_units, "experiment");
  // RunJobsInParallel labels failures by index: run over positions and name the seed here.
  internal::RunJobsInParallel(
      count, o.threads,
      [&](int k) {
        const std::size_t at = static_cast<std::size_t>(k);
        const std::uint64_t seed = o.first_seed + static_cast<std::uint64_t>(indices[at]);
        try {
          if (std::optional<SeedOutcome> done =
                  ReusableTask(o.output_dir, seed, p.identity, p.result.variants.size())) {
            outcomes[at] = std::move(*done);
            reused[at] = 1;
            progress.Line([&](std::ostream& out) {
              out << "[seed " << seed << "] done before: reused " << SeedDir(o.output_dir, seed)
                  << "/" << kTaskFile;
            });
            progress.Advance(seed_units);
            return;
          }
          outcomes[at] = internal::SeedPipeline(domain, o, p.result.methods, indices[at], p.shared,
                                                *p.env, progress)
                             .Run(p.result.variants);
          if (!o.output_dir.empty()) {
            WriteFileAtomically(
                SeedDir(o.output_dir, seed) + "/" + kTaskFile,
                TaskJson(p.identity, seed, o.threads, p.result.data_seconds, outcomes[at]).dump(2) +
                    "\n");
          }
        } catch (const std::exception& e) {
          SECURE_THROW("seed " << seed << ": " << e.what());
        }
      },
      nullptr, 0);  // the job's errors name the seed
  progress.Finish();
  if (report != nullptr) {
    for (std::size_t k = 0; k < indices.size(); ++k) {
      const std::uint64_t seed = o.first_seed + static_cast<std::uint64_t>(indices[k]);
      (reused[k] ? report->reused : report->computed).push_back(seed);
    }
  }
  return outcomes;
}

// 3. Across seeds (all of them, in order), one evaluation per variant.
void Assemble(std::vector<SeedOutcome> outcomes, ExperimentResult* result) {
  for (std::size_t v = 0; v < result->variants.size(); ++v) {
    eval::Evaluation evaluation(result->options.evaluation);
    for (const SeedOutcome& outcome : outcomes)
      for (const auto& [method, r] : outcome.results[v]) evaluation.Add(method, r);
    evaluation.Finish();
    result->evaluations.emplace_back(
        result->kind == ExperimentKind::kSensitivity ? result->variants[v].name : "main",
        std::move(evaluation));
  }
  for (SeedOutcome& outcome : outcomes)
    result->seed_summaries.push_back(std::move(outcome.summary));
}

}  // namespace

ExperimentResult RunExperiment(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& o, std::ostream* out) {
  ProgressLine line(out, /*live=*/false);
  return RunExperimentWithProgress(kind, domain, o, line);
}

ExperimentResult RunExperimentWithProgress(ExperimentKind kind, const Domain& domain,
                                           const ExperimentOptions& o, ProgressLine& line) {
  SECURE_CHECK(o.shards == 1, "RunExperiment runs every seed (shards = "
                                  << o.shards << "): use RunExperimentShard and MergeExperiment");
  const std::vector<eval::Method> methods = CheckRun(kind, domain, o);
  const Stopwatch clock;
  Progress progress(&line, o.verbose);
  nn::SetTorchThreads(1);  // parallelism comes from the seeds; 1 is fastest for small nets
  std::vector<int> all(static_cast<std::size_t>(o.seeds));
  for (int i = 0; i < o.seeds; ++i) all[static_cast<std::size_t>(i)] = i;
  Prepared p;
  p.result.methods = methods;
  Prepare(kind, domain, o, all, progress, clock, &p);
  std::vector<SeedOutcome> outcomes = RunSeeds(domain, o, p, all, progress, nullptr);
  ExperimentResult& result = p.result;
  Assemble(std::move(outcomes), &result);
  result.seconds = clock.Seconds();
  if (!o.output_dir.empty()) {
    WriteFileAtomically(o.output_dir + "/result.json", result.ToJson().dump(2) + "\n");
    const std::string not_written = WriteEpisodesFile(result, o.output_dir);
    if (!not_written.empty()) progress.Line([&](std::ostream& out) { out << not_written; });
  }
  return std::move(p.result);
}

ShardReport RunExperimentShard(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& o, std::ostream* out) {
  SECURE_CHECK_FIELD(!o.output_dir.empty(), kOptions, "output_dir", "(empty)",
                     "a directory: a shard writes its seeds' task files there");
  const std::vector<eval::Method> methods = CheckRun(kind, domain, o);
  const Stopwatch clock;
  ProgressLine line(out, /*live=*/false);
  Progress progress(&line, o.verbose);
  nn::SetTorchThreads(1);
  std::vector<int> mine;
  for (int i = o.shard; i < o.seeds; i += o.shards) mine.push_back(i);
  Prepared p;
  p.result.methods = methods;
  Prepare(kind, domain, o, mine, progress, clock, &p);
  ShardReport report;
  RunSeeds(domain, o, p, mine, progress, &report);
  report.seconds = clock.Seconds();
  return report;
}

ExperimentResult MergeExperiment(const std::vector<std::string>& run_dirs) {
  const internal::TaskSet set = internal::ReadTaskFiles(run_dirs);
  ExperimentResult result = internal::ResultFromTasks(set);
  std::vector<SeedOutcome> outcomes;
  double seed_seconds = 0.0;
  for (const auto& [seed, entry] : set.tasks) {
    outcomes.push_back(
        internal::OutcomeFromTask(entry.second, entry.first, result.variants.size()));
    result.data_seconds =
        std::max(result.data_seconds, internal::Number(entry.second, "data_seconds"));
    const nlohmann::json stages =
        entry.second["summary"].value("seconds", nlohmann::json::object());
    for (const auto& [stage, seconds] : stages.items())
      if (seconds.is_number()) seed_seconds += seconds.get<double>();
  }
  Assemble(std::move(outcomes), &result);
  result.seconds = result.data_seconds + seed_seconds;
  return result;
}

}  // namespace secure::experiments
