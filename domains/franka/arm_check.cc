#include "domains/franka/arm_check.h"

#include <utility>

#include "secure/common/enum_strings.h"
#include "secure/common/error.h"

namespace secure::domains::franka {

OwnedShieldModel::OwnedShieldModel(std::unique_ptr<Environment> environment)
    : environment_(std::move(environment)), model_(nullptr) {
  SECURE_CHECK(environment_ != nullptr, "OwnedShieldModel: no environment");
  model_ = &environment_->ShieldModel();
}

void OwnedShieldModel::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                              const Eigen::Ref<const Eigen::MatrixXf>& actions,
                              Eigen::Ref<Eigen::MatrixXf> next_states) const {
  model_->Step(state, actions, next_states);
}

void AddNoise(Rng& rng, double sd, int offset, int count, Eigen::Ref<Eigen::VectorXf> state) {
  for (int i = offset; i < offset + count; ++i) state[i] += static_cast<float>(sd * rng.Normal());
}

cbf::BarrierCheckProblem ArmCheckProblem(const ArmCheckSpec& spec,
                                         std::unique_ptr<Environment> environment,
                                         const shield::ShieldOptions& shield,
                                         const data::StateSet& safe,
                                         const data::StateSet& near_dangerous,
                                         std::unique_ptr<DynamicsModel>* dynamics) {
  SECURE_CHECK(environment != nullptr, "the " << spec.domain << " barrier check: no environment");
  SECURE_CHECK(static_cast<bool>(spec.perturb),
               "the " << spec.domain << " barrier check: no region perturbation");
  const int d = environment->observation_dim(), n = environment->action_dim();
  SECURE_CHECK(safe.states.rows() == d && near_dangerous.states.rows() == d,
               "the " << spec.domain << " barrier check needs observations of " << d
                      << " values; got " << safe.states.rows() << " (" << safe.source << ") and "
                      << near_dangerous.states.rows() << " (" << near_dangerous.source << ")");
  data::CheckNonEmptyFinite(safe, "the " + spec.domain + " barrier check: safe states");
  data::CheckNonEmptyFinite(near_dangerous,
                            "the " + spec.domain + " barrier check: near-dangerous states");
  shield.Validate();
  *dynamics = std::make_unique<OwnedShieldModel>(std::move(environment));

  cbf::BarrierCheckProblem p;
  p.action_lo = Eigen::VectorXf::Constant(n, -1.0f);
  p.action_hi = Eigen::VectorXf::Constant(n, 1.0f);
  p.dt = shield.dt;
  p.class_k = [shield](double h) { return shield::ClassKValue(shield, h); };
  p.class_k_description = ToString(shield::kClassKNames, shield.class_k) +
                          ", k = " + std::to_string(shield.class_k_gain);
  p.near_dangerous = near_dangerous;
  p.held_out_safe = safe;
  p.held_out_near_dangerous = near_dangerous;
  const Eigen::MatrixXf safe_states = safe.states, nd_states = near_dangerous.states;
  const auto perturb = spec.perturb;
  const auto project = spec.project;
  p.sample_region = [safe_states, nd_states, perturb, project](Rng& rng,
                                                               Eigen::Ref<Eigen::VectorXf> s) {
    const bool from_safe = rng.Uniform() < 0.5;
    const Eigen::MatrixXf& pool = from_safe ? safe_states : nd_states;
    s = pool.col(static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(pool.cols()))));
    perturb(rng, s);
    if (project) project(s);
  };
  p.project = project;
  p.is_unsafe = spec.is_unsafe;
  p.is_unsafe_description = spec.is_unsafe ? spec.is_unsafe_description : "";
  p.region_description = spec.region_description;
  return p;
}

}  // namespace secure::domains::franka
