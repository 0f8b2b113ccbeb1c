#include "secure/experiments/user_study.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numeric>
#include <optional>
#include <ostream>
#include <sstream>

#include "secure/cbf/barrier_net.h"
#include "secure/common/atomic_file.h"
#include "secure/common/build_info.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/eval/policy_eval.h"
#include "secure/experiments/internal/seed_runner.h"

namespace secure::experiments {
namespace {

constexpr const char* kOptions = "UserStudyOptions";

// A stream of its own for (seed, tag): the participants' data, training and evaluation draw
// from streams that depend on the study's seed and the participant, not on the spread.
std::uint64_t Stream(std::uint64_t seed, std::uint64_t tag) {
  Rng rng(seed ^ (0x9e3779b97f4a7c15ULL * (tag + 1)));
  return rng.NextU64() >> 1;  // (non-negative as a signed 64-bit value: the CLI's seed range)
}
enum : std::uint64_t { kDataTag = 1000, kTrainTag = 100000, kEvalTag = 200000, kPoolTag = 300000 };
constexpr std::uint64_t kGrouped = 99999;  // the grouped models' training stream

// Counts the steps where the shield changed the action although the participant's thresholds
// held with margin at the state it decided in.
class OverConservative final : public eval::StepObserver {
 public:
  OverConservative(const Population& population, int participant)
      : population_(population), participant_(participant) {}
  void OnEpisodeStart(long, const Eigen::VectorXf& observation) override { state_ = observation; }
  void OnStep(const eval::StepView& step) override {
    ++steps_;
    if (step.decision != nullptr && step.decision->intervened &&
        population_.HeldWithMargin(participant_, state_))
      ++over_;
    state_ = step.observation;
  }
  double Fraction() const { return steps_ > 0 ? double(over_) / double(steps_) : 0.0; }

 private:
  const Population& population_;
  int participant_;
  Eigen::VectorXf state_;
  long steps_ = 0, over_ = 0;
};

// Whole episodes of `demos` drawn at random until at least `states` states.
data::TrajectorySet SubsampleEpisodes(const std::vector<const data::TrajectorySet*>& sets,
                                      long states, Rng& rng) {
  struct Ref {
    const data::TrajectorySet* set;
    long episode;
  };
  std::vector<Ref> all;
  for (const data::TrajectorySet* s : sets)
    for (long e = 0; e < s->num_episodes(); ++e) all.push_back({s, e});
  Shuffle(all.begin(), all.end(), rng);
  const data::TrajectorySet& first = *sets.front();
  data::TrajectorySet out;
  out.source = "grouped demonstrations (all participants' episodes, subsampled)";
  out.state_features = first.state_features;
  out.action_features = first.action_features;
  out.episode_begin.push_back(0);
  std::vector<Ref> chosen;
  long total = 0;
  for (const Ref& r : all) {
    if (total >= states) break;
    chosen.push_back(r);
    total += r.set->episode_begin[r.episode + 1] - r.set->episode_begin[r.episode];
  }
  out.states.resize(first.states.rows(), total);
  out.actions.resize(first.actions.rows(), total);
  long at = 0;
  for (const Ref& r : chosen) {
    const long b = r.set->episode_begin[r.episode], n = r.set->episode_begin[r.episode + 1] - b;
    out.states.middleCols(at, n) = r.set->states.middleCols(b, n);
    out.actions.middleCols(at, n) = r.set->actions.middleCols(b, n);
    at += n;
    out.episode_begin.push_back(at);
  }
  return out;
}

// `count` states drawn without replacement from the pooled sets.
data::StateSet SubsampleStates(const std::vector<const data::StateSet*>& sets, long count, Rng& rng,
                               const std::string& source) {
  long total = 0;
  for (const data::StateSet* s : sets) total += s->size();
  std::vector<std::pair<const data::StateSet*, long>> all;
  all.reserve(static_cast<std::size_t>(total));
  for (const data::StateSet* s : sets)
    for (long i = 0; i < s->size(); ++i) all.emplace_back(s, i);
  Shuffle(all.begin(), all.end(), rng);
  count = std::min(count, total);
  data::StateSet out;
  out.source = source;
  out.features = sets.front()->features;
  out.states.resize(sets.front()->states.rows(), count);
  for (long i = 0; i < count; ++i)
    out.states.col(i) =
        all[static_cast<std::size_t>(i)].first->states.col(all[static_cast<std::size_t>(i)].second);
  return out;
}

std::string Fixed(double v, int digits) {
  if (std::isnan(v)) return "-";
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

std::string PValue(double p) {
  char b[64];
  if (p < 0.001)
    std::snprintf(b, sizeof b, "%.1e", p);
  else
    std::snprintf(b, sizeof b, "%.3f", p);
  return b;
}

nlohmann::json Number(double v) {
  return std::isnan(v) ? nlohmann::json(nullptr) : nlohmann::json(v);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
const std::vector<std::string>& UserStudyConditionNames() {
  static const std::vector<std::string> names{"(ind, ind)", "(ind, grp)", "(grp, ind)",
                                              "(grp, grp)"};
  return names;
}
bool GroupedPolicy(int c) { return c >= 2; }
bool GroupedBarrier(int c) { return c % 2 == 1; }

UserStudyOptions UserStudyOptions::From(const ExperimentOptions& preset, Profile profile) {
  UserStudyOptions o;
  o.bc = preset.bc;
  o.barrier = preset.flat_barrier;
  o.shield = preset.shield;
  if (profile == Profile::kQuick) {
    o.participants = 3;
    o.episodes = 3;
  }
  return o;
}

void UserStudyOptions::Validate() const {
  SECURE_CHECK_FIELD(participants >= 2 && participants <= 1000, kOptions, "participants",
                     participants, "in [2, 1000] (the tests compare participants)");
  SECURE_CHECK_FIELD(episodes >= 1 && episodes <= 100000, kOptions, "episodes", episodes,
                     "in [1, 100000]");
  SECURE_CHECK_FIELD(!spreads.empty() && spreads.size() <= 20, kOptions, "spreads",
                     spreads.size() << " values", "1 to 20 values");
  for (double s : spreads)
    SECURE_CHECK_FIELD(std::isfinite(s) && s >= 0 && s <= 1, kOptions, "spreads[]", s, "in [0, 1]");
  SECURE_CHECK_FIELD(threads >= 1, kOptions, "threads", threads, ">= 1");
  bc.Validate();
  barrier.Validate();
  shield.Validate();
}

nlohmann::json UserStudyOptions::ToJson() const {
  return {{"participants", participants},
          {"episodes", episodes},
          {"seed", seed},
          {"spreads", spreads},
          {"grouped_matched", grouped_matched},
          {"bc", bc.ToJson()},
          {"barrier", barrier.ToJson()},
          {"shield", shield.ToJson()}};
}

double UserStudyMetric::Mean(int c) const {
  double sum = 0;
  for (const auto& row : values) sum += row[static_cast<std::size_t>(c)];
  return values.empty() ? std::nan("") : sum / double(values.size());
}

double UserStudyMetric::StandardError(int c) const {
  const std::size_t n = values.size();
  if (n < 2) return std::nan("");
  const double m = Mean(c);
  double ss = 0;
  for (const auto& row : values) ss += std::pow(row[static_cast<std::size_t>(c)] - m, 2);
  return std::sqrt(ss / double(n - 1)) / std::sqrt(double(n));
}

int UserStudyMetric::Best() const {
  int best = 0;
  for (int c = 1; c < kUserStudyConditions; ++c) {
    const double a = Mean(c), b = Mean(best);
    if (higher_is_better ? a > b : a < b) best = c;
  }
  return best;
}

nlohmann::json UserStudyMetric::ToJson() const {
  nlohmann::json conditions = nlohmann::json::array();  // in the conditions' order
  for (int c = 0; c < kUserStudyConditions; ++c) {
    nlohmann::json per = nlohmann::json::array();
    for (const auto& row : values) per.push_back(row[static_cast<std::size_t>(c)]);
    conditions.push_back({{"condition", UserStudyConditionNames()[static_cast<std::size_t>(c)]},
                          {"policy", GroupedPolicy(c) ? "grouped" : "individual"},
                          {"barrier", GroupedBarrier(c) ? "grouped" : "individual"},
                          {"mean", Number(Mean(c))},
                          {"se", Number(StandardError(c))},
                          {"per_participant", per}});
  }
  return {{"label", label},
          {"higher_is_better", higher_is_better},
          {"conditions", conditions},
          {"best", UserStudyConditionNames()[static_cast<std::size_t>(Best())]},
          {"friedman", friedman ? friedman->ToJson() : nlohmann::json(nullptr)},
          {"posthoc", posthoc.ToJson()}};
}

nlohmann::json UserStudySpreadResult::ToJson() const {
  nlohmann::json m = nlohmann::json::object();
  for (const UserStudyMetric& metric : metrics) m[metric.key] = metric.ToJson();
  return {{"spread", spread},
          {"participants", participants},
          {"metrics", m},
          {"data", data},
          {"verdict", verdict}};
}

nlohmann::json UserStudyResult::ToJson() const {
  nlohmann::json s = nlohmann::json::array();
  for (const UserStudySpreadResult& r : spreads) s.push_back(r.ToJson());
  nlohmann::json j = {{"experiment",
                       {{"kind", "user-study"},
                        {"version", Version()},
                        {"domain", domain},
                        {"domain_options", domain_options},
                        {"population", population},
                        {"conditions", UserStudyConditionNames()},
                        {"time_unit", time_unit},
                        {"options", options.ToJson()},
                        {"seconds", seconds}}},
                      {"spreads", s}};
  if (paper) {
    nlohmann::json rows = nlohmann::json::array();
    for (const auto& [what, v] : paper->rows) rows.push_back({{"what", what}, {"values", v}});
    j["paper"] = {{"source", paper->source}, {"rows", rows}};
  }
  return j;
}

std::string UserStudyResult::Table() const {
  const std::vector<std::string>& names = UserStudyConditionNames();
  std::ostringstream out;
  out << "SECURE user study on " << domain_title
      << " (simulated participants): " << options.participants << " participants x "
      << options.episodes << " episodes per condition, seed " << options.seed << ", grouped data "
      << (options.grouped_matched ? "subsampled to one participant's size"
                                  : "all participants' pooled")
      << "; conditions (policy data, barrier data), ind = individual, grp = grouped\n";
  for (const UserStudySpreadResult& r : spreads) {
    out << "\n### Threshold spread " << r.spread << "\n\n"
        << "Mean (standard error) over participants; Friedman test across the four conditions.\n\n"
        << "| (policy, CBF) |";
    for (const std::string& n : names) out << " " << n << " |";
    out << " Friedman chi2 (p) |\n|---|---|---|---|---|---|\n";
    for (const UserStudyMetric& m : r.metrics) {
      out << "| " << m.label << " (this run) |";
      for (int c = 0; c < kUserStudyConditions; ++c)
        out << " " << Fixed(m.scale * m.Mean(c), m.scale == 1 ? 2 : 1) << " ("
            << Fixed(m.scale * m.StandardError(c), m.scale == 1 ? 2 : 1) << ") |";
      if (m.friedman)
        out << " " << Fixed(m.friedman->statistic, 2) << " (" << PValue(m.friedman->p_value)
            << ") |\n";
      else
        out << " - (all tied) |\n";
    }
    if (paper) {
      for (const auto& [what, v] : paper->rows) {
        out << "| " << what << " (paper, Likert rating) |";
        for (double x : v) out << " " << Fixed(x, 1) << " |";
        out << " |\n";
      }
    }
    if (paper)
      out << "\nThe paper's rows (" << paper->source
          << ") are Likert ratings, not rates: compare the order of the conditions, not the "
             "values.\n";
    out << "\nPost-hoc Wilcoxon signed-rank tests, Holm-adjusted p:\n\n| pair |";
    for (const UserStudyMetric& m : r.metrics) out << " " << m.label << " |";
    out << "\n|---|";
    for (std::size_t k = 0; k < r.metrics.size(); ++k) out << "---|";
    out << "\n";
    for (std::size_t i = 0; i < r.metrics.front().posthoc.pairs.size(); ++i) {
      const stats::WilcoxonPair& pair = r.metrics.front().posthoc.pairs[i];
      out << "| " << names[static_cast<std::size_t>(pair.i)] << " vs "
          << names[static_cast<std::size_t>(pair.j)] << " |";
      for (const UserStudyMetric& m : r.metrics)
        out << " " << PValue(m.posthoc.pairs[i].p_adjusted) << " |";
      out << "\n";
    }
    out << "\nHypothesis (the paper's): grouped policy + individual barrier, (grp, ind), is best. "
        << "Best mean: success " << names[static_cast<std::size_t>(r.metrics[0].Best())]
        << ", violations " << names[static_cast<std::size_t>(r.metrics[1].Best())]
        << ", over-conservativeness " << names[static_cast<std::size_t>(r.metrics[2].Best())]
        << ", time " << names[static_cast<std::size_t>(r.metrics[3].Best())]
        << ". Verdict: " << r.verdict << ".\n";
  }
  if (spreads.size() > 1) {
    out << "\n### The sweep over the threshold spread\n\n"
        << "| spread | best success | best violations | best over-conservative | Friedman p "
           "(violations) | violations % (grp, ind) vs (grp, grp) | verdict |\n"
        << "|---|---|---|---|---|---|---|\n";
    for (const UserStudySpreadResult& r : spreads) {
      const UserStudyMetric& v = r.metrics[1];
      out << "| " << r.spread << " | " << names[static_cast<std::size_t>(r.metrics[0].Best())]
          << " | " << names[static_cast<std::size_t>(v.Best())] << " | "
          << names[static_cast<std::size_t>(r.metrics[2].Best())] << " | "
          << (v.friedman ? PValue(v.friedman->p_value) : std::string("-")) << " | "
          << Fixed(100 * v.Mean(2), 1) << " vs " << Fixed(100 * v.Mean(3), 1) << " | " << r.verdict
          << " |\n";
    }
  }
  out << "\nViolation / margin: " << population << ".\n";
  return out.str();
}

// ---------------------------------------------------------------------------------------------
namespace {

struct Models {
  std::optional<policy::GaussianPolicy> policy;
  std::optional<cbf::BarrierNet> barrier;
};

UserStudyMetric MakeMetric(const char* key, const char* label, bool higher, double scale,
                           std::vector<std::vector<double>> values) {
  UserStudyMetric m;
  m.key = key;
  m.label = label;
  m.higher_is_better = higher;
  m.scale = scale;
  m.values = std::move(values);
  try {
    m.friedman = stats::Friedman(m.values);
  } catch (const Error&) {
    m.friedman.reset();  // every participant's values tie: no test
  }
  m.posthoc = stats::PairwiseWilcoxon(m.values);
  return m;
}

std::string Verdict(const UserStudySpreadResult& r) {
  constexpr int kHypothesis = 2;  // (grp, ind)
  const UserStudyMetric& success = r.metrics[0];
  const UserStudyMetric& violations = r.metrics[1];
  auto best = [&](const UserStudyMetric& m) {
    for (int c = 0; c < kUserStudyConditions; ++c) {
      if (c == kHypothesis) continue;
      const double a = m.Mean(kHypothesis), b = m.Mean(c);
      if (m.higher_is_better ? a < b : a > b) return false;
    }
    return true;
  };
  if (!best(success) || !best(violations)) return "not supported";
  bool differs = false;
  for (int c = 0; c < kUserStudyConditions; ++c)
    for (const UserStudyMetric* m : {&success, &violations})
      differs = differs || m->Mean(c) != m->Mean(kHypothesis);
  if (!differs) return "not supported (no differences)";
  // Significantly better than each other condition on success or on violations.
  for (int c = 0; c < kUserStudyConditions; ++c) {
    if (c == kHypothesis) continue;
    bool significant = false;
    for (const UserStudyMetric* m : {&success, &violations}) {
      for (const stats::WilcoxonPair& p : m->posthoc.pairs) {
        if ((p.i == c && p.j == kHypothesis) || (p.i == kHypothesis && p.j == c))
          significant = significant || (p.p_adjusted < 0.05 && m->Mean(kHypothesis) != m->Mean(c));
      }
    }
    if (!significant) return "consistent, not significant";
  }
  return "supported";
}

UserStudySpreadResult RunSpread(const Domain& domain, const UserStudyOptions& o, double spread,
                                internal::Progress& progress, double step_seconds) {
  PopulationOptions po;
  po.participants = o.participants;
  po.seed = o.seed;
  po.threshold_spread = spread;
  const std::unique_ptr<Population> population = domain.MakePopulation(po);
  const int n = population->size();
  SECURE_CHECK(n == o.participants,
               "the population has " << n << " participants, expected " << o.participants);
  const std::string tag = "[spread " + Fixed(spread, 2) + "]";
  UserStudySpreadResult result;
  result.spread = spread;
  for (int p = 0; p < n; ++p) result.participants.push_back(population->Participant(p));

  // 1. Each participant's data.
  std::vector<DomainData> data(static_cast<std::size_t>(n));
  internal::RunJobsInParallel(
      n, o.threads,
      [&](int p) {
        data[static_cast<std::size_t>(p)] =
            population->GenerateData(p, Stream(o.seed, kDataTag + static_cast<std::uint64_t>(p)));
      },
      "participant", 0);
  progress.Line(
      [&](std::ostream& out) { out << tag << " data of " << n << " participants generated"; });

  // 2. The grouped data: pooled, subsampled to one participant's mean size.
  std::vector<const data::TrajectorySet*> demos;
  std::vector<const data::StateSet*> safe, unsafe;
  double steps = 0, n_safe = 0, n_unsafe = 0;
  for (const DomainData& d : data) {
    demos.push_back(&d.demonstrations);
    safe.push_back(&d.safe);
    unsafe.push_back(&d.near_dangerous);
    steps += double(d.demonstrations.num_steps()) / n;
    n_safe += double(d.safe.size()) / n;
    n_unsafe += double(d.near_dangerous.size()) / n;
  }
  Rng pool(Stream(o.seed, kPoolTag));
  DomainData grouped;
  // (All of the pool, shuffled, unless matched to one participant's size.)
  const double all = o.grouped_matched ? 1.0 : double(n);
  grouped.demonstrations = SubsampleEpisodes(demos, std::lround(all * steps), pool);
  grouped.safe = SubsampleStates(safe, std::lround(all * n_safe), pool, "grouped safe states");
  grouped.near_dangerous =
      SubsampleStates(unsafe, std::lround(all * n_unsafe), pool, "grouped unsafe states");
  result.data = {{"individual_demonstration_states_mean", steps},
                 {"individual_safe_mean", n_safe},
                 {"individual_unsafe_mean", n_unsafe},
                 {"grouped_demonstration_states", grouped.demonstrations.num_steps()},
                 {"grouped_safe", grouped.safe.size()},
                 {"grouped_unsafe", grouped.near_dangerous.size()}};

  // 3. Models: per participant a policy and a barrier, and the grouped ones (index n).
  std::vector<Models> models(static_cast<std::size_t>(n + 1));
  internal::RunJobsInParallel(
      2 * (n + 1), o.threads,
      [&](int job) {
        const int p = job / 2;
        const DomainData& d = p < n ? data[static_cast<std::size_t>(p)] : grouped;
        const std::uint64_t seed =
            Stream(o.seed, kTrainTag + (p < n ? static_cast<std::uint64_t>(p) : kGrouped));
        Models& m = models[static_cast<std::size_t>(p)];
        if (job % 2 == 0) {
          policy::BcOptions bc = o.bc;
          bc.seed = seed;
          bc.verbose = false;
          m.policy = policy::TrainBc(bc, d.demonstrations);
        } else {
          cbf::BarrierTrainerOptions b = o.barrier;
          b.seed = seed;
          b.verbose = false;
          cbf::BarrierTrainingSummary summary;
          m.barrier = cbf::TrainBarrier(b, d.safe, d.near_dangerous, &summary);
        }
      },
      "training job", 0);
  progress.Line([&](std::ostream& out) {
    out << tag << " " << n << " individual and 1 grouped BC policies and barriers trained";
  });

  // 4. Every participant under every condition, on the same episodes.
  std::vector<std::vector<eval::SeedResult>> results(
      static_cast<std::size_t>(n), std::vector<eval::SeedResult>(kUserStudyConditions));
  std::vector<std::vector<double>> over(static_cast<std::size_t>(n),
                                        std::vector<double>(kUserStudyConditions));
  internal::RunJobsInParallel(
      n * kUserStudyConditions, o.threads,
      [&](int job) {
        const int p = job / kUserStudyConditions, c = job % kUserStudyConditions;
        const Models& pm = models[static_cast<std::size_t>(GroupedPolicy(c) ? n : p)];
        const Models& bm = models[static_cast<std::size_t>(GroupedBarrier(c) ? n : p)];
        const std::unique_ptr<domains::Environment> env = population->MakeEnvironment(p);
        const std::vector<std::string> features = env->ObservationFeatures();
        const cbf::BarrierNet& barrier = *bm.barrier;
        eval::SeedModels sm;
        sm.bc = &*pm.policy;
        sm.make_barrier = [&barrier, &features] {
          return barrier.MakeEvaluatorFor(features, "the participant's observations", "the barrier",
                                          256);
        };
        eval::EpisodeRunner runner(*env);
        OverConservative observer(*population, p);
        results[static_cast<std::size_t>(p)][static_cast<std::size_t>(c)] =
            eval::RunMethod(runner, eval::Method::kBcShield, sm, o.shield, o.episodes,
                            Stream(o.seed, kEvalTag + static_cast<std::uint64_t>(p)), &observer);
        over[static_cast<std::size_t>(p)][static_cast<std::size_t>(c)] = observer.Fraction();
      },
      "evaluation job", 0);

  // 5. Metrics and tests.
  std::vector<std::vector<double>> success(static_cast<std::size_t>(n)), violations(success),
      time(success);
  for (int p = 0; p < n; ++p) {
    for (int c = 0; c < kUserStudyConditions; ++c) {
      const eval::SeedResult& r = results[static_cast<std::size_t>(p)][static_cast<std::size_t>(c)];
      success[static_cast<std::size_t>(p)].push_back(r.success_rate());
      violations[static_cast<std::size_t>(p)].push_back(r.dangerous_rate());
      const double per_episode = r.episodes ? double(r.steps) / double(r.episodes) : 0.0;
      time[static_cast<std::size_t>(p)].push_back(step_seconds > 0 ? per_episode * step_seconds
                                                                   : per_episode);
    }
    progress.Line([&](std::ostream& out) {
      out << tag << " participant " << p << ":";
      for (int c = 0; c < kUserStudyConditions; ++c) {
        out << " " << UserStudyConditionNames()[static_cast<std::size_t>(c)] << " "
            << 100 * success[static_cast<std::size_t>(p)][static_cast<std::size_t>(c)] << "%/"
            << 100 * violations[static_cast<std::size_t>(p)][static_cast<std::size_t>(c)] << "%";
      }
      out << " (success/violations)";
    });
  }
  result.metrics.push_back(MakeMetric("success", "Task success %", true, 100, success));
  result.metrics.push_back(
      MakeMetric("violations", "Episodes with a violation %", false, 100, violations));
  result.metrics.push_back(
      MakeMetric("over_conservative", "Over-conservative steps %", false, 100, over));
  result.metrics.push_back(
      MakeMetric("time", step_seconds > 0 ? "Task time s" : "Task time (steps)", false, 1, time));
  result.verdict = Verdict(result);
  return result;
}

}  // namespace

UserStudyResult RunUserStudy(const Domain& domain, const UserStudyOptions& options,
                             std::ostream* progress_stream) {
  const Stopwatch clock;
  domain.Validate();
  options.Validate();
  SECURE_CHECK(domain.HasPopulation(),
               "the " << domain.name()
                      << " domain has no participants for a user study (Domain::HasPopulation)");
  CreateDirectories(options.output_dir);
  ProgressLine line(progress_stream, false);
  internal::Progress progress(&line, options.verbose && progress_stream != nullptr);
  UserStudyResult result;
  result.domain = domain.name();
  result.domain_title = domain.Title();
  result.domain_options = domain.OptionsJson();
  result.options = options;
  double step_seconds = 0;
  {
    PopulationOptions po;
    po.participants = options.participants;
    po.seed = options.seed;
    const std::unique_ptr<Population> population = domain.MakePopulation(po);
    result.population = population->Describe();
    result.paper = population->PaperReference();
    step_seconds = population->StepSeconds();
    result.time_unit = step_seconds > 0 ? "s" : "steps";
  }
  for (double spread : options.spreads)
    result.spreads.push_back(RunSpread(domain, options, spread, progress, step_seconds));
  result.seconds = clock.Seconds();
  if (!options.output_dir.empty())
    WriteFileAtomically(options.output_dir + "/result.json", result.ToJson().dump(2) + "\n");
  return result;
}

}  // namespace secure::experiments
