// secure cbf query: active label queries (cbf/query.h) — the k states of a pool a person should
// label next; secure cbf label: a domain's simulated person labels a CSV of states
// (experiments::Domain::Label). The labelled file goes back with `cbf train --augment-from`.
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/query.h"
#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/data/data.h"
#include "secure/experiments/domain.h"

namespace secure::cli {
namespace {

// Writes the chosen pool states: query (rank, 0 = ask first), pool_row (0-based column of the
// pool), the pool's features, h (ensemble: mean; absent without a model), spread, score.
void WriteQueries(const std::string& path, const data::StateSet& pool,
                  const cbf::QueryResult& r, bool with_h) {
  std::vector<std::string> columns{"query", "pool_row"};
  columns.insert(columns.end(), pool.features.begin(), pool.features.end());
  if (with_h) columns.insert(columns.end(), {"h", "spread"});
  columns.push_back("score");
  const long m = static_cast<long>(r.indices.size());
  Eigen::MatrixXd values(static_cast<long>(columns.size()), m);
  for (long j = 0; j < m; ++j) {
    const long i = r.indices[static_cast<std::size_t>(j)];
    long row = 0;
    values(row++, j) = double(j);
    values(row++, j) = double(i);
    for (int f = 0; f < pool.dim(); ++f) values(row++, j) = pool.states(f, i);
    if (with_h) {
      values(row++, j) = r.h(j);
      values(row++, j) = r.spread(j);
    }
    values(row++, j) = r.score(j);
  }
  data::WriteCsv(path, columns, values);
}

struct QueryCommand {
  const Config* config = nullptr;
  std::vector<std::string> models;
  std::string pool_path, out, strategy = "margin", domain;
  cbf::QueryOptions options;
  long episodes = 100;
  std::uint64_t seed = 0;
  bool json = false;

  void Register(CLI::App& cbf) {
    CLI::App* cmd = cbf.add_subcommand(
        "query",
        "Active label queries: the --k states of a pool a person should label next (strategies "
        "margin | disagreement | shield-relevant | diversity | random; docs in secure/cbf/"
        "README.md). Writes them with their features; add a `label` column (1 safe, 0 "
        "near-dangerous, -1 skip) or run `secure cbf label`, then `secure cbf train "
        "--augment-from`");
    cmd->add_option("--model", models,
                    "barrier model file; repeat for an ensemble (disagreement: 2 or more)");
    cmd->add_option("--pool", pool_path,
                    "unlabelled candidate states: a CSV with a header row (or HDF5), every column "
                    "a feature; the model reads its features by name");
    cmd->add_option("--domain", domain,
                    "shield-relevant without --pool: the pool is the states a shielded run of "
                    "this domain visits with the (first) model as barrier: " +
                        DomainsWith(kShieldRun));
    cmd->add_option("--episodes", episodes, "episodes of that shielded run")
        ->capture_default_str();
    cmd->add_option("--k", options.k, "states to propose")->capture_default_str();
    cmd->add_option("--strategy", strategy,
                    "margin | disagreement | shield-relevant | diversity | random")
        ->capture_default_str();
    cmd->add_option("--radius", options.diversity_radius,
                    "diversity radius (pool-standard-deviation units): no two proposed states "
                    "closer; with any strategy (0: off)")
        ->capture_default_str();
    AddSeedOption(cmd, "--seed", &seed, "random and diversity's first state; the shielded run");
    cmd->add_option("--out", out, "CSV of the proposed states")->required();
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    options.strategy = FromString(cbf::kQueryStrategyNames, strategy, "--strategy");
    options.seed = seed;
    options.Validate();
    SECURE_CHECK(!out.empty(), "cbf query: --out is empty");
    std::vector<cbf::BarrierNet> nets;
    for (const std::string& m : models) nets.push_back(cbf::BarrierNet::Load(m));
    data::StateSet pool;
    if (!pool_path.empty()) {
      SECURE_CHECK(domain.empty(), "cbf query: give --pool or --domain, not both");
      pool = data::ReadStateSet(pool_path);
    } else {
      SECURE_CHECK(!domain.empty(), "cbf query: give --pool (or, for shield-relevant, --domain)");
      SECURE_CHECK(options.strategy == cbf::QueryStrategy::kShieldRelevant,
                   "cbf query: --domain gathers the pool of --strategy shield-relevant only");
      SECURE_CHECK(!nets.empty(), "cbf query: --domain needs --model (the shield's barrier)");
      CheckRange("--episodes", episodes, 1, kMaxEpisodes);
      const std::unique_ptr<experiments::Domain> d =
          experiments::DomainRegistry::Global().Make(domain);
      RequireCapability(*d, domain, kShieldRun, "cbf query: ");
      experiments::ShieldRunRequest request = d->ShieldRunPreset();
      request.episodes = episodes;
      request.seed = seed;
      request.record_states = kMaxStates;
      const std::vector<std::string> features = d->MakeEnvironment()->ObservationFeatures();
      const std::unique_ptr<cbf::Barrier> barrier =
          nets[0].MakeEvaluatorFor(features, "the " + domain + " domain", models[0]);
      pool = d->RunShield(request, *barrier).visited;
      SECURE_CHECK(pool.size() >= 1, "cbf query: the shielded run visited no state");
    }
    std::vector<std::unique_ptr<cbf::Barrier>> evaluators;
    std::vector<cbf::Barrier*> barriers;
    for (std::size_t i = 0; i < nets.size(); ++i) {
      evaluators.push_back(
          nets[i].MakeEvaluatorFor(pool.features, pool.source, models[i]));
      barriers.push_back(evaluators.back().get());
    }
    const bool uses_barriers = options.strategy != cbf::QueryStrategy::kDiversity &&
                               options.strategy != cbf::QueryStrategy::kRandom;
    // diversity and random take no barrier; a model given there only fills h (the first).
    if (!uses_barriers && barriers.size() > 1) barriers.resize(1);
    SECURE_CHECK(options.k <= pool.size(), "cbf query: --k " << options.k << " exceeds the "
                                                             << pool.size() << " states of "
                                                             << pool.source);
    const cbf::QueryResult r = cbf::SelectQueries(barriers, pool.states, options);
    WriteQueries(out, pool, r, !barriers.empty());
    if (json) {
      PrintJson({{"command", "cbf query"},
                 {"strategy", strategy},
                 {"pool", pool.source},
                 {"pool_states", pool.size()},
                 {"k", options.k},
                 {"radius", options.diversity_radius},
                 {"proposed", r.indices.size()},
                 {"pool_rows", r.indices},
                 {"out", out}});
    } else {
      std::cout << "proposed " << r.indices.size() << " of " << pool.size() << " states ("
                << strategy << ") -> " << out << "\n";
    }
  }
};

struct LabelCommand {
  std::string domain, states, out;
  std::uint64_t seed = 0;
  bool json = false;

  void Register(CLI::App& cbf) {
    CLI::App* cmd = cbf.add_subcommand(
        "label",
        "A domain's simulated person labels a CSV of states (e.g. `cbf query` output): writes it "
        "with a `label` column (1 safe, 0 near-dangerous, -1 cannot say) for `cbf train "
        "--augment-from`");
    AddDomainOption(cmd, &domain, kLabeller)->required();
    cmd->add_option("--states", states, "CSV of states (the domain's observation features)")
        ->required()
        ->check(CLI::ExistingFile);
    AddSeedOption(cmd, "--seed", &seed, "the person's label noise");
    cmd->add_option("--out", out, "labelled CSV")->required();
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    const std::unique_ptr<experiments::Domain> d =
        experiments::DomainRegistry::Global().Make(domain);
    RequireCapability(*d, domain, kLabeller, "cbf label: ");
    const std::vector<std::string> features = d->MakeEnvironment()->ObservationFeatures();
    const data::NumericTable all = data::ReadCsv(states);
    // The domain's features by name, every column kept in the output.
    const data::StateSet set = data::ReadStateSet(states, features);
    const std::vector<int> labels = d->Label(set.states, seed);
    std::vector<std::string> columns;
    for (const std::string& c : all.columns)
      if (c != cbf::kLabelColumn) columns.push_back(c);
    Eigen::MatrixXd values(static_cast<long>(columns.size()) + 1, all.values.cols());
    long row = 0;
    for (std::size_t c = 0; c < all.columns.size(); ++c)
      if (all.columns[c] != cbf::kLabelColumn) values.row(row++) = all.values.row(static_cast<long>(c));
    long counts[3] = {0, 0, 0};
    for (long i = 0; i < values.cols(); ++i) {
      const int l = labels[static_cast<std::size_t>(i)];
      values(row, i) = l;
      ++counts[l + 1];
    }
    columns.push_back(cbf::kLabelColumn);
    data::WriteCsv(out, columns, values);
    if (json) {
      PrintJson({{"command", "cbf label"},
                 {"domain", domain},
                 {"labeller", d->LabellerDescription()},
                 {"safe", counts[2]},
                 {"near_dangerous", counts[1]},
                 {"cannot_say", counts[0]},
                 {"out", out}});
    } else {
      std::cout << "labelled " << values.cols() << " states (" << counts[2] << " safe, "
                << counts[1] << " near-dangerous, " << counts[0] << " cannot say) -> " << out
                << "\n";
    }
  }
};

}  // namespace

void RegisterCbfQueryCommands(CLI::App& cbf, const Config& config) {
  (void)config;
  static QueryCommand query;
  static LabelCommand label;
  query.Register(cbf);
  label.Register(cbf);
}

}  // namespace secure::cli
