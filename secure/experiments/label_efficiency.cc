#include "secure/experiments/label_efficiency.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <sstream>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/ground_truth_study.h"
#include "secure/experiments/internal/label_efficiency_closed_loop.h"
#include "secure/experiments/internal/seed_runner.h"

namespace secure::experiments {

LabelEfficiencyOptions LabelEfficiencyOptions::For(const Domain& domain, Profile profile) {
  LabelEfficiencyOptions o;
  o.trainer = domain.HasGroundTruth() ? domain.GroundTruthTrainerPreset()
                                      : domain.Preset().flat_barrier;
  o.per_obstacle_trainer = domain.Preset().per_obstacle_barrier;
  if (profile == Profile::kQuick) {
    o.seeds = 2;
    o.pool = 2000;
    o.initial_labels = 10;
    o.rounds = 2;
    o.k = 10;
    o.ensemble = 2;
    o.eval_states = 20000;
    o.final_grid = false;
    o.episodes = 5;
    o.final_episodes = 10;
    o.shield_pool_states = 2000;
    o.shield_pool_episodes = 5;
    o.reference_states = 200;
    o.max_epochs = 300;
    o.trainer.max_epochs = std::min(o.trainer.max_epochs, 30);
    o.per_obstacle_trainer.max_epochs = std::min(o.per_obstacle_trainer.max_epochs, 10);
  }
  return o;
}

void LabelEfficiencyOptions::Validate() const {
  const char* T = "LabelEfficiencyOptions";
  SECURE_CHECK_FIELD(!strategies.empty(), T, "strategies", strategies.size(), "non-empty");
  for (std::size_t i = 0; i < strategies.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      SECURE_CHECK_FIELD(strategies[i] != strategies[j], T, "strategies",
                         ToString(cbf::kQueryStrategyNames, strategies[i]), "listed once");
  SECURE_CHECK_FIELD(seeds >= 1 && seeds <= 10000, T, "seeds", seeds, "in [1, 10000]");
  SECURE_CHECK_FIELD(pool >= 2 && pool <= kMaxStates, T, "pool", pool, ">= 2");
  SECURE_CHECK_FIELD(initial_labels >= 2 && initial_labels <= pool, T, "initial_labels",
                     initial_labels, "in [2, pool]");
  SECURE_CHECK_FIELD(rounds >= 0 && rounds <= 1000, T, "rounds", rounds, "in [0, 1000]");
  SECURE_CHECK_FIELD(std::isfinite(k_growth) && k_growth >= 1 && k_growth <= 10, T, "k_growth",
                     k_growth, "in [1, 10]");
  SECURE_CHECK_FIELD(k >= 1 && LabelsAtTheEnd() <= static_cast<double>(pool), T, "k", k,
                     ">= 1, with initial_labels + the rounds' queries ("
                         << LabelsAtTheEnd() << ") <= pool (" << pool << ")");
  SECURE_CHECK_FIELD(ensemble >= 2 && ensemble <= 64, T, "ensemble", ensemble, "in [2, 64]");
  SECURE_CHECK_FIELD(std::isfinite(radius) && radius >= 0, T, "radius", radius, ">= 0");
  SECURE_CHECK_FIELD(eval_states >= 0 && eval_states <= kMaxStates, T, "eval_states",
                     eval_states, ">= 0");
  SECURE_CHECK_FIELD(episodes >= 0 && episodes <= kMaxEpisodes, T, "episodes", episodes, ">= 0");
  SECURE_CHECK_FIELD(final_episodes >= 0 && final_episodes <= kMaxEpisodes, T, "final_episodes",
                     final_episodes, ">= 0");
  SECURE_CHECK_FIELD(shield_pool_states >= 1 && shield_pool_states <= kMaxStates, T,
                     "shield_pool_states", shield_pool_states, ">= 1");
  SECURE_CHECK_FIELD(shield_pool_episodes >= 1 && shield_pool_episodes <= kMaxEpisodes, T,
                     "shield_pool_episodes", shield_pool_episodes, ">= 1");
  SECURE_CHECK_FIELD(reference_states >= 1 && reference_states <= kMaxStates, T,
                     "reference_states", reference_states, ">= 1");
  SECURE_CHECK_FIELD(max_epochs >= 1 && max_epochs <= 1000000, T, "max_epochs", max_epochs,
                     "in [1, 1000000]");
  SECURE_CHECK_FIELD(threads >= 1 && threads <= 1024, T, "threads", threads, "in [1, 1024]");
  SECURE_CHECK_FIELD(shard_count >= 1 && shard_index >= 0 && shard_index < shard_count, T,
                     "shard_index", shard_index, "in [0, shard_count)");
  trainer.Validate();
  if (barrier_kind == BarrierKind::kPerObstacle) {
    per_obstacle_trainer.Validate();
    SECURE_CHECK_FIELD(per_obstacle_trainer.input.layout.IsSet(), T, "barrier_kind",
                       "per-obstacle", "a domain with an obstacle layout (its per-obstacle barrier)");
  }
}

long LabelEfficiencyOptions::QueriesIn(int round) const {
  return std::llround(static_cast<double>(k) * std::pow(k_growth, round));
}

double LabelEfficiencyOptions::LabelsAtTheEnd() const {
  double labels = static_cast<double>(initial_labels);
  for (int r = 0; r < rounds; ++r)
    labels += std::round(static_cast<double>(k) * std::pow(k_growth, r));
  return labels;
}

nlohmann::json LabelEfficiencyOptions::ToJson() const {
  std::vector<std::string> names;
  for (cbf::QueryStrategy s : strategies) names.push_back(ToString(cbf::kQueryStrategyNames, s));
  nlohmann::json j{{"strategies", names},
          {"seeds", seeds},
          {"first_seed", first_seed},
          {"pool", pool},
          {"initial_labels", initial_labels},
          {"rounds", rounds},
          {"k", k},
          {"ensemble", ensemble},
          {"radius", radius},
          {"eval_states", eval_states},
          {"final_grid", final_grid},
          {"episodes", episodes},
          {"final_episodes", final_episodes},
          {"shield_pool_states", shield_pool_states},
          {"shield_pool_episodes", shield_pool_episodes},
          {"trainer", trainer.ToJson()},
          {"reference_states", reference_states},
          {"max_epochs", max_epochs}};
  // Absent at their defaults: the job files of older runs stay valid.
  if (errors_from_labeller) j["errors_from_labeller"] = true;
  if (k_growth != 1) j["k_growth"] = k_growth;
  if (barrier_kind == BarrierKind::kPerObstacle) {
    j["barrier_kind"] = ToString(kBarrierKindNames, barrier_kind);
    j["per_obstacle_trainer"] = per_obstacle_trainer.ToJson();
  }
  if (!policies_from.empty()) j["policies_from"] = policies_from;
  return j;
}

nlohmann::json LabelEfficiencyPoint::ToJson() const {
  return {{"round", round},
          {"labels", labels},
          {"safe_labels", safe_labels},
          {"near_dangerous_labels", near_dangerous_labels},
          {"over_conservative", over},
          {"under_conservative", under},
          {"dangerous", dangerous},
          {"success", success},
          {"episodes", episodes}};
}

nlohmann::json LabelEfficiencyCurve::ToJson() const {
  nlohmann::json points_json = nlohmann::json::array();
  for (const LabelEfficiencyPoint& p : points) points_json.push_back(p.ToJson());
  nlohmann::json j{{"strategy", strategy}, {"seed", seed}, {"points", points_json},
                   {"seconds", seconds}};
  if (final_grid) j["final_grid"] = final_grid->ToJson();
  if (!closed_loop.is_null()) j["closed_loop"] = closed_loop;
  if (strategy == ToString(cbf::kQueryStrategyNames, cbf::QueryStrategy::kShieldRelevant))
    j["margin_rounds"] = margin_rounds;
  return j;
}

LabelEfficiencyCurve LabelEfficiencyCurve::FromJson(const nlohmann::json& j) {
  LabelEfficiencyCurve c;
  c.strategy = j.at("strategy").get<std::string>();
  c.seed = j.at("seed").get<std::uint64_t>();
  c.seconds = j.at("seconds").get<double>();
  c.margin_rounds = j.value("margin_rounds", 0);
  for (const nlohmann::json& p : j.at("points")) {
    LabelEfficiencyPoint q;
    q.round = p.at("round").get<int>();
    q.labels = p.at("labels").get<long>();
    q.safe_labels = p.at("safe_labels").get<long>();
    q.near_dangerous_labels = p.at("near_dangerous_labels").get<long>();
    q.over = p.at("over_conservative").get<double>();
    q.under = p.at("under_conservative").get<double>();
    q.dangerous = p.at("dangerous").get<double>();
    q.success = p.at("success").get<double>();
    q.episodes = p.at("episodes").get<long>();
    c.points.push_back(q);
  }
  if (j.contains("final_grid")) {
    const nlohmann::json& g = j["final_grid"].at("counts");
    cbf::Confusion conf;
    conf.safe_as_safe = g.at("safe_as_safe").get<long>();
    conf.safe_as_unsafe = g.at("safe_as_unsafe").get<long>();
    conf.unsafe_as_safe = g.at("unsafe_as_safe").get<long>();
    conf.unsafe_as_unsafe = g.at("unsafe_as_unsafe").get<long>();
    c.final_grid = conf;
  }
  if (j.contains("closed_loop")) c.closed_loop = j["closed_loop"];
  return c;
}

namespace {

// Streams of a seed (salts keep them apart from each other and from the domain's data).
std::uint64_t Stream(std::uint64_t seed, std::uint64_t salt) {
  return (seed * 0x9e3779b97f4a7c15ULL) ^ salt;
}

data::StateSet Columns(const data::StateSet& from, const std::vector<long>& cols) {
  data::StateSet s;
  s.source = from.source;
  s.features = from.features;
  s.states.resize(from.dim(), static_cast<long>(cols.size()));
  for (std::size_t j = 0; j < cols.size(); ++j)
    s.states.col(static_cast<long>(j)) = from.states.col(cols[j]);
  return s;
}

void Append(data::StateSet* to, const Eigen::Ref<const Eigen::VectorXf>& state) {
  to->states.conservativeResize(Eigen::NoChange, to->size() + 1);
  to->states.col(to->size() - 1) = state;
}

struct Job {
  const Domain& domain;
  const LabelEfficiencyOptions& options;
  cbf::QueryStrategy strategy;
  std::uint64_t seed;
  const data::StateSet& pool;
  const data::StateSet& eval;           // states for the ground-truth estimate (may be empty)
  const Eigen::VectorXd& eval_truth;    // their ground-truth h (or labeller: +1 safe, -1
                                        // near-dangerous, NaN cannot say)
  std::vector<std::string> features;    // the domain's observation features

  // The preset's gradient steps on reference_states states, whatever the labels' count.
  template <typename Trainer>
  Trainer Scaled(Trainer t, long labels, std::uint64_t training_seed) const {
    t.seed = training_seed;
    t.verbose = false;
    t.threads = 1;
    const double steps_per_epoch_ref = std::ceil(double(options.reference_states) / t.batch_size);
    const double steps_per_epoch =
        std::ceil(double(labels) * (1 - t.validation_fraction) / t.batch_size);
    const double epochs = std::ceil(t.max_epochs * steps_per_epoch_ref / std::max(1.0, steps_per_epoch));
    t.max_epochs = static_cast<int>(std::clamp(epochs, double(t.max_epochs), double(options.max_epochs)));
    t.max_epochs = std::max(t.max_epochs, 1);
    return t;
  }

  internal::SeedBarrier Train(const data::StateSet& safe, const data::StateSet& near,
                              std::uint64_t training_seed) const {
    const long labels = safe.size() + near.size();
    internal::SeedBarrier b;
    if (options.barrier_kind == BarrierKind::kPerObstacle) {
      cbf::CarBarrierTrainingSummary summary;
      b.per_obstacle = cbf::TrainCarBarrier(
          Scaled(options.per_obstacle_trainer, labels, training_seed), safe, near, &summary);
    } else {
      cbf::BarrierTrainingSummary summary;
      b.flat = cbf::TrainBarrier(Scaled(options.trainer, labels, training_seed), safe, near,
                                 &summary);
    }
    return b;
  }

  // Table 1's over- and under-conservative rates of `barrier` on the estimate states (against
  // the ground truth, or the person's answers; states the person cannot say are skipped).
  void Errors(cbf::Barrier& barrier, LabelEfficiencyPoint* p) const {
    Eigen::VectorXf h(eval.size());
    barrier.Evaluate(eval.states, h);
    long ts = 0, tu = 0, over = 0, under = 0;
    for (long i = 0; i < eval.size(); ++i) {
      if (std::isnan(eval_truth(i))) continue;  // the person cannot say
      const bool truly_safe = eval_truth(i) >= 0, predicted_safe = h(i) >= 0;
      if (truly_safe) {
        ++ts;
        over += !predicted_safe;
      } else {
        ++tu;
        under += predicted_safe;
      }
    }
    p->over = ts > 0 ? 100.0 * double(over) / double(ts) : 0.0;
    p->under = tu > 0 ? 100.0 * double(under) / double(tu) : 0.0;
  }

  // The round's closed loop: SECURE on the run's policy (`loop`), else the domain's shield run;
  // at the last round with `loop`, AIRL and SECURE over the run's barrier beside it.
  void ClosedLoop(const internal::SeedBarrier& net, cbf::Barrier& barrier,
                  const internal::RunPolicyLoop* loop, long episodes, bool last,
                  LabelEfficiencyPoint* p, LabelEfficiencyCurve* curve) const {
    p->episodes = episodes;
    if (loop != nullptr) {
      const eval::SeedResult r = loop->Secure(net, episodes);
      p->dangerous = 100.0 * r.dangerous_rate();
      p->success = 100.0 * r.success_rate();
      if (last)
        curve->closed_loop = {{"secure", r.ToJson()},
                              {"airl", loop->Airl(episodes).ToJson()},
                              {"secure_full_labels", loop->SecureFullLabels(episodes).ToJson()}};
      return;
    }
    ShieldRunRequest request = domain.ShieldRunPreset();
    request.episodes = episodes;
    request.seed = Stream(seed, 0xe7a1ULL);  // the same episodes for every strategy and round
    const ShieldRunReport report = domain.RunShield(request, barrier);
    const double e = double(report.json.value("episodes", episodes));
    p->dangerous = 100.0 * report.json.value("dangerous_episodes", 0L) / e;
    p->success = 100.0 * report.json.value("success_episodes", 0L) / e;
  }

  LabelEfficiencyCurve Run() const {
    const Stopwatch clock;
    LabelEfficiencyCurve curve;
    curve.strategy = ToString(cbf::kQueryStrategyNames, strategy);
    curve.seed = seed;
    const long n = pool.size();
    std::vector<char> asked(static_cast<std::size_t>(n), 0);
    data::StateSet safe{"labelled safe", pool.features, Eigen::MatrixXf(pool.dim(), 0)};
    data::StateSet near{"labelled near-dangerous", pool.features, Eigen::MatrixXf(pool.dim(), 0)};
    long labels = 0;
    const auto add = [&](const Eigen::Ref<const Eigen::MatrixXf>& states) {
      const std::vector<int> l = domain.Label(states, Stream(seed, 0x1abe1ULL) + labels);
      for (long i = 0; i < states.cols(); ++i) {
        if (l[static_cast<std::size_t>(i)] == 1) Append(&safe, states.col(i));
        if (l[static_cast<std::size_t>(i)] == 0) Append(&near, states.col(i));
      }
      labels += states.cols();
    };
    // The initial labels: the same random pool states for every strategy of the seed.
    {
      std::vector<long> order(static_cast<std::size_t>(n));
      std::iota(order.begin(), order.end(), 0L);
      Rng rng(Stream(seed, 0x1417ULL));
      Shuffle(order.begin(), order.end(), rng);
      long used = 0;
      std::vector<long> first(order.begin(), order.begin() + options.initial_labels);
      for (long i : first) asked[static_cast<std::size_t>(i)] = 1;
      add(Columns(pool, first).states);
      used = options.initial_labels;
      while ((safe.size() == 0 || near.size() == 0) && used < n) {
        const long i = order[static_cast<std::size_t>(used++)];
        asked[static_cast<std::size_t>(i)] = 1;
        add(pool.states.col(i));
      }
      SECURE_CHECK(safe.size() > 0 && near.size() > 0,
                   "label-efficiency: the person labels every state of the "
                       << domain.name() << " pool (seed " << seed << ") as one class");
    }
    std::unique_ptr<cbf::Barrier> truth = domain.MakeGroundTruth();
    const bool shield_run = domain.HasShieldRun();
    std::unique_ptr<internal::RunPolicyLoop> loop;
    if (!options.policies_from.empty())
      loop = std::make_unique<internal::RunPolicyLoop>(domain, options.policies_from, seed);
    for (int round = 0; round <= options.rounds; ++round) {
      const bool last = round == options.rounds;
      const std::uint64_t training_seed = Stream(seed, 0x7a11ULL) + static_cast<std::uint64_t>(round);
      const internal::SeedBarrier net = Train(safe, near, training_seed);
      std::unique_ptr<cbf::Barrier> barrier =
          internal::BarrierOn(net, features, "the " + domain.name() + " domain");
      LabelEfficiencyPoint p;
      p.round = round;
      p.labels = labels;
      p.safe_labels = safe.size();
      p.near_dangerous_labels = near.size();
      if (eval.size() > 0) Errors(*barrier, &p);
      const long episodes = last ? options.final_episodes : options.episodes;
      if (episodes > 0 && (loop || shield_run))
        ClosedLoop(net, *barrier, loop.get(), episodes, last, &p, &curve);
      if (last && options.final_grid && truth) {
        const std::optional<cbf::StateSource> grid = domain.ValidationGrid();
        if (grid) {
          cbf::GridValidationOptions v;
          v.threads = 1;
          curve.final_grid = cbf::ValidateOnGrid(
              [&] { return internal::BarrierOn(net, features, "the " + domain.name() + " domain"); },
              [&] { return domain.MakeGroundTruth(); }, *grid, v);
        }
      }
      curve.points.push_back(p);
      if (last) break;

      // Ask k more.
      cbf::QueryOptions q;
      q.strategy = strategy;
      q.k = options.QueriesIn(round);
      q.seed = Stream(seed, 0x9e7ULL) + static_cast<std::uint64_t>(round);
      q.diversity_radius = strategy == cbf::QueryStrategy::kRandom ? 0.0 : options.radius;
      if (strategy == cbf::QueryStrategy::kShieldRelevant && shield_run) {
        ShieldRunRequest request = domain.ShieldRunPreset();
        request.episodes = options.shield_pool_episodes;
        request.seed = Stream(seed, 0x5e1ULL) + static_cast<std::uint64_t>(round);
        request.record_states = options.shield_pool_states;
        const data::StateSet visited = domain.RunShield(request, *barrier).visited;
        if (visited.size() >= q.k) {
          std::unique_ptr<cbf::Barrier> on_visited =
              internal::BarrierOn(net, visited.features, visited.source);
          const cbf::QueryResult r = cbf::SelectQueries({on_visited.get()}, visited.states, q);
          add(Columns(visited, r.indices).states);
          continue;
        }
        // Too few visited states: margin over the pool instead (below), counted.
        ++curve.margin_rounds;
      }
      std::vector<long> open;
      for (long i = 0; i < n; ++i)
        if (!asked[static_cast<std::size_t>(i)]) open.push_back(i);
      const data::StateSet candidates = Columns(pool, open);
      std::vector<internal::SeedBarrier> others;  // the disagreement ensemble's other members
      std::vector<const internal::SeedBarrier*> members;
      std::vector<std::unique_ptr<cbf::Barrier>> evaluators;
      std::vector<cbf::Barrier*> barriers;
      if (strategy == cbf::QueryStrategy::kDisagreement) {
        others.reserve(static_cast<std::size_t>(options.ensemble));
        members.push_back(&net);
        for (int m = 1; m < options.ensemble; ++m) {
          others.push_back(Train(safe, near, training_seed + 1000003ULL * static_cast<std::uint64_t>(m)));
          members.push_back(&others.back());
        }
      } else if (strategy != cbf::QueryStrategy::kDiversity &&
                 strategy != cbf::QueryStrategy::kRandom) {
        members.push_back(&net);
      }
      for (const internal::SeedBarrier* m : members) {
        evaluators.push_back(internal::BarrierOn(*m, candidates.features, candidates.source));
        barriers.push_back(evaluators.back().get());
      }
      if (strategy == cbf::QueryStrategy::kShieldRelevant) q.strategy = cbf::QueryStrategy::kMargin;
      const cbf::QueryResult r = cbf::SelectQueries(barriers, candidates.states, q);
      std::vector<long> chosen;
      for (long i : r.indices) {
        chosen.push_back(open[static_cast<std::size_t>(i)]);
        asked[static_cast<std::size_t>(chosen.back())] = 1;
      }
      add(Columns(pool, chosen).states);
    }
    curve.seconds = clock.Seconds();
    return curve;
  }
};

std::string Percent(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

}  // namespace

LabelEfficiencyResult RunLabelEfficiency(const Domain& domain,
                                         const LabelEfficiencyOptions& options,
                                         std::ostream* progress) {
  options.Validate();
  SECURE_CHECK(domain.HasLabeller(), "label-efficiency: the " << domain.name()
                                                              << " domain has no labeller");
  // shield-relevant asks about the states the domain's shielded loop visits: without a shield run
  // it would be margin under another name.
  SECURE_CHECK(domain.HasShieldRun() ||
                   std::find(options.strategies.begin(), options.strategies.end(),
                             cbf::QueryStrategy::kShieldRelevant) == options.strategies.end(),
               "label-efficiency: strategy shield-relevant queries the states the shielded loop "
               "visits, and the "
                   << domain.name()
                   << " domain has no shield run (Domain::HasShieldRun): leave it out of the "
                      "strategies");
  const Stopwatch clock;
  const nlohmann::json options_json = options.ToJson();
  const std::vector<std::string> features = domain.MakeEnvironment()->ObservationFeatures();
  const int S = static_cast<int>(options.strategies.size());

  std::vector<LabelEfficiencyCurve> curves(static_cast<std::size_t>(options.seeds * S));
  std::vector<char> done(curves.size(), 0);
  std::vector<int> todo;
  const auto file_of = [&](int job) {
    const std::uint64_t seed = options.first_seed + static_cast<std::uint64_t>(job / S);
    return options.output_dir + "/seed-" + std::to_string(seed) + "/" +
           ToString(cbf::kQueryStrategyNames, options.strategies[static_cast<std::size_t>(job % S)]) +
           ".json";
  };
  for (int job = 0; job < options.seeds * S; ++job) {
    if ((job / S) % options.shard_count != options.shard_index) continue;
    if (!options.output_dir.empty() && std::filesystem::exists(file_of(job))) {
      const nlohmann::json j = nlohmann::json::parse(ReadFile(file_of(job)), nullptr, false);
      SECURE_CHECK(!j.is_discarded() && j.contains("options") && j.contains("curve"),
                   file_of(job) << ": not a label-efficiency job file");
      SECURE_CHECK(j["options"] == options_json && j.value("domain", "") == domain.name(),
                   file_of(job) << ": a job file of another label-efficiency experiment (other "
                                   "options or domain); use another --out");
      curves[static_cast<std::size_t>(job)] = LabelEfficiencyCurve::FromJson(j["curve"]);
      done[static_cast<std::size_t>(job)] = 1;
      continue;
    }
    todo.push_back(job);
  }
  // A run without a seed's models fails here, before any training.
  if (!options.policies_from.empty())
    for (int job : todo)
      internal::RunPolicyLoop(domain, options.policies_from,
                              options.first_seed + static_cast<std::uint64_t>(job / S));
  if (progress != nullptr)
    *progress << "secure experiment label-efficiency on " << domain.name() << ": "
              << options.seeds << " seeds x " << S << " strategies, " << options.initial_labels
              << " initial labels + " << options.rounds << " rounds x " << options.k;
  if (progress != nullptr && options.k_growth != 1)
    *progress << " x " << options.k_growth << "^round";
  if (progress != nullptr)
    *progress << " (" << options.LabelsAtTheEnd() << " labels at the end), on "
              << options.threads << " threads"
              << (options.output_dir.empty() ? "" : ", writing to " + options.output_dir) << "\n";
  // Per seed: the pool and the ground-truth evaluation states (computed by the seed's jobs on
  // demand, once).
  struct SeedData {
    std::once_flag once;
    data::StateSet pool, eval;
    Eigen::VectorXd truth;
  };
  std::vector<SeedData> seed_data(static_cast<std::size_t>(options.seeds));
  std::mutex print;
  internal::RunJobsInParallel(
      static_cast<int>(todo.size()), options.threads,
      [&](int t) {
        const int job = todo[static_cast<std::size_t>(t)];
        const std::uint64_t seed = options.first_seed + static_cast<std::uint64_t>(job / S);
        SeedData& sd = seed_data[static_cast<std::size_t>(job / S)];
        std::call_once(sd.once, [&] {
          sd.pool = domain.SampleQueryPool(options.pool, seed);
          SECURE_CHECK(static_cast<double>(sd.pool.size()) >= options.LabelsAtTheEnd(),
                       "label-efficiency: the " << domain.name() << " pool has " << sd.pool.size()
                                                << " states, fewer than the "
                                                << options.LabelsAtTheEnd()
                                                << " labels of the last round");
          std::unique_ptr<cbf::Barrier> truth = domain.MakeGroundTruth();
          if (truth && options.eval_states > 0) {
            sd.eval = domain.SampleQueryPool(options.eval_states, Stream(seed, 0xe5a1ULL));
            Eigen::VectorXf h(sd.eval.size());
            truth->Evaluate(sd.eval.states, h);
            sd.truth = h.cast<double>();
          } else if (options.errors_from_labeller && options.eval_states > 0) {
            sd.eval = domain.SampleQueryPool(options.eval_states, Stream(seed, 0xe5a1ULL));
            const std::vector<int> l = domain.Label(sd.eval.states, Stream(seed, 0xe5a2ULL));
            sd.truth.resize(sd.eval.size());
            for (long i = 0; i < sd.eval.size(); ++i) {
              const int v = l[static_cast<std::size_t>(i)];
              sd.truth(i) = v == 1 ? 1.0 : v == 0 ? -1.0 : std::nan("");
            }
          }
        });
        const Job j{domain, options, options.strategies[static_cast<std::size_t>(job % S)],
                    seed, sd.pool, sd.eval, sd.truth, features};
        LabelEfficiencyCurve c = j.Run();
        if (!options.output_dir.empty()) {
          CreateDirectories(std::filesystem::path(file_of(job)).parent_path().string());
          const nlohmann::json out{{"domain", domain.name()}, {"options", options_json},
                                   {"curve", c.ToJson()}};
          WriteFileAtomically(file_of(job), out.dump(1) + "\n");
        }
        if (progress && options.verbose) {
          std::lock_guard<std::mutex> lock(print);
          const LabelEfficiencyPoint& p = c.points.back();
          *progress << "[seed " << seed << "] " << c.strategy << ": " << p.labels << " labels, over "
                    << Percent(p.over) << " %, under " << Percent(p.under) << " %, dangerous "
                    << Percent(p.dangerous) << " % (" << c.seconds << " s)\n";
        }
        curves[static_cast<std::size_t>(job)] = std::move(c);
        done[static_cast<std::size_t>(job)] = 1;
      },
      "label-efficiency job", 0);

  LabelEfficiencyResult result;
  result.domain = domain.name();
  result.options = options_json;
  result.labeller = domain.LabellerDescription();
  result.paper = domain.PaperGroundTruthReference();
  for (std::size_t i = 0; i < curves.size(); ++i)
    if (done[i]) result.curves.push_back(curves[i]);
  result.seconds = clock.Seconds();
  const bool complete = std::all_of(done.begin(), done.end(), [](char d) { return d != 0; });
  if (complete && options.shard_count == 1 && !options.policies_from.empty() && options.seeds >= 2 &&
      options.final_episodes > 0)
    result.closed_loop = internal::ClosedLoopEvaluations(result.curves, domain, options);
  if (!options.output_dir.empty())
    for (const auto& [name, doc] : result.closed_loop)
      WriteFileAtomically(options.output_dir + "/closed-loop-" + name + ".json", doc.dump(1) + "\n");
  if (!options.output_dir.empty() && complete && options.shard_count == 1) {
    WriteFileAtomically(options.output_dir + "/result.json", result.ToJson().dump(1) + "\n");
    std::ostringstream csv;
    csv << "strategy,seed,round,labels,safe_labels,near_dangerous_labels,over_conservative,"
           "under_conservative,dangerous,success,episodes\n";
    for (const LabelEfficiencyCurve& c : result.curves)
      for (const LabelEfficiencyPoint& p : c.points)
        csv << c.strategy << "," << c.seed << "," << p.round << "," << p.labels << ","
            << p.safe_labels << "," << p.near_dangerous_labels << "," << p.over << "," << p.under
            << "," << p.dangerous << "," << p.success << "," << p.episodes << "\n";
    WriteFileAtomically(options.output_dir + "/curves.csv", csv.str());
  }
  return result;
}

nlohmann::json LabelEfficiencyResult::ToJson() const {
  nlohmann::json c = nlohmann::json::array();
  for (const LabelEfficiencyCurve& curve : curves) c.push_back(curve.ToJson());
  nlohmann::json j{{"experiment", "label-efficiency"}, {"domain", domain},
                   {"options", options},               {"labeller", labeller},
                   {"curves", c},                      {"seconds", seconds}};
  if (!closed_loop.empty()) {
    j["closed_loop"] = nlohmann::json::object();
    for (const auto& [name, doc] : closed_loop) j["closed_loop"][name] = doc;
  }
  if (paper)
    j["paper"] = {{"over_conservative", paper->over_conservative},
                  {"under_conservative", paper->under_conservative}};
  return j;
}

std::string LabelEfficiencyResult::Table() const {
  std::ostringstream out;
  out << "Label efficiency on " << domain << " (labeller: " << labeller << ")\n\n";
  out << "| strategy | round | labels | near-dangerous labels | over-conservative % | "
         "under-conservative % | dangerous % | success % |\n|---|---:|---:|---:|---:|---:|---:|---:|\n";
  std::vector<std::string> names;
  for (const LabelEfficiencyCurve& c : curves)
    if (std::find(names.begin(), names.end(), c.strategy) == names.end()) names.push_back(c.strategy);
  const auto mean_std = [](const std::vector<double>& v) {
    if (v.empty() || v[0] < 0) return std::string("–");
    const MeanStd m = MeanStd::Of(v);
    char buf[48];
    std::snprintf(buf, sizeof buf, "%.2f (%.2f)", m.mean, m.std);
    return std::string(buf);
  };
  std::ostringstream reach;
  for (const std::string& s : names) {
    std::vector<const LabelEfficiencyCurve*> cs;
    for (const LabelEfficiencyCurve& c : curves)
      if (c.strategy == s) cs.push_back(&c);
    const std::size_t rounds = cs.front()->points.size();
    long reached = -1;
    for (std::size_t r = 0; r < rounds; ++r) {
      std::vector<double> labels, nd, over, under, dangerous, success;
      for (const LabelEfficiencyCurve* c : cs) {
        if (r >= c->points.size()) continue;
        const LabelEfficiencyPoint& p = c->points[r];
        labels.push_back(double(p.labels));
        nd.push_back(double(p.near_dangerous_labels));
        over.push_back(p.over);
        under.push_back(p.under);
        dangerous.push_back(p.dangerous);
        success.push_back(p.success);
      }
      const MeanStd l = MeanStd::Of(labels), n = MeanStd::Of(nd);
      out << "| " << s << " | " << r << " | " << l.mean << " | " << n.mean << " | "
          << mean_std(over) << " | " << mean_std(under) << " | " << mean_std(dangerous) << " | "
          << mean_std(success) << " |\n";
      if (paper && reached < 0 && !over.empty() && over[0] >= 0 &&
          MeanStd::Of(over).mean <= paper->over_conservative &&
          MeanStd::Of(under).mean <= paper->under_conservative)
        reached = static_cast<long>(l.mean);
    }
    if (paper)
      reach << "| " << s << " | " << (reached < 0 ? std::string("not reached") : std::to_string(reached))
            << " |\n";
    std::vector<double> go, gu;
    for (const LabelEfficiencyCurve* c : cs)
      if (c->final_grid) {
        go.push_back(100 * c->final_grid->OverConservative());
        gu.push_back(100 * c->final_grid->UnderConservative());
      }
    if (!go.empty())
      out << "| " << s << " | final, validation grid | | | " << mean_std(go) << " | "
          << mean_std(gu) << " | | |\n";
  }
  out << "\nmean (sample std) over seeds; over/under on the estimate states each round, on the "
         "validation grid at the last round (Table 1)"
      << (options.value("errors_from_labeller", false)
              ? "; without a ground truth, against the labeller's answers (the person, not physics)"
              : "")
      << "\n";
  int margin_rounds = 0, shield_rounds = 0;
  for (const LabelEfficiencyCurve& c : curves)
    if (c.strategy == ToString(cbf::kQueryStrategyNames, cbf::QueryStrategy::kShieldRelevant)) {
      margin_rounds += c.margin_rounds;
      shield_rounds += std::max(0, static_cast<int>(c.points.size()) - 1);
    }
  if (margin_rounds > 0)
    out << "shield-relevant: " << margin_rounds << " of " << shield_rounds
        << " query rounds asked by margin over the pool (the shielded run visited fewer than k "
           "states)\n";
  if (!closed_loop.empty()) out << "\n" << internal::ClosedLoopTable(closed_loop);
  if (paper) {
    out << "\nLabels (mean over seeds) at which the mean errors first reach the paper's Table 1 ("
        << paper->over_conservative << " % over, " << paper->under_conservative << " % under):\n\n"
        << "| strategy | labels |\n|---|---:|\n"
        << reach.str();
  }
  return out.str();
}

}  // namespace secure::experiments
