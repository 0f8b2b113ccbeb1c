#include "secure/experiments/reproduce.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <ostream>
#include <sstream>
#include <utility>

#include "secure/common/atomic_file.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/run_lock.h"
#include "secure/common/timer.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/ground_truth_study.h"
#include "secure/experiments/user_study.h"

namespace secure::experiments {
namespace {

// The studies in the order they run per domain, with where the paper has them.
struct StudyInfo {
  const char* name;
  const char* paper;
};
constexpr StudyInfo kStudies[] = {
    {"ground-truth", "Table 1"},      {"method-comparison", "Table 3"},
    {"ablation", "Figure 9"},         {"sensitivity", "Section 6.3"},
    {"joint", "Section 4.1 (joint)"}, {"user-study", "Table 4"},
};

bool IsStudy(const std::string& name) {
  return std::any_of(std::begin(kStudies), std::end(kStudies),
                     [&](const StudyInfo& s) { return name == s.name; });
}

std::string StudyList() {
  std::string list;
  for (const StudyInfo& s : kStudies) list += (list.empty() ? "" : ", ") + std::string(s.name);
  return list;
}

bool Wanted(const std::vector<std::string>& filter, const std::string& name) {
  return filter.empty() || std::find(filter.begin(), filter.end(), name) != filter.end();
}

// Whether `domain` (quick or full: the capabilities do not depend on the profile) runs `study`.
bool Declares(const Domain& domain, const std::string& study) {
  if (study == "ground-truth") return domain.HasGroundTruth();
  if (study == "user-study") return domain.HasPopulation();
  const std::vector<std::string> declared = domain.PaperExperiments();
  const bool listed = std::find(declared.begin(), declared.end(), study) != declared.end();
  if (study == "method-comparison") return listed || domain.PaperReference().has_value();
  return listed;
}

// What a one-task study records about its options: a rerun reuses its study.json only if the
// plan is the same.
nlohmann::json GroundTruthPlan(const Domain& d, const GroundTruthStudyOptions& o,
                               const std::string& profile) {
  return {{"study", "ground-truth"},     {"domain", d.name()},
          {"profile", profile},          {"domain_options", d.OptionsJson()},
          {"seeds", o.seeds},            {"first_seed", o.first_seed},
          {"safe", o.n_safe},            {"unsafe", o.n_unsafe},
          {"trainer", o.trainer.ToJson()}, {"ground_truth", d.GroundTruthJson()}};
}

GroundTruthStudyOptions GroundTruthOptionsFor(const Domain& d, Profile profile) {
  GroundTruthStudyOptions o;  // the paper's Table 1 protocol: 5 seeds of 800 + 800 states
  o.trainer = d.GroundTruthTrainerPreset();
  if (profile == Profile::kQuick) {
    o.seeds = 2;
    o.n_safe = o.n_unsafe = 300;
    o.trainer.max_epochs = std::min(o.trainer.max_epochs, 40);
  }
  return o;
}

std::optional<nlohmann::json> ReadJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception&) {
    return std::nullopt;  // a torn or foreign file: the study runs again and replaces it
  }
}

// A one-task study: reused from dir/study.json if its plan matches, else run and recorded.
// `run` returns (result JSON, Markdown table).
template <typename Run>
void RunOneTaskStudy(const ReproduceTask& task, const nlohmann::json& plan, Run run,
                     ReproduceTaskReport* report) {
  const std::string path = task.dir + "/study.json";
  if (const std::optional<nlohmann::json> old = ReadJson(path);
      old && old->is_object() && old->value("plan", nlohmann::json()) == plan) {
    report->status = "reused";
    report->table = old->value("table", "");
    return;
  }
  auto [result, table] = run();
  WriteFileAtomically(path, nlohmann::json{{"plan", plan}, {"table", table}, {"result", result}}
                                    .dump(2) +
                                "\n");
  report->status = "computed";
  report->table = std::move(table);
}

std::string SeedList(const std::vector<std::uint64_t>& seeds) {
  if (seeds.empty()) return "none";
  std::ostringstream out;
  for (std::size_t i = 0; i < seeds.size(); ++i) out << (i ? " " : "") << seeds[i];
  return out.str();
}

void RunTask(const ReproduceTask& task, std::size_t index, const DomainRegistry& registry,
             const ReproduceOptions& o, std::ostream* progress, ReproduceTaskReport* report) {
  const bool sharded = o.shards > 1;
  const std::string profile = o.profile == Profile::kQuick ? "quick" : "full";
  if (!task.seed_tasks && sharded && static_cast<int>(index % std::size_t(o.shards)) != o.shard) {
    report->status = "other shard";
    return;
  }
  const std::unique_ptr<Domain> d = registry.Make(task.domain, o.profile);
  d->Validate();
  CreateDirectories(task.dir);
  // One run per directory; the shards of a seed-task study share it.
  const RunDirectoryLock lock(task.dir, task.seed_tasks && sharded ? o.shard : 0,
                              task.seed_tasks && sharded ? o.shards : 1);
  if (task.study == "ground-truth") {
    GroundTruthStudyOptions gt = GroundTruthOptionsFor(*d, o.profile);
    gt.validation.threads = o.threads;
    gt.progress = o.verbose;
    RunOneTaskStudy(task, GroundTruthPlan(*d, gt, profile), [&] {
      const GroundTruthStudyResult r = RunGroundTruthStudy(*d, gt);
      return std::pair{r.ToJson(), r.Table()};
    }, report);
    return;
  }
  if (task.study == "user-study") {
    UserStudyOptions us = UserStudyOptions::From(d->Preset(), o.profile);
    us.threads = o.threads;
    us.verbose = o.verbose;
    us.output_dir = task.dir;
    const nlohmann::json plan = {{"study", "user-study"}, {"domain", d->name()},
                                 {"profile", profile}, {"domain_options", d->OptionsJson()},
                                 {"options", us.ToJson()}};
    RunOneTaskStudy(task, plan, [&] {
      const UserStudyResult r = RunUserStudy(*d, us, progress);
      return std::pair{r.ToJson(), r.Table()};
    }, report);
    return;
  }
  const ExperimentKind kind = FromString(kExperimentKindNames, task.study, "study");
  ExperimentOptions options = d->Preset();
  options.threads = o.threads;
  options.verbose = o.verbose;
  options.output_dir = task.dir;
  if (sharded) {
    options.shard = o.shard;
    options.shards = o.shards;
  }
  options.Validate();  // (the driver checks the options against the domain)
  if (sharded) {
    const ShardReport shard = RunExperimentShard(kind, *d, options, progress);
    report->status = "shard " + std::to_string(o.shard) + "/" + std::to_string(o.shards) +
                     ": computed seeds " + SeedList(shard.computed) + ", reused " +
                     SeedList(shard.reused);
    return;
  }
  // Unsharded: every seed's task file is reused where a shard or an earlier run wrote it.
  const ExperimentResult r = RunExperiment(kind, *d, options, progress);
  report->status = "computed (seeds resumed from task files where present)";
  report->table = r.Table();
}

}  // namespace

void ReproduceOptions::Validate(const DomainRegistry& registry) const {
  SECURE_CHECK(!out.empty(), "reproduce: the output directory (--out) is required");
  for (const std::string& d : domains)
    SECURE_CHECK(registry.Has(d), "reproduce: --domain '" << d << "' is not registered (one of: "
                                                          << registry.NameList() << ")");
  for (const std::string& s : studies)
    SECURE_CHECK(IsStudy(s), "reproduce: --study '" << s << "', must be one of: " << StudyList());
  SECURE_CHECK(threads >= 1 && threads <= 1024,
               "reproduce: --threads = " << threads << ", must be in [1, 1024]");
  SECURE_CHECK(shards >= 1 && shard >= 0 && shard < shards,
               "reproduce: shard " << shard << "/" << shards << ", expected 0 <= k < N");
}

std::vector<ReproduceTask> PlanReproduce(const DomainRegistry& registry,
                                         const ReproduceOptions& options) {
  std::vector<ReproduceTask> plan;
  for (const std::string& name : registry.Names()) {
    if (!Wanted(options.domains, name)) continue;
    const std::unique_ptr<Domain> d = registry.Make(name, options.profile);
    for (const std::string& declared : d->PaperExperiments())
      SECURE_CHECK(IsStudy(declared) && declared != "ground-truth" && declared != "user-study",
                   "domain " << name << ": PaperExperiments() lists '" << declared
                             << "', not one of: method-comparison, ablation, sensitivity, joint");
    for (const StudyInfo& s : kStudies) {
      if (!Wanted(options.studies, s.name) || !Declares(*d, s.name)) continue;
      ReproduceTask t;
      t.domain = name;
      t.study = s.name;
      t.paper = s.paper;
      t.dir = (std::filesystem::path(options.out) / name / s.name).string();
      t.seed_tasks = t.study != "ground-truth" && t.study != "user-study";
      plan.push_back(std::move(t));
    }
  }
  return plan;
}

nlohmann::json ReproduceReport::ToJson() const {
  nlohmann::json tasks_json = nlohmann::json::array();
  for (const ReproduceTaskReport& t : tasks) {
    tasks_json.push_back({{"domain", t.task.domain},
                          {"study", t.task.study},
                          {"paper", t.task.paper},
                          {"dir", t.task.domain + "/" + t.task.study},
                          {"status", t.status},
                          {"seconds", t.seconds},
                          {"table", t.table}});
  }
  return {{"command", "reproduce"}, {"profile", profile}, {"shard", shard},
          {"shards", shards},       {"seconds", seconds}, {"tasks", tasks_json}};
}

std::string ReproduceReport::Summary() const {
  std::ostringstream out;
  out << "| domain | study | paper | status | seconds |\n|---|---|---|---|---:|\n";
  out.setf(std::ios::fixed);
  out.precision(1);
  for (const ReproduceTaskReport& t : tasks)
    out << "| " << t.task.domain << " | " << t.task.study << " | " << t.task.paper << " | "
        << t.status << " | " << t.seconds << " |\n";
  return out.str();
}

ReproduceReport RunReproduce(const DomainRegistry& registry, const ReproduceOptions& options,
                             std::ostream* progress) {
  options.Validate(registry);
  const Stopwatch timer;
  const std::vector<ReproduceTask> plan = PlanReproduce(registry, options);
  SECURE_CHECK(!plan.empty(), "reproduce: no registered domain declares a study of the paper "
                              "among the chosen domains and studies");
  ReproduceReport report;
  report.shard = options.shard;
  report.shards = options.shards;
  report.profile = options.profile == Profile::kQuick ? "quick" : "full";
  CreateDirectories(options.out);
  for (std::size_t i = 0; i < plan.size(); ++i) {
    ReproduceTaskReport r;
    r.task = plan[i];
    if (progress != nullptr && options.verbose)
      *progress << "reproduce [" << i + 1 << "/" << plan.size() << "] " << r.task.study << " ("
                << r.task.paper << ") on " << r.task.domain << " -> " << r.task.dir << "\n";
    const Stopwatch task_timer;
    try {
      RunTask(plan[i], i, registry, options, progress, &r);
    } catch (const Error& e) {
      SECURE_THROW("reproduce: " << r.task.study << " on " << r.task.domain << " ("
                                 << r.task.dir << "): " << e.what());
    }
    r.seconds = task_timer.Seconds();
    report.tasks.push_back(std::move(r));
  }
  report.seconds = timer.Seconds();
  if (options.shards == 1)
    WriteFileAtomically(options.out + "/reproduce.json", report.ToJson().dump(2) + "\n");
  return report;
}

}  // namespace secure::experiments
