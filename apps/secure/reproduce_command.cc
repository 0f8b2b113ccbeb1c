// secure reproduce --out DIR [--profile full|quick] [--shard k/N] [--domain NAME]...
//   [--study NAME]... [--threads N] [--json] [--list]
// Every experiment of the paper on every registered domain that declares it, each into
// DIR/<domain>/<study>/ (secure/experiments/reproduce.h); then `secure report DIR` makes one page
// of every table. Sharded like `secure experiment` (--shard, a SLURM array, mpirun ranks:
// docs/CLUSTER.md); an unsharded run after the shards reuses their tasks and writes each run's
// result.json and DIR/reproduce.json.
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/run_lock.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/reproduce.h"
#include "shard_flag.h"

namespace secure::cli {
namespace {

struct ReproduceCommand {
  experiments::ReproduceOptions options;
  std::string profile = "full", shard;
  bool json = false, list = false;

  void Register(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand(
        "reproduce",
        "Every experiment of the paper on every registered domain that declares it (Table 1, "
        "Table 3's rows, Figure 9, Section 6.3, the joint optimisation, the user study), each "
        "into DIR/<domain>/<study>/; resumable, shardable; then `secure report DIR`");
    cmd->add_option("--out", options.out, "the parent directory of the runs")
        ->required()
        ->transform(DirectoryPath());
    cmd->add_option("--profile", profile,
                    "full (the paper's protocol: the domains' presets) or quick (their small "
                    "profiles, for tests and smoke runs)")
        ->capture_default_str()
        ->check(CLI::IsMember({"full", "quick"}));
    AddDomainOption(cmd, &options.domains,
                    "only this domain (repeatable; default every registered one)");
    cmd->add_option("--study", options.studies,
                    "only this study (repeatable): ground-truth, method-comparison, ablation, "
                    "sensitivity, joint, user-study");
    cmd->add_option("--threads", options.threads, "seeds (participants) in parallel per run")
        ->capture_default_str();
    cmd->add_option("--shard", shard,
                    "k/N: run shard k of N (the seeds k mod N of every experiment, every N-th "
                    "one-task study); default: a SLURM array element's or an mpirun rank's "
                    "place; afterwards an unsharded run merges (docs/CLUSTER.md)");
    cmd->add_flag("--list", list, "print the plan (domain, study, paper, directory) and exit");
    cmd->add_flag("--json", json, "print DIR/reproduce.json's document");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    options.profile = profile == "quick" ? experiments::Profile::kQuick
                                         : experiments::Profile::kFull;
    const Shard where = ResolveShard(shard);
    options.shard = where.index;
    options.shards = where.count;
    options.Validate(registry);
    const std::vector<experiments::ReproduceTask> plan =
        experiments::PlanReproduce(registry, options);
    if (list) {
      for (const experiments::ReproduceTask& t : plan)
        std::cout << t.domain << " " << t.study << " (" << t.paper << ") " << t.dir << "\n";
      return;
    }
    SECURE_CHECK(!plan.empty(), "reproduce: no registered domain declares a study of the paper "
                                "among the chosen domains and studies");
    CreateDirectories(options.out);
    // The parent directory for this process alone (or shared by the shards of one reproduce).
    const RunDirectoryLock lock(options.out, where.count > 1 ? where.index : 0, where.count);
    if (!where.source.empty())
      std::cerr << "shard " << where.index << "/" << where.count << " (from " << where.source
                << "): ";
    std::cerr << "secure reproduce (" << profile << " profile) into " << options.out << "\n";
    const experiments::ReproduceReport report =
        experiments::RunReproduce(registry, options, &std::cerr);
    if (json) {
      PrintJson(report.ToJson());
      return;
    }
    std::cout << report.Summary();
    if (where.count > 1) {
      std::cout << "\nshard " << where.index << "/" << where.count
                << " done. When every shard is: secure reproduce --out " << options.out
                << " --profile " << profile
                << " (unsharded: reuses the shards' tasks, writes each result.json), then "
                   "secure report "
                << options.out << "\n";
    } else {
      std::cout << "\nwrote " << options.out << "/reproduce.json; the page: secure report "
                << options.out << "\n";
    }
  }
};

}  // namespace

void RegisterReproduceCommand(CLI::App& app) {
  static ReproduceCommand reproduce;
  reproduce.Register(app);
}

}  // namespace secure::cli
