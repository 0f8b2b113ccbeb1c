#include "secure/cbf/barrier_check.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numeric>
#include <set>
#include <sstream>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_value.h"

namespace secure::cbf {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Per-feature standard deviation of the columns of `x` (population std, in double).
Eigen::VectorXd FeatureStd(const Eigen::Ref<const Eigen::MatrixXf>& x) {
  const long n = x.cols();
  Eigen::VectorXd std_dev = Eigen::VectorXd::Zero(x.rows());
  if (n == 0) return std_dev;
  const Eigen::MatrixXd xd = x.cast<double>();
  const Eigen::VectorXd mean = xd.rowwise().mean();
  for (long i = 0; i < n; ++i) std_dev.array() += (xd.col(i) - mean).array().square();
  return (std_dev / static_cast<double>(n)).cwiseSqrt();
}

// The check's evaluation machinery: h of batches and max_a g of single states.
class Checker {
 public:
  Checker(Barrier& barrier, const domains::DynamicsModel& dynamics,
          const BarrierCheckProblem& problem, const BarrierCheckOptions& options)
      : barrier_(barrier), dynamics_(dynamics), problem_(problem), options_(options) {
    const int n = dynamics.action_dim();
    long grid_points = 0;
    if (options.action_grid >= 2) {
      grid_points = 1;
      for (int i = 0; i < n && grid_points <= 4096; ++i) grid_points *= options.action_grid;
      if (grid_points > 4096) grid_points = 0;
    }
    grid_.resize(n, grid_points);
    for (long k = 0; k < grid_points; ++k) {
      long rest = k;
      for (int i = 0; i < n; ++i) {
        const long idx = rest % options.action_grid;
        rest /= options.action_grid;
        const double t = static_cast<double>(idx) / (options.action_grid - 1);
        grid_(i, k) = static_cast<float>(problem.action_lo[i] +
                                         t * (problem.action_hi[i] - problem.action_lo[i]));
      }
    }
    const long batch =
        std::max<long>({grid_points + options.action_samples, options.action_samples, 1L});
    actions_.resize(n, batch);
    next_.resize(dynamics.state_dim(), batch);
    h_next_.resize(batch);
    one_.resize(dynamics.state_dim(), 1);
    h_one_.resize(1);
  }

  void H(const Eigen::Ref<const Eigen::MatrixXf>& states, Eigen::VectorXf* h) {
    h->resize(states.cols());
    if (states.cols() > 0) barrier_.Evaluate(states, *h);
  }

  double HOne(const Eigen::Ref<const Eigen::VectorXf>& state) {
    one_.col(0) = state;
    barrier_.Evaluate(one_, h_one_);
    return h_one_[0];
  }

  // max_a g(state, a); -inf if no action gives a finite g (or h(s) is not finite).
  double MaxG(const Eigen::Ref<const Eigen::VectorXf>& state, double h_s, Rng& rng) {
    if (!std::isfinite(h_s)) return -kInf;
    const int n = dynamics_.action_dim();
    const double alpha = problem_.class_k(h_s);
    double best = -kInf;
    Eigen::VectorXf best_action = 0.5f * (problem_.action_lo + problem_.action_hi);
    auto evaluate = [&](long count) {
      dynamics_.Step(state, actions_.leftCols(count), next_.leftCols(count));
      barrier_.Evaluate(next_.leftCols(count), h_next_.head(count));
      for (long k = 0; k < count; ++k) {
        const double g = (static_cast<double>(h_next_[k]) - h_s) / problem_.dt + alpha;
        if (std::isfinite(g) && g > best) {
          best = g;
          best_action = actions_.col(k);
        }
      }
    };
    // The grid and uniform random actions over the box.
    const long grid_points = grid_.cols();
    if (grid_points > 0) actions_.leftCols(grid_points) = grid_;
    for (long k = 0; k < options_.action_samples; ++k)
      for (int i = 0; i < n; ++i)
        actions_(i, grid_points + k) =
            static_cast<float>(rng.Uniform(problem_.action_lo[i], problem_.action_hi[i]));
    evaluate(grid_points + options_.action_samples);
    // Refinement: uniform in a box around the best action, halved each round.
    const Eigen::VectorXd width = (problem_.action_hi - problem_.action_lo).cast<double>() /
                                  (grid_points > 0 ? 2.0 * (options_.action_grid - 1) : 4.0);
    for (int round = 0; round < options_.action_refine_rounds && options_.action_samples > 0;
         ++round) {
      const double shrink = std::ldexp(1.0, -round);
      const Eigen::VectorXf centre = best_action;
      for (long k = 0; k < options_.action_samples; ++k)
        for (int i = 0; i < n; ++i) {
          const double w = width[i] * shrink;
          const double a =
              std::clamp(centre[i] + rng.Uniform(-w, w), static_cast<double>(problem_.action_lo[i]),
                         static_cast<double>(problem_.action_hi[i]));
          actions_(i, k) = static_cast<float>(a);
        }
      evaluate(options_.action_samples);
    }
    return best;
  }

 private:
  Barrier& barrier_;
  const domains::DynamicsModel& dynamics_;
  const BarrierCheckProblem& problem_;
  const BarrierCheckOptions& options_;
  Eigen::MatrixXf grid_, actions_, next_, one_;
  Eigen::VectorXf h_next_, h_one_;
};

void ValidateInputs(Barrier& barrier, const domains::DynamicsModel& dynamics,
                    const BarrierCheckProblem& p, const BarrierCheckOptions& options) {
  options.Validate();
  const int d = barrier.state_dim();
  SECURE_CHECK(dynamics.state_dim() == d, "barrier check: the barrier ("
                                              << barrier.Describe() << ") has state dimension " << d
                                              << ", the dynamics model (" << dynamics.Describe()
                                              << ") " << dynamics.state_dim());
  const int n = dynamics.action_dim();
  SECURE_CHECK(p.action_lo.size() == n && p.action_hi.size() == n,
               "barrier check: the action box has " << p.action_lo.size() << " / "
                                                    << p.action_hi.size()
                                                    << " bounds, the dynamics model's action "
                                                       "dimension is "
                                                    << n);
  for (int i = 0; i < n; ++i)
    SECURE_CHECK(std::isfinite(p.action_lo[i]) && std::isfinite(p.action_hi[i]) &&
                     p.action_lo[i] <= p.action_hi[i],
                 "barrier check: action box [" << i << "] = [" << p.action_lo[i] << ", "
                                               << p.action_hi[i]
                                               << "], must be finite with lo <= hi");
  SECURE_CHECK(std::isfinite(p.dt) && p.dt > 0,
               "barrier check: dt = " << p.dt << ", must be finite and > 0");
  SECURE_CHECK(static_cast<bool>(p.class_k), "barrier check: no class-K function given");
  SECURE_CHECK(static_cast<bool>(p.sample_region), "barrier check: no region sampler given");
  data::CheckNonEmptyFinite(p.near_dangerous, "barrier check: near-dangerous states");
  SECURE_CHECK(p.near_dangerous.states.rows() == d, "barrier check: the near-dangerous states ("
                                                        << p.near_dangerous.source << ") have "
                                                        << p.near_dangerous.states.rows()
                                                        << " features, the barrier expects " << d);
  SECURE_CHECK(p.held_out_safe.has_value() == p.held_out_near_dangerous.has_value(),
               "barrier check: give both held-out classes or neither");
  for (const auto* set : {&p.held_out_safe, &p.held_out_near_dangerous}) {
    if (!set->has_value()) continue;
    data::CheckNonEmptyFinite(**set, "barrier check: held-out states");
    SECURE_CHECK((*set)->states.rows() == d, "barrier check: held-out states ("
                                                 << (*set)->source << ") have "
                                                 << (*set)->states.rows()
                                                 << " features, the barrier expects " << d);
  }
}

// One local search (elitist (1 + lambda) evolution strategy, step x1.5 on success, x0.6 on
// failure). `propose` fills a candidate from the current state and a step; `score` returns the
// objective to MAXIMISE for an eligible candidate, or nullopt if it is not eligible.
template <typename Propose, typename Score>
std::pair<Eigen::VectorXf, double> LocalSearch(const Eigen::VectorXf& start, double start_score,
                                               const BarrierCheckOptions& options, Propose propose,
                                               Score score) {
  Eigen::VectorXf current = start, candidate(start.size()), best_candidate(start.size());
  double current_score = start_score, step = options.search_step;
  for (int it = 0; it < options.search_steps; ++it) {
    double best = -kInf;
    for (int k = 0; k < options.search_population; ++k) {
      propose(current, step, candidate);
      const std::optional<double> s = score(candidate);
      if (s && *s > best) {
        best = *s;
        best_candidate = candidate;
      }
    }
    if (best > current_score) {
      current = best_candidate;
      current_score = best;
      step *= 1.5;
    } else if (best == current_score) {
      current = best_candidate;  // drift along a plateau (e.g. h at a cap), same step
    } else {
      step *= 0.6;
    }
  }
  return {current, current_score};
}

std::string FormatNumber(double v) {
  char buffer[40];
  std::snprintf(buffer, sizeof buffer, "%.9g", v);
  return buffer;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
void CheckThresholds::Validate() const {
  auto check = [](double v, const char* field) {
    SECURE_CHECK_FIELD(std::isfinite(v) && v >= 0 && v <= 1, "CheckThresholds", field, v,
                       "in [0, 1]");
  };
  check(no_safe_action, "no_safe_action");
  check(near_dangerous, "near_dangerous");
  check(unsafe, "unsafe");
  check(min_accuracy_safe, "min_accuracy_safe");
  check(min_accuracy_near_dangerous, "min_accuracy_near_dangerous");
}

nlohmann::json CheckThresholds::ToJson() const {
  return {{"no_safe_action", no_safe_action},
          {"near_dangerous", near_dangerous},
          {"unsafe", unsafe},
          {"min_accuracy_safe", min_accuracy_safe},
          {"min_accuracy_near_dangerous", min_accuracy_near_dangerous}};
}

void BarrierCheckOptions::Validate() const {
  SECURE_CHECK_FIELD(region_samples > 0 && region_samples <= kMaxStates, "BarrierCheckOptions",
                     "region_samples", region_samples, "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(near_samples > 0 && near_samples <= kMaxStates, "BarrierCheckOptions",
                     "near_samples", near_samples, "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(std::isfinite(near_radius) && near_radius > 0, "BarrierCheckOptions",
                     "near_radius", near_radius, "finite and > 0");
  SECURE_CHECK_FIELD(action_grid == 0 || (action_grid >= 2 && action_grid <= 1000),
                     "BarrierCheckOptions", "action_grid", action_grid,
                     "0 (no grid) or in [2, 1000]");
  SECURE_CHECK_FIELD(action_samples >= 0 && action_samples <= kMaxShieldSamples,
                     "BarrierCheckOptions", "action_samples", action_samples,
                     "in [0, " << kMaxShieldSamples << "]");
  SECURE_CHECK_FIELD(action_grid > 0 || action_samples > 0, "BarrierCheckOptions", "action_samples",
                     action_samples, "> 0 when action_grid is 0");
  SECURE_CHECK_FIELD(action_refine_rounds >= 0, "BarrierCheckOptions", "action_refine_rounds",
                     action_refine_rounds, ">= 0");
  SECURE_CHECK_FIELD(search_starts >= 0, "BarrierCheckOptions", "search_starts", search_starts,
                     ">= 0");
  SECURE_CHECK_FIELD(search_steps >= 0, "BarrierCheckOptions", "search_steps", search_steps,
                     ">= 0");
  SECURE_CHECK_FIELD(search_population > 0 && search_population <= kMaxShieldSamples,
                     "BarrierCheckOptions", "search_population", search_population,
                     "in [1, " << kMaxShieldSamples << "]");
  SECURE_CHECK_FIELD(std::isfinite(search_step) && search_step > 0, "BarrierCheckOptions",
                     "search_step", search_step, "finite and > 0");
  SECURE_CHECK_FIELD(worst_examples >= 0, "BarrierCheckOptions", "worst_examples", worst_examples,
                     ">= 0");
  thresholds.Validate();
}

nlohmann::json BarrierCheckOptions::ToJson() const {
  return {{"region_samples", region_samples},
          {"near_samples", near_samples},
          {"near_radius", near_radius},
          {"action_grid", action_grid},
          {"action_samples", action_samples},
          {"action_refine_rounds", action_refine_rounds},
          {"search_starts", search_starts},
          {"search_steps", search_steps},
          {"search_population", search_population},
          {"search_step", search_step},
          {"worst_examples", worst_examples},
          {"seed", seed},
          {"thresholds", thresholds.ToJson()}};
}

void BarrierCheckOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  SECURE_CHECK(node.IsMap(), source << ": expected a mapping of barrier check options");
  for (const auto& item : node) {
    const std::string key = YamlKey(item.first, source);
    const YAML::Node& v = item.second;
    if (key == "region_samples") {
      region_samples = YamlValue<long>(v, key, source);
    } else if (key == "near_samples") {
      near_samples = YamlValue<long>(v, key, source);
    } else if (key == "near_radius") {
      near_radius = YamlValue<double>(v, key, source);
    } else if (key == "action_grid") {
      action_grid = YamlValue<int>(v, key, source);
    } else if (key == "action_samples") {
      action_samples = YamlValue<int>(v, key, source);
    } else if (key == "action_refine_rounds") {
      action_refine_rounds = YamlValue<int>(v, key, source);
    } else if (key == "search_starts") {
      search_starts = YamlValue<int>(v, key, source);
    } else if (key == "search_steps") {
      search_steps = YamlValue<int>(v, key, source);
    } else if (key == "search_population") {
      search_population = YamlValue<int>(v, key, source);
    } else if (key == "search_step") {
      search_step = YamlValue<double>(v, key, source);
    } else if (key == "worst_examples") {
      worst_examples = YamlValue<int>(v, key, source);
    } else if (key == "seed") {
      seed = YamlValue<std::uint64_t>(v, key, source);
    } else if (key == "thresholds") {
      SECURE_CHECK(v.IsMap(), source << ": field 'thresholds' must be a mapping");
      for (const auto& t : v) {
        const std::string name = YamlKey(t.first, source);
        const std::string where = "thresholds." + name;
        if (name == "no_safe_action") {
          thresholds.no_safe_action = YamlValue<double>(t.second, where, source);
        } else if (name == "near_dangerous") {
          thresholds.near_dangerous = YamlValue<double>(t.second, where, source);
        } else if (name == "unsafe") {
          thresholds.unsafe = YamlValue<double>(t.second, where, source);
        } else if (name == "min_accuracy_safe") {
          thresholds.min_accuracy_safe = YamlValue<double>(t.second, where, source);
        } else if (name == "min_accuracy_near_dangerous") {
          thresholds.min_accuracy_near_dangerous = YamlValue<double>(t.second, where, source);
        } else {
          SECURE_THROW(source << ": unknown field '" << where
                              << "' in the barrier check options (valid: no_safe_action, "
                                 "near_dangerous, unsafe, min_accuracy_safe, "
                                 "min_accuracy_near_dangerous)");
        }
      }
    } else {
      SECURE_THROW(source << ": unknown field '" << key
                          << "' in the barrier check options (valid: the keys of "
                             "BarrierCheckOptions::ToJson, e.g. region_samples, near_radius, "
                             "thresholds)");
    }
  }
}

// ---------------------------------------------------------------------------------------------
const CheckKindStats& CheckReport::Stats(CheckKind kind) const {
  switch (kind) {
    case CheckKind::kNoSafeAction:
      return no_safe_action;
    case CheckKind::kNearDangerous:
      return near_dangerous;
    case CheckKind::kUnsafe:
      return unsafe;
  }
  SECURE_INTERNAL_CHECK(false, "unknown check kind");
  return unsafe;
}

nlohmann::json CheckReport::ToJson() const {
  auto number = [](double v) -> nlohmann::json {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  nlohmann::json kinds = nlohmann::json::object();
  const double tau[3] = {thresholds.no_safe_action, thresholds.near_dangerous, thresholds.unsafe};
  for (int k = 0; k < 3; ++k) {
    const auto kind = static_cast<CheckKind>(k);
    const CheckKindStats& s = Stats(kind);
    long examples = 0;
    for (const CheckExample& e : worst) examples += e.kind == kind;
    kinds[ToString(kCheckKindNames, kind)] = {{"available", s.available},
                                              {"checked", s.checked},
                                              {"counterexamples", s.counterexamples},
                                              {"rate", s.rate()},
                                              {"threshold", tau[k]},
                                              {"flagged", s.available && s.rate() > tau[k]},
                                              {"search_counterexamples", s.search_counterexamples},
                                              {"worst_objective", number(s.worst_objective)},
                                              {"examples", examples}};
  }
  nlohmann::json j = {{"verdict", Verdict()},
                      {"flagged", flagged},
                      {"reasons", reasons},
                      {"barrier", barrier},
                      {"dynamics", dynamics},
                      {"region", region},
                      {"unsafe_test", unsafe_test},
                      {"class_k", class_k},
                      {"dt", dt},
                      {"kinds", kinds},
                      {"options", options.ToJson()}};
  if (has_accuracy) {
    j["accuracy"] = {{"held_out_safe", held_out_safe},
                     {"held_out_near_dangerous", held_out_near_dangerous},
                     {"safe", accuracy_safe},
                     {"near_dangerous", accuracy_near_dangerous}};
  } else {
    j["accuracy"] = nullptr;
  }
  return j;
}

std::string CheckReport::Summary() const {
  std::ostringstream out;
  char line[256];
  if (has_accuracy) {
    std::snprintf(line, sizeof line,
                  "held-out accuracy: safe %.4f (%ld states), near-dangerous %.4f (%ld states)\n",
                  accuracy_safe, held_out_safe, accuracy_near_dangerous, held_out_near_dangerous);
    out << line;
  }
  const char* what[3] = {"(a) h >= 0 but no action with g >= 0",
                         "(b) near a near-dangerous state, h >= 0",
                         "(c) unsafe by the domain's test, h >= 0"};
  const double tau[3] = {thresholds.no_safe_action, thresholds.near_dangerous, thresholds.unsafe};
  for (int k = 0; k < 3; ++k) {
    const CheckKindStats& s = Stats(static_cast<CheckKind>(k));
    if (!s.available) {
      out << what[k] << ": not checked (the domain has no unsafe test)\n";
      continue;
    }
    std::snprintf(line, sizeof line,
                  "%s: %ld of %ld sampled (rate %.4f, threshold %g), local search %ld\n", what[k],
                  s.counterexamples, s.checked, s.rate(), tau[k], s.search_counterexamples);
    out << line;
  }
  out << "verdict: " << Verdict();
  for (std::size_t i = 0; i < reasons.size(); ++i) out << (i ? "; " : " (") << reasons[i];
  if (!reasons.empty()) out << ")";
  out << "\n";
  return out.str();
}

void CheckReport::WriteCsv(const std::string& path) const {
  std::string text = "kind,found_by";
  for (const std::string& f : features) text += "," + f;
  text += ",h,objective\n";
  for (const CheckExample& e : worst) {
    text += ToString(kCheckKindNames, e.kind);
    text += e.from_search ? ",search" : ",sample";
    for (long i = 0; i < e.state.size(); ++i) text += "," + FormatNumber(e.state[i]);
    text += "," + FormatNumber(e.h) + "," + FormatNumber(e.objective) + "\n";
  }
  WriteFileAtomically(path, text);
}

// ---------------------------------------------------------------------------------------------
double MaxCbfCondition(Barrier& barrier, const domains::DynamicsModel& dynamics,
                       const BarrierCheckProblem& problem, const BarrierCheckOptions& options,
                       const Eigen::Ref<const Eigen::VectorXf>& state, Rng& rng) {
  ValidateInputs(barrier, dynamics, problem, options);
  SECURE_CHECK(state.size() == barrier.state_dim(),
               "MaxCbfCondition: state has " << state.size() << " values, the barrier expects "
                                             << barrier.state_dim());
  Checker checker(barrier, dynamics, problem, options);
  return checker.MaxG(state, checker.HOne(state), rng);
}

CheckReport CheckBarrier(Barrier& barrier, const domains::DynamicsModel& dynamics,
                         const BarrierCheckProblem& p, const BarrierCheckOptions& o) {
  ValidateInputs(barrier, dynamics, p, o);
  const int d = barrier.state_dim();
  Checker checker(barrier, dynamics, p, o);
  Rng rng(o.seed);
  CheckReport report;
  report.barrier = barrier.Describe();
  report.dynamics = dynamics.Describe();
  report.region = p.region_description;
  report.unsafe_test = p.is_unsafe ? p.is_unsafe_description : "";
  report.class_k = p.class_k_description;
  report.dt = p.dt;
  report.options = o;
  report.thresholds = o.thresholds;
  report.features = p.near_dangerous.features;  // checked: one name per row

  // Held-out accuracy.
  Eigen::VectorXf h;
  if (p.held_out_safe) {
    report.has_accuracy = true;
    checker.H(p.held_out_safe->states, &h);
    report.held_out_safe = p.held_out_safe->size();
    report.accuracy_safe = double((h.array() >= 0.0f).count()) / double(h.size());
    checker.H(p.held_out_near_dangerous->states, &h);
    report.held_out_near_dangerous = p.held_out_near_dangerous->size();
    report.accuracy_near_dangerous = double((h.array() < 0.0f).count()) / double(h.size());
  }

  struct Scored {
    long index;
    double objective;
    double h;  // tie-break: the smaller h first (nearer the boundary)
  };
  std::vector<CheckExample> pool[3];
  auto add_example = [&](CheckKind kind, bool from_search, const Eigen::VectorXf& s, double hv,
                         double objective) {
    pool[static_cast<int>(kind)].push_back({kind, from_search, s, hv, objective});
  };

  // Sampling phase, region: (a) and (c).
  Eigen::MatrixXf region(d, o.region_samples);
  for (long i = 0; i < o.region_samples; ++i) {
    p.sample_region(rng, region.col(i));
    SECURE_CHECK(
        region.col(i).allFinite(),
        "barrier check: the region sampler returned a non-finite state (sample " << i << ")");
  }
  Eigen::VectorXf h_region;
  checker.H(region, &h_region);
  std::vector<Scored> eligible_a, eligible_c;
  report.unsafe.available = static_cast<bool>(p.is_unsafe);
  report.no_safe_action.worst_objective = kInf;
  report.unsafe.worst_objective = -kInf;
  for (long i = 0; i < o.region_samples; ++i) {
    const double hv = h_region[i];
    if (p.is_unsafe && p.is_unsafe(region.col(i))) {
      ++report.unsafe.checked;
      eligible_c.push_back({i, hv, hv});
      report.unsafe.worst_objective = std::max(report.unsafe.worst_objective, hv);
      if (hv >= 0) {
        ++report.unsafe.counterexamples;
        add_example(CheckKind::kUnsafe, false, region.col(i), hv, hv);
      }
    }
    if (hv >= 0) {
      ++report.no_safe_action.checked;
      const double g = checker.MaxG(region.col(i), hv, rng);
      eligible_a.push_back({i, g, hv});
      report.no_safe_action.worst_objective = std::min(report.no_safe_action.worst_objective, g);
      if (g < 0) {
        ++report.no_safe_action.counterexamples;
        add_example(CheckKind::kNoSafeAction, false, region.col(i), hv, g);
      }
    }
  }

  // Sampling phase, near-dangerous: (b).
  Eigen::VectorXd nd_scale = FeatureStd(p.near_dangerous.states);
  for (long i = 0; i < nd_scale.size(); ++i)
    if (!(nd_scale[i] > 0)) nd_scale[i] = 1.0;  // a constant feature: move in feature units
  const Eigen::VectorXd radius = o.near_radius * nd_scale;
  Eigen::MatrixXf near(d, o.near_samples);
  std::vector<long> anchors(static_cast<std::size_t>(o.near_samples));
  const long n_nd = p.near_dangerous.size();
  for (long j = 0; j < o.near_samples; ++j) {
    const long k = static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(n_nd)));
    anchors[static_cast<std::size_t>(j)] = k;
    for (int i = 0; i < d; ++i)
      near(i, j) =
          static_cast<float>(p.near_dangerous.states(i, k) + rng.Uniform(-radius[i], radius[i]));
  }
  Eigen::VectorXf h_near;
  checker.H(near, &h_near);
  std::vector<Scored> eligible_b;
  report.near_dangerous.worst_objective = -kInf;
  for (long j = 0; j < o.near_samples; ++j) {
    const double hv = h_near[j];
    ++report.near_dangerous.checked;
    eligible_b.push_back({j, hv, hv});
    report.near_dangerous.worst_objective = std::max(report.near_dangerous.worst_objective, hv);
    if (hv >= 0) {
      ++report.near_dangerous.counterexamples;
      add_example(CheckKind::kNearDangerous, false, near.col(j), hv, hv);
    }
  }

  // Local search from the most promising samples of each kind.
  const Eigen::VectorXd region_scale = FeatureStd(region);
  auto top = [&](std::vector<Scored> v, bool lowest) {
    std::stable_sort(v.begin(), v.end(), [&](const Scored& x, const Scored& y) {
      if (x.objective != y.objective)
        return lowest ? x.objective < y.objective : x.objective > y.objective;
      return x.h < y.h;
    });
    if (static_cast<long>(v.size()) > o.search_starts) v.resize(o.search_starts);
    return v;
  };
  auto perturb = [&](const Eigen::VectorXd& scale) {
    return [&rng, &p, scale](const Eigen::VectorXf& from, double step, Eigen::VectorXf& to) {
      for (long i = 0; i < from.size(); ++i)
        to[i] = static_cast<float>(from[i] + step * scale[i] * rng.Normal());
      if (p.project) p.project(to);
    };
  };
  // (a): minimise max_a g among states with h >= 0 (maximise its negative).
  for (const Scored& s : top(eligible_a, true)) {
    const auto [state, score] =
        LocalSearch(region.col(s.index), -s.objective, o, perturb(region_scale),
                    [&](const Eigen::VectorXf& c) -> std::optional<double> {
                      if (!c.allFinite()) return std::nullopt;
                      const double hv = checker.HOne(c);
                      if (!(hv >= 0)) return std::nullopt;
                      return -checker.MaxG(c, hv, rng);
                    });
    const double g = -score;
    report.no_safe_action.worst_objective = std::min(report.no_safe_action.worst_objective, g);
    if (g < 0) {
      ++report.no_safe_action.search_counterexamples;
      add_example(CheckKind::kNoSafeAction, true, state, checker.HOne(state), g);
    }
  }
  // (b): maximise h inside the box around the sample's near-dangerous anchor.
  for (const Scored& s : top(eligible_b, false)) {
    const Eigen::VectorXf anchor =
        p.near_dangerous.states.col(anchors[static_cast<std::size_t>(s.index)]);
    const auto [state, score] = LocalSearch(
        near.col(s.index), s.objective, o,
        [&](const Eigen::VectorXf& from, double step, Eigen::VectorXf& to) {
          for (long i = 0; i < from.size(); ++i) {
            const double v = from[i] + step * nd_scale[i] * rng.Normal();
            to[i] = static_cast<float>(std::clamp(v, anchor[i] - radius[i], anchor[i] + radius[i]));
          }
        },
        [&](const Eigen::VectorXf& c) -> std::optional<double> {
          const double hv = checker.HOne(c);
          if (!std::isfinite(hv)) return std::nullopt;
          return hv;
        });
    report.near_dangerous.worst_objective = std::max(report.near_dangerous.worst_objective, score);
    if (score >= 0) {
      ++report.near_dangerous.search_counterexamples;
      add_example(CheckKind::kNearDangerous, true, state, score, score);
    }
  }
  // (c): maximise h among states the predicate calls unsafe.
  if (p.is_unsafe) {
    for (const Scored& s : top(eligible_c, false)) {
      const auto [state, score] =
          LocalSearch(region.col(s.index), s.objective, o, perturb(region_scale),
                      [&](const Eigen::VectorXf& c) -> std::optional<double> {
                        if (!c.allFinite() || !p.is_unsafe(c)) return std::nullopt;
                        const double hv = checker.HOne(c);
                        if (!std::isfinite(hv)) return std::nullopt;
                        return hv;
                      });
      report.unsafe.worst_objective = std::max(report.unsafe.worst_objective, score);
      if (score >= 0) {
        ++report.unsafe.search_counterexamples;
        add_example(CheckKind::kUnsafe, true, state, score, score);
      }
    }
  }
  auto finite_or_nan = [](double& v) {
    if (!std::isfinite(v)) v = std::numeric_limits<double>::quiet_NaN();
  };
  if (report.no_safe_action.checked == 0) finite_or_nan(report.no_safe_action.worst_objective);
  if (report.near_dangerous.checked == 0) finite_or_nan(report.near_dangerous.worst_objective);
  if (report.unsafe.checked == 0) finite_or_nan(report.unsafe.worst_objective);

  // The worst examples per kind.
  for (int k = 0; k < 3; ++k) {
    std::vector<CheckExample>& v = pool[k];
    const bool lowest = k == static_cast<int>(CheckKind::kNoSafeAction);
    std::stable_sort(v.begin(), v.end(), [&](const CheckExample& x, const CheckExample& y) {
      return lowest ? x.objective < y.objective : x.objective > y.objective;
    });
    if (static_cast<long>(v.size()) > o.worst_examples) v.resize(o.worst_examples);
    report.worst.insert(report.worst.end(), v.begin(), v.end());
  }

  // The verdict.
  auto flag = [&](bool condition, const std::string& reason) {
    if (!condition) return;
    report.flagged = true;
    report.reasons.push_back(reason);
  };
  auto rate_reason = [](const char* name, double rate, double tau) {
    char buffer[96];
    std::snprintf(buffer, sizeof buffer, "rate(%s) %.4f > %g", name, rate, tau);
    return std::string(buffer);
  };
  const CheckThresholds& t = o.thresholds;
  flag(report.no_safe_action.rate() > t.no_safe_action,
       rate_reason("a", report.no_safe_action.rate(), t.no_safe_action));
  flag(report.near_dangerous.rate() > t.near_dangerous,
       rate_reason("b", report.near_dangerous.rate(), t.near_dangerous));
  flag(report.unsafe.available && report.unsafe.rate() > t.unsafe,
       rate_reason("c", report.unsafe.rate(), t.unsafe));
  if (report.has_accuracy) {
    char buffer[96];
    std::snprintf(buffer, sizeof buffer, "held-out safe accuracy %.4f < %g", report.accuracy_safe,
                  t.min_accuracy_safe);
    flag(report.accuracy_safe < t.min_accuracy_safe, buffer);
    std::snprintf(buffer, sizeof buffer, "held-out near-dangerous accuracy %.4f < %g",
                  report.accuracy_near_dangerous, t.min_accuracy_near_dangerous);
    flag(report.accuracy_near_dangerous < t.min_accuracy_near_dangerous, buffer);
  }
  return report;
}

data::StateSet ReadCheckStates(const std::string& path, const std::vector<std::string>& features) {
  // A check without counterexamples writes a header-only file: that adds no states.
  CheckRegularInputFile(path);  // no FIFO, no device, within the input limit
  std::ifstream in(path);
  SECURE_CHECK(in.good(), path << ": cannot open the check CSV");
  std::string header, line;
  std::getline(in, header);
  bool has_rows = false;
  while (std::getline(in, line))
    if (line.find_first_not_of(" \t\r") != std::string::npos) has_rows = true;
  if (!has_rows) {
    data::StateSet empty;
    empty.source = path;
    empty.features = features;
    empty.states.resize(static_cast<long>(features.size()), 0);
    // Still check the columns, so that a file for another model is caught.
    std::set<std::string> names;
    std::stringstream cells(header);
    std::string cell;
    while (std::getline(cells, cell, ',')) {
      while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
      names.insert(cell);
    }
    for (const std::string& f : features)
      SECURE_CHECK(names.count(f), path << ": the check CSV has no column '" << f
                                        << "' (its header: " << header << ")");
    return empty;
  }
  return data::ReadStateSet(path, features);
}

}  // namespace secure::cbf
