#include "secure/experiments/check_problem.h"

#include <cstdint>
#include <utility>

#include "secure/common/enum_strings.h"
#include "secure/common/error.h"

namespace secure::experiments {

cbf::BarrierCheckProblem CheckProblemBase(const std::string& domain, int state_dim, int action_dim,
                                          double action_bound, const shield::ShieldOptions& shield,
                                          const data::StateSet& safe,
                                          const data::StateSet& near_dangerous) {
  SECURE_CHECK(safe.states.rows() == state_dim && near_dangerous.states.rows() == state_dim,
               "the " << domain << " barrier check needs states of " << state_dim << " values; got "
                      << safe.states.rows() << " (" << safe.source << ") and "
                      << near_dangerous.states.rows() << " (" << near_dangerous.source << ")");
  data::CheckNonEmptyFinite(safe, "the " + domain + " barrier check: safe states");
  data::CheckNonEmptyFinite(near_dangerous,
                            "the " + domain + " barrier check: near-dangerous states");
  shield.Validate();
  cbf::BarrierCheckProblem p;
  p.action_lo = Eigen::VectorXf::Constant(action_dim, -static_cast<float>(action_bound));
  p.action_hi = Eigen::VectorXf::Constant(action_dim, static_cast<float>(action_bound));
  p.dt = shield.dt;
  p.class_k = [shield](double h) { return shield::ClassKValue(shield, h); };
  p.class_k_description = ToString(shield::kClassKNames, shield.class_k) +
                          ", k = " + std::to_string(shield.class_k_gain);
  p.near_dangerous = near_dangerous;
  p.held_out_safe = safe;
  p.held_out_near_dangerous = near_dangerous;
  return p;
}

std::function<void(Rng&, Eigen::Ref<Eigen::VectorXf>)> PerturbedHeldOutRegion(
    const data::StateSet& safe, const data::StateSet& near_dangerous,
    std::function<void(Rng&, Eigen::Ref<Eigen::VectorXf>)> perturb,
    std::function<void(Eigen::Ref<Eigen::VectorXf>)> project) {
  const Eigen::MatrixXf safe_states = safe.states, nd_states = near_dangerous.states;
  return [safe_states, nd_states, perturb = std::move(perturb), project = std::move(project)](
             Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
    const bool from_safe = rng.Uniform() < 0.5;
    const Eigen::MatrixXf& pool = from_safe ? safe_states : nd_states;
    s = pool.col(static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(pool.cols()))));
    perturb(rng, s);
    if (project) project(s);
  };
}

}  // namespace secure::experiments
