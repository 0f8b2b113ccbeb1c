#pragma once
// `secure reproduce`: every experiment of the paper on every registered domain that declares it,
// each into a run directory of its own, DIR/<domain>/<study>/, so that a killed run resumes, a
// run shards across machines, and the shards merge (docs/CLUSTER.md).
//
// The studies and which domains run them (from the registry and the domains' capabilities; no
// domain is named here):
//   ground-truth       Table 1 (Section 5)     every domain with a ground truth (HasGroundTruth)
//   method-comparison  Table 3's rows          every domain with the paper's Table 3 numbers
//                                              (PaperReference)
//   ablation           Figure 9                the domains that list it in PaperExperiments()
//   sensitivity        Section 6.3             the same
//   joint              Section 4.1 (joint      the same
//                      optimisation)
//   user-study         Table 4 (Section 7.2)   every domain with participants (HasPopulation)
// Each with the domain's preset for the profile (full: the paper's protocol; quick: the small
// profile the tests use).
//
// Runs. The experiment kinds (method-comparison, ablation, sensitivity, joint) are seed tasks of
// experiments::RunExperiment: their task files (seed-K/task.json) make a rerun resume, and a
// shard k/N runs the seeds k mod N of every one of them (RunExperimentShard). The ground-truth
// study and the user study are one task each: shard k/N runs those whose place in the plan is
// k mod N; a finished one is reused from its study.json (when the plan's options match). An
// unsharded run after the shards (in the same DIR, or in a DIR the shards' directories were
// copied into) reuses every task and writes each run's result.json and DIR/reproduce.json: the
// plan, what each task did, and each study's Markdown table (beside the paper's numbers where the
// domain has them), which `secure report DIR` turns into one page.
//
//   experiments::ReproduceOptions o;
//   o.out = "paper";
//   o.profile = experiments::Profile::kQuick;
//   const experiments::ReproduceReport r =
//       experiments::RunReproduce(experiments::DomainRegistry::Global(), o, &std::cerr);
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/experiments/domain.h"

namespace secure::experiments {

/// One study of one domain, and where it runs.
struct ReproduceTask {
  std::string domain;  // the registry name
  std::string study;   // "ground-truth" | "method-comparison" | "ablation" | "sensitivity" |
                       // "joint" | "user-study"
  std::string paper;   // where the paper has it: "Table 1", "Table 3", "Figure 9", ...
  std::string dir;     // out/<domain>/<study>
  bool seed_tasks = false;  // an experiment kind: sharded by seed (else: one task)
};

struct ReproduceOptions {
  std::string out;  // the parent directory of every run (required)
  Profile profile = Profile::kFull;
  std::vector<std::string> domains;  // only these (registry names); empty: every domain
  std::vector<std::string> studies;  // only these studies; empty: every study
  int threads = 2;                   // seeds (participants) in parallel within a run
  int shard = 0, shards = 1;         // this process's shard (see the header comment)
  bool verbose = true;               // progress lines

  /// @throws secure::Error naming the field and value (an unknown domain or study among them).
  void Validate(const DomainRegistry& registry) const;
};

/// The tasks of `options` (domains and studies filtered), in the order they run: by domain name,
/// then in the order of the header's list. @throws secure::Error if a domain declares an unknown
/// study in PaperExperiments(), naming the domain and the value.
std::vector<ReproduceTask> PlanReproduce(const DomainRegistry& registry,
                                         const ReproduceOptions& options);

/// What one task did in this process.
struct ReproduceTaskReport {
  ReproduceTask task;
  std::string status;  // "computed", "reused", "shard k/N: computed seeds ..., reused ...",
                       // "other shard"
  double seconds = 0;
  std::string table;   // the study's Markdown table (an unsharded run; empty otherwise)
};

struct ReproduceReport {
  std::vector<ReproduceTaskReport> tasks;
  int shard = 0, shards = 1;
  std::string profile;  // "full" | "quick"
  double seconds = 0;

  /// {"command": "reproduce", "profile", "shard", "shards", "seconds", "tasks": [{domain, study,
  /// paper, dir (relative to out), status, seconds, table}]}: DIR/reproduce.json.
  nlohmann::json ToJson() const;
  /// One Markdown row per task: domain, study, paper, status, seconds.
  std::string Summary() const;
};

/// Runs the plan's tasks (those of options.shard when sharded). An unsharded run writes
/// out/reproduce.json. @throws secure::Error on invalid options, or naming the task whose run
/// failed.
ReproduceReport RunReproduce(const DomainRegistry& registry, const ReproduceOptions& options,
                             std::ostream* progress);

}  // namespace secure::experiments
