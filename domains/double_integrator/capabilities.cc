// DoubleIntegratorDomain's ground-truth sampler, Table 1's trainer preset and paper numbers, and
// its shield run: what the generic ground-truth study, `cbf train --domain` and `secure shield
// run` reach through experiments::Domain (domain.h).
#include <utility>

#include "domains/double_integrator/domain.h"
#include "domains/double_integrator/shield_run.h"
#include "domains/double_integrator/table1.h"
#include "secure/common/error.h"
#include <string>

namespace secure::domains::double_integrator {

experiments::GroundTruthSample DoubleIntegratorDomain::SampleGroundTruth(
    long n_safe, long n_unsafe, std::uint64_t seed) const {
  options_.task.truth.Validate();
  cbf::DoubleIntegratorData d =
      cbf::SampleDoubleIntegratorData(options_.task.truth, StateBox{}, n_safe, n_unsafe, seed);
  return {std::move(d.safe), std::move(d.unsafe)};
}

cbf::BarrierTrainerOptions DoubleIntegratorDomain::GroundTruthTrainerPreset() const {
  return cbf::DoubleIntegratorTrainerPreset();
}

nlohmann::json DoubleIntegratorDomain::GroundTruthJson() const {
  const GroundTruth& t = options_.task.truth;
  return {{"obstacle", {t.obstacle_x, t.obstacle_y}}, {"radius", t.radius}, {"gamma", t.gamma}};
}

std::optional<experiments::PaperGroundTruthStudy>
DoubleIntegratorDomain::PaperGroundTruthReference() const {
  experiments::PaperGroundTruthStudy p;
  p.over_conservative = 1.9;
  p.over_conservative_std = 1.0;
  p.under_conservative = 4.1;
  p.under_conservative_std = 2.2;
  return p;
}

experiments::ShieldRunRequest DoubleIntegratorDomain::ShieldRunPreset() const {
  const eval::ShieldRunOptions defaults;  // shield_run.h: why these values
  experiments::ShieldRunRequest r;
  r.episodes = defaults.episodes;
  r.seed = defaults.seed;
  r.policy_sigma = defaults.policy_sigma;
  r.shield = defaults.shield;
  r.shield.dt = options_.task.dt;
  return r;
}

experiments::ShieldRunReport DoubleIntegratorDomain::RunShield(
    const experiments::ShieldRunRequest& request, cbf::Barrier& barrier) const {
  eval::ShieldRunOptions o;
  o.task = options_.task;
  o.episodes = request.episodes;
  o.seed = request.seed;
  o.policy_sigma = request.policy_sigma;
  o.shield = request.shield;
  o.shield.dt = o.task.dt;  // the shield looks ahead exactly one control period
  o.record_states = request.record_states;
  o.Validate();
  const eval::ShieldRunResult result = eval::RunDoubleIntegratorShield(o, barrier, request.shielded);
  experiments::ShieldRunReport report{result.ToJson(), result.Table(), {}};
  report.visited.source = "states visited by the shielded run (seed " +
                          std::to_string(request.seed) + ")";
  report.visited.features = StateFeatures();
  report.visited.states = result.visited;
  return report;
}

}  // namespace secure::domains::double_integrator
