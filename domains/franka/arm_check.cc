#include "domains/franka/arm_check.h"

#include <utility>

#include "secure/common/error.h"
#include "secure/experiments/check_problem.h"

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
  cbf::BarrierCheckProblem p =
      experiments::CheckProblemBase(spec.domain, environment->observation_dim(),
                                    environment->action_dim(), 1.0, shield, safe, near_dangerous);
  *dynamics = std::make_unique<OwnedShieldModel>(std::move(environment));
  p.sample_region =
      experiments::PerturbedHeldOutRegion(safe, near_dangerous, spec.perturb, spec.project);
  p.project = spec.project;
  p.is_unsafe = spec.is_unsafe;
  p.is_unsafe_description = spec.is_unsafe ? spec.is_unsafe_description : "";
  p.region_description = spec.region_description;
  return p;
}

void MarkHeldOut(std::uint64_t data_seed, data::StateSet* safe, data::StateSet* near_dangerous) {
  const std::string seed = " (held out, data_seed " + std::to_string(data_seed) + ")";
  safe->source += seed;
  near_dangerous->source += seed;
}

}  // namespace secure::domains::franka
