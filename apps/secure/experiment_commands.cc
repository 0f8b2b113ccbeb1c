// The experiments as commands, on any registered domain (secure/experiments/experiment.h):
//   secure experiment KIND --domain NAME   KIND: method-comparison | joint | ablation | sensitivity
//   secure experiment derby-table3 | derby-joint | derby-ablation | derby-sensitivity
//                                          aliases: KIND on the derby domain
//   secure demo                            the main job: the method comparison on the double
//                                          integrator with every method (BC, AIRL, SECURE, the
//                                          two shield ablations, BC + shield)
//   secure experiment merge RUN_DIR...    the result of a sharded run (docs/CLUSTER.md)
//   secure experiment user-study           the 2 x 2 user study of Section 7.2 with simulated
//                                          participants, on a domain that has them
//                                          (experiments/user_study.h)
// Each prints a Markdown table (or, with --json, the result document in the format of
// `secure eval --json`); --quick is the domain's small profile, used by the tests.
// --shard k/N (or, without it, a SLURM array element's or an mpirun rank's place) runs only the
// seeds with index = k (mod N), writing their task files into --out; `merge` assembles them.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "shard_flag.h"
#include "secure/common/atomic_file.h"
#include "secure/common/enum_strings.h"
#include "secure/common/filesystem.h"
#include "secure/common/progress.h"
#include "secure/common/run_lock.h"
#include "secure/experiments/config_section.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/user_study.h"

namespace secure::cli {
namespace {

using experiments::ExperimentKind;

std::string SeedList(const std::vector<std::uint64_t>& seeds) {
  if (seeds.empty()) return "none";
  std::ostringstream out;
  for (std::size_t i = 0; i < seeds.size(); ++i) out << (i ? ", " : "") << seeds[i];
  return out.str();
}

// The paper's Table 3 numbers of the result's domain, for a method comparison of a registered
// domain that has them (Domain::PaperReference).
std::optional<experiments::PaperTable3> PaperReferenceOf(
    const experiments::ExperimentResult& result) {
  if (result.kind != ExperimentKind::kMethodComparison) return std::nullopt;
  const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
  if (!registry.Has(result.domain)) return std::nullopt;
  return registry.Make(result.domain, experiments::Profile::kQuick)->PaperReference();
}

std::string Percent(double mean, double std) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(1);
  s << mean;
  if (!std::isnan(std)) s << " (" << std << ")";
  return s.str();
}

// The run beside the paper, in the paper's Table 3 form: a success and a dangerous row for this
// run and for the paper, columns BC, AIRL, SECURE and SECURE's difference to AIRL.
std::string PaperFormTable(const experiments::ExperimentResult& result,
                           const experiments::PaperTable3& paper) {
  const auto& methods = result.evaluations.front().second.methods();
  auto ours = [&](eval::Method m, bool success) -> std::pair<double, double> {
    const auto it = methods.find(m);
    if (it == methods.end()) return {std::nan(""), std::nan("")};
    const stats::SampleSummary& r = success ? it->second.success_rate : it->second.dangerous_rate;
    return {100 * r.mean, 100 * r.std};
  };
  auto theirs = [&](const std::string& m, bool success) -> std::pair<double, double> {
    for (const experiments::PaperTable3Row& row : paper.rows)
      if (row.method == m)
        return success ? std::pair{row.success, row.success_std}
                       : std::pair{row.dangerous, row.dangerous_std};
    return {std::nan(""), std::nan("")};
  };
  auto cell = [](std::pair<double, double> v) {
    return std::isnan(v.first) ? std::string("-") : Percent(v.first, v.second);
  };
  auto diff = [](double a, double b) {
    if (std::isnan(a) || std::isnan(b)) return std::string("-");
    std::ostringstream s;
    s.setf(std::ios::fixed | std::ios::showpos);
    s.precision(1);
    s << a - b << " points";
    return s.str();
  };
  std::ostringstream out;
  out << "Beside the paper (" << paper.source << "), Table 3's form:\n\n"
      << "| " << result.domain_title << " | BC | AIRL | SECURE | SECURE vs AIRL |\n"
      << "|---|---|---|---|---|\n";
  for (const bool success : {true, false}) {
    const char* rate = success ? "Success rate %" : "Dangerous rate %";
    const auto s = ours(eval::Method::kSecure, success), a = ours(eval::Method::kAirl, success);
    out << "| " << rate << " (this run) | " << cell(ours(eval::Method::kBc, success)) << " | "
        << cell(a) << " | " << cell(s) << " | " << diff(s.first, a.first) << " |\n";
    const auto ps = theirs("secure", success), pa = theirs("airl", success);
    out << "| " << rate << " (paper) | " << cell(theirs("bc", success)) << " | " << cell(pa)
        << " | " << cell(ps) << " | " << diff(ps.first, pa.first) << " |\n";
  }
  if (!paper.comparison.empty()) out << "\nThe paper's comparison: " << paper.comparison << "\n";
  return out.str();
}

// What an unsharded run prints on stdout (and merge prints).
void PrintResult(const experiments::ExperimentResult& result, bool json,
                 const std::string& command_name) {
  const std::optional<experiments::PaperTable3> paper = PaperReferenceOf(result);
  if (json) {
    nlohmann::json r = result.ToJson();
    r["command"] = command_name;
    if (paper) r["paper"] = experiments::PaperTable3Json(*paper);
    PrintJson(r);
  } else {
    std::cout << "\n"
              << result.Table() << "\nData: " << result.demonstrations << " expert demonstrations ("
              << result.discarded_demonstrations << " discarded), " << result.safe_states
              << " safe + " << result.near_dangerous_states << " near-dangerous states. Total "
              << result.seconds << " s.\n";
    if (paper) std::cout << "\n" << PaperFormTable(result, *paper);
  }
}

struct ExperimentCommand {
  std::string command_name;  // "demo", "experiment ablation", ...
  ExperimentKind kind = ExperimentKind::kMethodComparison;
  std::string domain;        // fixed for the aliases, else from --domain
  bool all_methods = false;  // demo: every method of eval::AllMethods()
  bool quick = false;
  bool json = false;
  int seeds = 0;
  long episodes = 0;
  std::uint64_t first_seed = 0;
  int threads = 2;
  std::string barrier, methods, out, shard;
  std::string progress = "auto";
  int closed_loop_candidates = 0;  // --closed-loop N (absent: the config's closed_loop section)
  CLI::Option* closed_loop_option = nullptr;
  int repair_rounds = 0;  // --closed-loop-repair R
  CLI::Option* repair_option = nullptr;
  int barrier_ensemble = 1;  // --barrier-ensemble K (absent: the config's barrier.ensemble)
  CLI::Option* ensemble_option = nullptr;
  const Config* config = nullptr;
  CLI::Option* seeds_option = nullptr;
  CLI::Option* methods_option = nullptr;
  CLI::Option* episodes_option = nullptr;
  shield::ShieldOptions shield;  // bound to the shield flags; given ones override the config
  ShieldFlags shield_flags;

  CLI::App* Register(CLI::App& parent, const Config& cfg, const std::string& name,
                     const std::string& description, ExperimentKind which,
                     const std::string& fixed_domain) {
    kind = which;
    domain = fixed_domain;
    config = &cfg;
    command_name = (parent.get_name() == "experiment" ? "experiment " : "") + name;
    CLI::App* cmd = parent.add_subcommand(name, description);
    AddConfigFlag(cmd, cfg);
    if (fixed_domain.empty()) AddDomainOption(cmd, &domain)->required();
    cmd->add_flag("--quick", quick,
                  "the domain's small profile (2 seeds, few episodes, short training)");
    seeds_option = cmd->add_option(
        "--seeds", seeds,
        "seeds, at most " + std::to_string(kMaxSeeds) +
            " (default: the domain's preset, `secure domains NAME [--quick]`)");
    episodes_option = cmd->add_option("--episodes", episodes,
                                      "episodes per method and seed, at most " +
                                          std::to_string(kMaxEpisodes) +
                                          " (default: the domain's preset, `secure domains NAME "
                                          "[--quick]`)");
    AddSeedOption(cmd, "--first-seed", &first_seed, "seeds first-seed, first-seed + 1, ...");
    cmd->add_option("--threads", threads, "seeds run in parallel")->capture_default_str();
    cmd->add_option("--barrier", barrier,
                    "flat (an MLP on the whole state) or per-obstacle (alias per-car: one MLP "
                    "per obstacle, the minimum over those in range) (default: the domain's)");
    methods_option = cmd->add_option("--methods", methods,
                    "comma-separated subset of bc, airl, secure, secure-random-safe, "
                    "secure-no-resampling, bc+shield, secure-myopic, joint, cbf-qp, secure-qp, first-safe, cbf-grad "
                    "(default: the "
                    "experiment's)");
    cmd->add_option("--out", out,
                    "directory for the data, per-seed models and learning curves, result.json, "
                    "episodes.csv (per-episode outcomes)")
        ->transform(DirectoryPath());
    cmd->add_option("--shard", shard,
                    "k/N: run only the seeds with index k mod N (0-based; needs --out), then "
                    "`secure experiment merge`; default: a SLURM array element's or an mpirun "
                    "rank's place (docs/CLUSTER.md)");
    closed_loop_option = cmd->add_option("--closed-loop", closed_loop_candidates,
                    "N: the closed-loop check before deployment, trying up to N training "
                    "initialisations per seed (kinds method-comparison, ablation; thresholds "
                    "in the config's closed_loop section; docs/RESULTS.md); 0: off. Default: "
                    "the domain's preset (`secure domains NAME`; on in panda-push's)");
    repair_option = cmd->add_option(
        "--closed-loop-repair", repair_rounds,
        "R: with --closed-loop, repair a failing candidate up to R times before replacing it: "
        "the states before its dangerous steps join the near-dangerous states and its barrier "
        "is retrained (closed_loop.repair_rounds)");
    ensemble_option = cmd->add_option(
        "--barrier-ensemble", barrier_ensemble,
        "K: a flat barrier is the minimum over K barriers trained from different "
        "initialisations on the same labels (barrier.ensemble; 1: one barrier)");
    shield_flags.Add(cmd, &shield, /*domain_preset=*/true);  // `secure domains NAME` lists it
    cmd->add_flag("--json", json, "print the result document (as `secure eval --json`)");
    AddProgressOption(cmd, &progress);
    cmd->callback([this] { Run(); });
    return cmd;
  }

  void Run() {
    config->Check();
    // A given --seeds / --episodes must be usable (0 is not "the default").
    if (seeds_option->count() > 0) CheckRange("--seeds", seeds, 1, kMaxSeeds);
    if (episodes_option->count() > 0) CheckRange("--episodes", episodes, 1, kMaxEpisodes);
    const std::unique_ptr<experiments::Domain> d = experiments::DomainRegistry::Global().Make(
        domain, quick ? experiments::Profile::kQuick : experiments::Profile::kFull);
    // The domain's config section (experiments::ReadSection), then the flags given.
    experiments::ExperimentOptions options =
        experiments::ReadSection(config->root, config->path, *d);
    if (all_methods) options.methods = eval::AllMethods();
    options.shield = OverlayShieldFlags(options.shield, shield_flags, &shield);
    if (seeds_option->count() > 0) options.seeds = seeds;
    if (episodes_option->count() > 0) options.episodes = episodes;
    // An empty --methods '' is an error, not the defaults (issue 34).
    SECURE_CHECK(methods_option->count() == 0 || !methods.empty(),
                 "--methods is empty: give at least one method (or leave the flag out for the "
                 "experiment's)");
    if (!methods.empty()) options.methods = eval::ParseMethods(methods);
    if (closed_loop_option->count() > 0) {
      CheckRange("--closed-loop", closed_loop_candidates, 0, 64);
      options.closed_loop.enabled = closed_loop_candidates > 0;
      if (closed_loop_candidates > 0) options.closed_loop.max_candidates = closed_loop_candidates;
    }
    if (repair_option->count() > 0) {
      CheckRange("--closed-loop-repair", repair_rounds, 0, 16);
      SECURE_CHECK(options.closed_loop.enabled,
                   "--closed-loop-repair needs the closed-loop check (--closed-loop N, or "
                   "closed_loop: {enabled: true} in the config)");
      options.closed_loop.repair_rounds = repair_rounds;
    }
    if (!barrier.empty()) {
      options.barrier_kind = barrier == "per-car"
                                 ? experiments::BarrierKind::kPerObstacle
                                 : FromString(experiments::kBarrierKindNames, barrier, "--barrier");
    }
    if (ensemble_option->count() > 0) {
      CheckRange("--barrier-ensemble", barrier_ensemble, 1, cbf::kMaxBarrierEnsemble);
      SECURE_CHECK(options.barrier_kind == experiments::BarrierKind::kFlat,
                   "--barrier-ensemble needs a flat barrier (the " << d->name()
                                                                   << " domain's is per-obstacle)");
      options.flat_barrier.ensemble = barrier_ensemble;
    }
    options.first_seed = first_seed;
    options.threads = threads;
    options.output_dir = out;
    const Shard where = ResolveShard(shard);
    const bool sharded = where.count > 1;
    SECURE_CHECK(!sharded || !out.empty(),
                 "shard " << where.index << "/" << where.count << " (from " << where.source
                          << ") needs --out: every shard writes its seeds' task files there, "
                             "then `secure experiment merge` assembles the result");
    if (sharded) {
      options.shard = where.index;
      options.shards = where.count;
    }
    d->Validate();  // before the first line of progress
    options.Validate();
    experiments::CheckExperimentOptions(*d, options);
    CreateDirectories(out);  // (also done by the run) an unusable --out fails before any output
    // One run per directory (shards of one experiment share it): a second one fails at once.
    std::optional<RunDirectoryLock> lock;
    if (!out.empty()) lock.emplace(out, sharded ? where.index : 0, sharded ? where.count : 1);
    if (!where.source.empty())
      std::cerr << "shard " << where.index << "/" << where.count << " (from " << where.source
                << "): ";
    std::cerr << "secure " << command_name << " on " << d->name() << ": " << options.seeds
              << " seeds x " << options.episodes << " episodes per method on " << options.threads
              << " threads" << (out.empty() ? "" : ", writing to " + out) << "\n";
    if (sharded) {
      const experiments::ShardReport report =
          experiments::RunExperimentShard(kind, *d, options, &std::cerr);
      if (json) {
        PrintJson({{"command", command_name},
                   {"shard", where.index},
                   {"shards", where.count},
                   {"shard_from", where.source},
                   {"computed_seeds", report.computed},
                   {"reused_seeds", report.reused},
                   {"out", out},
                   {"seconds", report.seconds}});
      } else {
        std::cout << "shard " << where.index << "/" << where.count << ": seeds "
                  << SeedList(report.computed) << " computed, " << SeedList(report.reused)
                  << " reused, task files in " << out << "/seed-K/task.json (" << report.seconds
                  << " s). When every shard is done: secure experiment merge " << out << "\n";
      }
      return;
    }
    ProgressLine line(&std::cerr, ProgressIsLive(progress));
    const experiments::ExperimentResult result =
        experiments::RunExperimentWithProgress(kind, *d, options, line);
    PrintResult(result, json, command_name);
  }
};

// secure experiment merge RUN_DIR... [--out DIR] [--json]
struct MergeCommand {
  std::vector<std::string> dirs;
  std::string out;
  bool json = false;

  void Register(CLI::App& parent) {
    CLI::App* cmd = parent.add_subcommand(
        "merge",
        "The result of a sharded experiment (--shard, a SLURM array, mpirun): checks that the "
        "task files of RUN_DIR... (the shards' --out directories, or the one they shared) are "
        "of one experiment, with every seed once, and writes result.json, episodes.csv and the table an "
        "unsharded run writes");
    cmd->add_option("run_dirs", dirs, "the shards' run directories")
        ->required()
        ->transform(DirectoryPath());
    cmd->add_option("--out", out,
                    "where to write result.json and episodes.csv (default: the first RUN_DIR)")
        ->transform(DirectoryPath());
    cmd->add_flag("--json", json, "print the result document (as `secure eval --json`)");
    cmd->callback([this] { Run(); });
  }

  // The shards' seed-K directories (models, learning curves) as symbolic links in `target`, so
  // that the merged run directory is one that `secure report` draws completely. A name that
  // exists in `target` already is left alone. Returns the number of links made.
  int LinkSeedDirectories(const std::string& target) const {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path target_canonical = fs::canonical(target, ec);
    int linked = 0;
    for (const std::string& dir : dirs) {
      const fs::path canonical = fs::canonical(dir, ec);
      if (ec || canonical == target_canonical) continue;
      for (const auto& entry : fs::directory_iterator(canonical)) {
        const std::string name = entry.path().filename().string();
        if (name.rfind("seed-", 0) != 0 || !entry.is_directory()) continue;
        const fs::path link = fs::path(target) / name;
        if (fs::exists(fs::symlink_status(link))) continue;
        fs::create_directory_symlink(entry.path(), link, ec);
        SECURE_CHECK(!ec, "merge: cannot link " << link.string() << " -> "
                                                 << entry.path().string() << ": "
                                                 << ec.message());
        ++linked;
      }
    }
    return linked;
  }

  void Run() {
    // Every run directory must be there before anything is made (the first is the default
    // --out: creating it would turn "no such directory" into "no task file").
    for (const std::string& dir : dirs) {
      std::error_code ec;
      const auto status = std::filesystem::status(dir, ec);
      SECURE_CHECK(std::filesystem::exists(status),
                   "merge: run directory '" << dir << "' does not exist (expected the --out "
                                            << "directory of a shard)");
      SECURE_CHECK(std::filesystem::is_directory(status),
                   "merge: '" << dir << "' is not a directory (expected the --out directory "
                              << "of a shard)");
    }
    const std::string target = out.empty() ? dirs.front() : out;
    CreateDirectories(target);
    const RunDirectoryLock lock(target);  // not while a run (or a shard) still writes there
    const experiments::ExperimentResult result = experiments::MergeExperiment(dirs);
    WriteFileAtomically(target + "/result.json", result.ToJson().dump(2) + "\n");
    const std::string episodes_not_written = experiments::WriteEpisodesFile(result, target);
    const int linked = LinkSeedDirectories(target);
    // Directories named twice (SH0 ./SH0) count once, as the merge reads them once.
    std::vector<std::filesystem::path> distinct;
    for (const std::string& d : dirs) {
      std::error_code ec;
      const std::filesystem::path c = std::filesystem::canonical(d, ec);
      if (std::find(distinct.begin(), distinct.end(), c) == distinct.end()) distinct.push_back(c);
    }
    std::cerr << "secure experiment merge: " << result.options.seeds << " seeds of "
              << ToString(experiments::kExperimentKindNames, result.kind) << " on " << result.domain
              << " from " << distinct.size() << " director"
              << (distinct.size() == 1 ? "y" : "ies")
              << ", wrote " << target << "/result.json"
              << (episodes_not_written.empty() ? " and " + target + "/" +
                                                     experiments::kEpisodesFile
                                               : std::string());
    if (linked > 0)
      std::cerr << " and linked " << linked << " seed director" << (linked == 1 ? "y" : "ies")
                << " of the shards into it (seed-K -> SHARD/seed-K: the models and curves "
                   "`secure report` draws)";
    std::cerr << "\n";
    if (!episodes_not_written.empty())
      std::cerr << "secure experiment merge: " << episodes_not_written << "\n";
    PrintResult(result, json, "experiment merge");
  }
};

// secure experiment user-study [--domain NAME] [--participants N] [--episodes N] [--seed S]
//   [--spread LIST] [--quick] [--json] [--out DIR] [--threads N]
struct UserStudyCommand {
  std::string domain;  // default: the first registered domain with participants
  bool quick = false, json = false, grouped_matched = false;
  int participants = 0, threads = 2;
  long episodes = 0;
  std::uint64_t seed = 0;
  std::string spread, out;
  const Config* config = nullptr;
  CLI::Option *participants_option = nullptr, *episodes_option = nullptr;

  void Register(CLI::App& parent, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = parent.add_subcommand(
        "user-study",
        "The user study of Section 7.2 (Table 4) with simulated participants: policy data "
        "individual vs grouped x barrier data individual vs grouped, per participant on their own "
        "episodes; Friedman and Holm-corrected Wilcoxon tests across participants");
    AddConfigFlag(cmd, cfg);
    cmd->add_option("--domain", domain,
                    "a domain with participants (default: the first registered one): " +
                        DomainsWith(kPopulation));
    cmd->add_flag("--quick", quick, "the small profile (3 participants x 3 episodes, small data)");
    participants_option = cmd->add_option("--participants", participants,
                                          "participants, 2 to 1000 (default 12)");
    episodes_option = cmd->add_option(
        "--episodes", episodes, "episodes per participant and condition (default 20)");
    AddSeedOption(cmd, "--seed", &seed, "the participants, their data, training and episodes");
    cmd->add_option("--spread", spread,
                    "threshold spreads, comma-separated values in [0, 1] (the participants' "
                    "comfort distances and maximum tilts about their mean scaled by it; several "
                    "values: the sweep), default 1");
    cmd->add_flag("--grouped-matched", grouped_matched,
                  "subsample the grouped data to one participant's size (default: all "
                  "participants' data pooled, as the paper)");
    cmd->add_option("--threads", threads, "parallel jobs")->capture_default_str();
    cmd->add_option("--out", out, "directory for result.json")->transform(DirectoryPath());
    cmd->add_flag("--json", json, "print the result document");
    cmd->callback([this] { Run(); });
  }

  static std::vector<double> ParseSpreads(const std::string& text) {
    std::vector<double> values;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
      std::size_t used = 0;
      double v = std::nan("");
      try {
        v = std::stod(item, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      SECURE_CHECK(used == item.size() && !item.empty() && std::isfinite(v) && v >= 0 && v <= 1,
                   "--spread '" << text << "': '" << item
                                << "' is not a number in [0, 1] (expected e.g. 0,0.5,1)");
      values.push_back(v);
    }
    SECURE_CHECK(!values.empty() && text.back() != ',',
                 "--spread '" << text << "': expected comma-separated numbers in [0, 1]");
    return values;
  }

  void Run() {
    config->Check();
    if (participants_option->count() > 0) CheckRange("--participants", participants, 2, 1000);
    if (episodes_option->count() > 0) CheckRange("--episodes", episodes, 1, 100000);
    CheckRange("--threads", threads, 1, 1024);
    const std::vector<double> spreads =
        spread.empty() ? std::vector<double>{1.0} : ParseSpreads(spread);
    const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    const experiments::Profile profile =
        quick ? experiments::Profile::kQuick : experiments::Profile::kFull;
    if (domain.empty()) {
      for (const std::string& name : registry.Names())
        if (registry.Make(name, profile)->HasPopulation()) {
          domain = name;
          break;
        }
      SECURE_CHECK(!domain.empty(), "no registered domain has participants for a user study");
    }
    const std::unique_ptr<experiments::Domain> d = registry.Make(domain, profile);
    SECURE_CHECK(d->HasPopulation(), "--domain " << domain
                                                 << ": the domain has no participants for a "
                                                    "user study (Domain::HasPopulation)");
    const experiments::ExperimentOptions preset =
        experiments::ReadSection(config->root, config->path, *d);
    experiments::UserStudyOptions options = experiments::UserStudyOptions::From(preset, profile);
    if (participants_option->count() > 0) options.participants = participants;
    if (episodes_option->count() > 0) options.episodes = episodes;
    options.seed = seed;
    options.spreads = spreads;
    options.grouped_matched = grouped_matched;
    options.threads = threads;
    options.output_dir = out;
    d->Validate();
    options.Validate();
    CreateDirectories(out);
    std::optional<RunDirectoryLock> lock;
    if (!out.empty()) lock.emplace(out);
    std::cerr << "secure experiment user-study on " << d->name() << ": " << options.participants
              << " participants x " << options.episodes << " episodes x 4 conditions, "
              << spreads.size() << " spread(s), on " << options.threads << " threads"
              << (out.empty() ? "" : ", writing to " + out) << "\n";
    const experiments::UserStudyResult result = experiments::RunUserStudy(*d, options, &std::cerr);
    if (json) {
      nlohmann::json j = result.ToJson();
      j["command"] = "experiment user-study";
      PrintJson(j);
    } else {
      std::cout << "\n" << result.Table() << "\nTotal " << result.seconds << " s.\n";
    }
  }
};

}  // namespace

void RegisterExperimentCommands(CLI::App& app, const Config& config) {
  static ExperimentCommand demo;
  static ExperimentCommand kinds[4];
  static ExperimentCommand derby[4];
  static MergeCommand merge;
  static UserStudyCommand user_study;
  demo.all_methods = true;
  demo.Register(app, config, "demo",
                "The main job: the complete SECURE pipeline on the double-integrator reach-avoid "
                "task (demonstrations, learned barrier, BC and AIRL, every method evaluated over "
                "seeds) and its results table",
                ExperimentKind::kMethodComparison, "double-integrator");

  CLI::App* cmd =
      app.add_subcommand("experiment", "The paper's experiments (Section 6) on any domain: " +
                                           experiments::DomainRegistry::Global().NameList());
  cmd->require_subcommand(1);
  const struct {
    ExperimentKind kind;
    const char* alias;
    const char* description;
  } table[4] = {
      {ExperimentKind::kMethodComparison, "derby-table3",
       "Table 3 row: BC, AIRL and SECURE over seeds; Mann-Whitney U and TOST of SECURE against "
       "AIRL"},
      {ExperimentKind::kJoint, "derby-joint",
       "The joint-optimisation baseline (AIRL with the barrier's derivative condition as an "
       "extra loss) next to AIRL and SECURE"},
      {ExperimentKind::kAblation, "derby-ablation",
       "Figure 9: SECURE, random safe action, no adaptive resampling (Kruskal-Wallis + Dunn), "
       "and the myopic test h(T(s, a)) >= 0"},
      {ExperimentKind::kSensitivity, "derby-sensitivity",
       "Section 6.3: SECURE with barriers from reduced, imbalanced and label-flipped data"},
  };
  for (int i = 0; i < 4; ++i) {
    kinds[i].Register(*cmd, config, ToString(experiments::kExperimentKindNames, table[i].kind),
                      table[i].description, table[i].kind, "");
    derby[i].Register(*cmd, config, table[i].alias,
                      std::string(table[i].description) + " (on the derby domain)", table[i].kind,
                      "derby");
  }
  merge.Register(*cmd);
  user_study.Register(*cmd, config);
  RegisterLabelEfficiencyCommand(*cmd, config);
}

}  // namespace secure::cli
