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

// CheckBarrier's phases, in the order they draw from the check's one random stream: held-out
// accuracy, sampling the region ((a), (c)) and the near-dangerous neighbourhood ((b)), local
// search from the most promising samples of each kind, then the worst examples and the verdict.
class CheckRun {
 public:
  CheckRun(Barrier& barrier, const domains::DynamicsModel& dynamics, const BarrierCheckProblem& p,
           const BarrierCheckOptions& o)
      : p_(p), o_(o), d_(barrier.state_dim()), checker_(barrier, dynamics, p, o), rng_(o.seed) {
    report_.barrier = barrier.Describe();
    report_.dynamics = dynamics.Describe();
  }

  CheckReport Run() {
    report_.region = p_.region_description;
    report_.unsafe_test = p_.is_unsafe ? p_.is_unsafe_description : "";
    report_.class_k = p_.class_k_description;
    report_.dt = p_.dt;
    report_.options = o_;
    report_.thresholds = o_.thresholds;
    report_.features = p_.near_dangerous.features;  // checked: one name per row
    HeldOutAccuracy();
    SampleRegion();
    SampleNearDangerous();
    region_scale_ = FeatureStd(region_);
    SearchNoSafeAction();
    SearchNearDangerous();
    if (p_.is_unsafe) SearchUnsafe();
    auto finite_or_nan = [](double& v) {
      if (!std::isfinite(v)) v = std::numeric_limits<double>::quiet_NaN();
    };
    if (report_.no_safe_action.checked == 0) finite_or_nan(report_.no_safe_action.worst_objective);
    if (report_.near_dangerous.checked == 0) finite_or_nan(report_.near_dangerous.worst_objective);
    if (report_.unsafe.checked == 0) finite_or_nan(report_.unsafe.worst_objective);
    KeepWorst();
    Verdict();
    return std::move(report_);
  }

 private:
  struct Scored {
    long index;
    double objective;
    double h;  // tie-break: the smaller h first (nearer the boundary)
  };

  void AddExample(CheckKind kind, bool from_search, const Eigen::VectorXf& s, double hv,
                  double objective) {
    pool_[static_cast<int>(kind)].push_back({kind, from_search, s, hv, objective});
  }

  void HeldOutAccuracy() {
    if (!p_.held_out_safe) return;
    Eigen::VectorXf h;
    report_.has_accuracy = true;
    checker_.H(p_.held_out_safe->states, &h);
    report_.held_out_safe = p_.held_out_safe->size();
    report_.accuracy_safe = double((h.array() >= 0.0f).count()) / double(h.size());
    checker_.H(p_.held_out_near_dangerous->states, &h);
    report_.held_out_near_dangerous = p_.held_out_near_dangerous->size();
    report_.accuracy_near_dangerous = double((h.array() < 0.0f).count()) / double(h.size());
  }

  // Sampling phase, region: (a) and (c).
  void SampleRegion() {
    region_.resize(d_, o_.region_samples);
    for (long i = 0; i < o_.region_samples; ++i) {
      p_.sample_region(rng_, region_.col(i));
      SECURE_CHECK(
          region_.col(i).allFinite(),
          "barrier check: the region sampler returned a non-finite state (sample " << i << ")");
    }
    Eigen::VectorXf h_region;
    checker_.H(region_, &h_region);
    report_.unsafe.available = static_cast<bool>(p_.is_unsafe);
    report_.no_safe_action.worst_objective = kInf;
    report_.unsafe.worst_objective = -kInf;
    for (long i = 0; i < o_.region_samples; ++i) {
      const double hv = h_region[i];
      if (p_.is_unsafe && p_.is_unsafe(region_.col(i))) {
        ++report_.unsafe.checked;
        eligible_c_.push_back({i, hv, hv});
        report_.unsafe.worst_objective = std::max(report_.unsafe.worst_objective, hv);
        if (hv >= 0) {
          ++report_.unsafe.counterexamples;
          AddExample(CheckKind::kUnsafe, false, region_.col(i), hv, hv);
        }
      }
      if (hv >= 0) {
        ++report_.no_safe_action.checked;
        const double g = checker_.MaxG(region_.col(i), hv, rng_);
        eligible_a_.push_back({i, g, hv});
        report_.no_safe_action.worst_objective =
            std::min(report_.no_safe_action.worst_objective, g);
        if (g < 0) {
          ++report_.no_safe_action.counterexamples;
          AddExample(CheckKind::kNoSafeAction, false, region_.col(i), hv, g);
        }
      }
    }
  }

  // Sampling phase, near-dangerous: (b).
  void SampleNearDangerous() {
    nd_scale_ = FeatureStd(p_.near_dangerous.states);
    for (long i = 0; i < nd_scale_.size(); ++i)
      if (!(nd_scale_[i] > 0)) nd_scale_[i] = 1.0;  // a constant feature: move in feature units
    radius_ = o_.near_radius * nd_scale_;
    near_.resize(d_, o_.near_samples);
    anchors_.resize(static_cast<std::size_t>(o_.near_samples));
    const long n_nd = p_.near_dangerous.size();
    for (long j = 0; j < o_.near_samples; ++j) {
      const long k = static_cast<long>(rng_.UniformIndex(static_cast<std::uint64_t>(n_nd)));
      anchors_[static_cast<std::size_t>(j)] = k;
      for (int i = 0; i < d_; ++i)
        near_(i, j) = static_cast<float>(p_.near_dangerous.states(i, k) +
                                         rng_.Uniform(-radius_[i], radius_[i]));
    }
    Eigen::VectorXf h_near;
    checker_.H(near_, &h_near);
    report_.near_dangerous.worst_objective = -kInf;
    for (long j = 0; j < o_.near_samples; ++j) {
      const double hv = h_near[j];
      ++report_.near_dangerous.checked;
      eligible_b_.push_back({j, hv, hv});
      report_.near_dangerous.worst_objective =
          std::max(report_.near_dangerous.worst_objective, hv);
      if (hv >= 0) {
        ++report_.near_dangerous.counterexamples;
        AddExample(CheckKind::kNearDangerous, false, near_.col(j), hv, hv);
      }
    }
  }

  // The `search_starts` samples with the lowest (or highest) objective.
  std::vector<Scored> Top(std::vector<Scored> v, bool lowest) const {
    std::stable_sort(v.begin(), v.end(), [&](const Scored& x, const Scored& y) {
      if (x.objective != y.objective)
        return lowest ? x.objective < y.objective : x.objective > y.objective;
      return x.h < y.h;
    });
    if (static_cast<long>(v.size()) > o_.search_starts) v.resize(o_.search_starts);
    return v;
  }
  auto Perturb(const Eigen::VectorXd& scale) {
    return [this, scale](const Eigen::VectorXf& from, double step, Eigen::VectorXf& to) {
      for (long i = 0; i < from.size(); ++i)
        to[i] = static_cast<float>(from[i] + step * scale[i] * rng_.Normal());
      if (p_.project) p_.project(to);
    };
  }

  // (a): minimise max_a g among states with h >= 0 (maximise its negative).
  void SearchNoSafeAction() {
    for (const Scored& s : Top(eligible_a_, true)) {
      const auto [state, score] =
          LocalSearch(region_.col(s.index), -s.objective, o_, Perturb(region_scale_),
                      [&](const Eigen::VectorXf& c) -> std::optional<double> {
                        if (!c.allFinite()) return std::nullopt;
                        const double hv = checker_.HOne(c);
                        if (!(hv >= 0)) return std::nullopt;
                        return -checker_.MaxG(c, hv, rng_);
                      });
      const double g = -score;
      report_.no_safe_action.worst_objective =
          std::min(report_.no_safe_action.worst_objective, g);
      if (g < 0) {
        ++report_.no_safe_action.search_counterexamples;
        AddExample(CheckKind::kNoSafeAction, true, state, checker_.HOne(state), g);
      }
    }
  }

  // (b): maximise h inside the box around the sample's near-dangerous anchor.
  void SearchNearDangerous() {
    for (const Scored& s : Top(eligible_b_, false)) {
      const Eigen::VectorXf anchor =
          p_.near_dangerous.states.col(anchors_[static_cast<std::size_t>(s.index)]);
      const auto [state, score] = LocalSearch(
          near_.col(s.index), s.objective, o_,
          [&](const Eigen::VectorXf& from, double step, Eigen::VectorXf& to) {
            for (long i = 0; i < from.size(); ++i) {
              const double v = from[i] + step * nd_scale_[i] * rng_.Normal();
              to[i] = static_cast<float>(
                  std::clamp(v, anchor[i] - radius_[i], anchor[i] + radius_[i]));
            }
          },
          [&](const Eigen::VectorXf& c) -> std::optional<double> {
            const double hv = checker_.HOne(c);
            if (!std::isfinite(hv)) return std::nullopt;
            return hv;
          });
      report_.near_dangerous.worst_objective =
          std::max(report_.near_dangerous.worst_objective, score);
      if (score >= 0) {
        ++report_.near_dangerous.search_counterexamples;
        AddExample(CheckKind::kNearDangerous, true, state, score, score);
      }
    }
  }

  // (c): maximise h among states the predicate calls unsafe.
  void SearchUnsafe() {
    for (const Scored& s : Top(eligible_c_, false)) {
      const auto [state, score] =
          LocalSearch(region_.col(s.index), s.objective, o_, Perturb(region_scale_),
                      [&](const Eigen::VectorXf& c) -> std::optional<double> {
                        if (!c.allFinite() || !p_.is_unsafe(c)) return std::nullopt;
                        const double hv = checker_.HOne(c);
                        if (!std::isfinite(hv)) return std::nullopt;
                        return hv;
                      });
      report_.unsafe.worst_objective = std::max(report_.unsafe.worst_objective, score);
      if (score >= 0) {
        ++report_.unsafe.search_counterexamples;
        AddExample(CheckKind::kUnsafe, true, state, score, score);
      }
    }
  }

  // The worst examples per kind.
  void KeepWorst() {
    for (int k = 0; k < 3; ++k) {
      std::vector<CheckExample>& v = pool_[k];
      const bool lowest = k == static_cast<int>(CheckKind::kNoSafeAction);
      std::stable_sort(v.begin(), v.end(), [&](const CheckExample& x, const CheckExample& y) {
        return lowest ? x.objective < y.objective : x.objective > y.objective;
      });
      if (static_cast<long>(v.size()) > o_.worst_examples) v.resize(o_.worst_examples);
      report_.worst.insert(report_.worst.end(), v.begin(), v.end());
    }
  }

  void Verdict() {
    auto flag = [&](bool condition, const std::string& reason) {
      if (!condition) return;
      report_.flagged = true;
      report_.reasons.push_back(reason);
    };
    auto rate_reason = [](const char* name, double rate, double tau) {
      char buffer[96];
      std::snprintf(buffer, sizeof buffer, "rate(%s) %.4f > %g", name, rate, tau);
      return std::string(buffer);
    };
    const CheckThresholds& t = o_.thresholds;
    flag(report_.no_safe_action.rate() > t.no_safe_action,
         rate_reason("a", report_.no_safe_action.rate(), t.no_safe_action));
    flag(report_.near_dangerous.rate() > t.near_dangerous,
         rate_reason("b", report_.near_dangerous.rate(), t.near_dangerous));
    flag(report_.unsafe.available && report_.unsafe.rate() > t.unsafe,
         rate_reason("c", report_.unsafe.rate(), t.unsafe));
    if (report_.has_accuracy) {
      char buffer[96];
      std::snprintf(buffer, sizeof buffer, "held-out safe accuracy %.4f < %g",
                    report_.accuracy_safe, t.min_accuracy_safe);
      flag(report_.accuracy_safe < t.min_accuracy_safe, buffer);
      std::snprintf(buffer, sizeof buffer, "held-out near-dangerous accuracy %.4f < %g",
                    report_.accuracy_near_dangerous, t.min_accuracy_near_dangerous);
      flag(report_.accuracy_near_dangerous < t.min_accuracy_near_dangerous, buffer);
    }
  }

  const BarrierCheckProblem& p_;
  const BarrierCheckOptions& o_;
  const int d_;
  Checker checker_;
  Rng rng_;
  CheckReport report_;
  std::vector<CheckExample> pool_[3];
  Eigen::MatrixXf region_, near_;
  std::vector<Scored> eligible_a_, eligible_b_, eligible_c_;
  std::vector<long> anchors_;
  Eigen::VectorXd nd_scale_, radius_, region_scale_;
};

}  // namespace

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
  return CheckRun(barrier, dynamics, p, o).Run();
}

}  // namespace secure::cbf
