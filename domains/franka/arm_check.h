#pragma once
// What the Franka plug-ins' barrier checks (cbf/barrier_check.h; experiments::Domain::
// MakeCheckProblem) share: the environment's own shield model as the check's dynamics (owned, so
// that it outlives the check), the action box every plug-in clips its action to ([-1, 1]^n), dt
// and class-K from the shield's options, and a region of held-out observations perturbed by the
// plug-in's own noise. Each plug-in adds its perturbation, its unsafe test (computed from the
// observation) and its descriptions. Includes no MuJoCo header.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "secure/cbf/barrier_check.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"
#include "secure/shield/shield.h"

namespace secure::domains::franka {

/// An environment's shield model (Environment::ShieldModel()) that owns the environment, so that
/// the model stays valid as long as this object (the check's dynamics, returned through
/// MakeCheckProblem's `dynamics`). Step() is the environment's model's; one thread at a time.
class OwnedShieldModel final : public DynamicsModel {
 public:
  /// @throws secure::Error if `environment` is null.
  explicit OwnedShieldModel(std::unique_ptr<Environment> environment);
  int state_dim() const override { return model_->state_dim(); }
  int action_dim() const override { return model_->action_dim(); }
  std::string Describe() const override { return model_->Describe(); }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  std::unique_ptr<Environment> environment_;
  const DynamicsModel* model_;
};

/// A plug-in's part of its check problem.
struct ArmCheckSpec {
  std::string domain;  // the registry name, for errors ("kitchen-cutting")
  /// Perturbs a held-out observation (copied into `state`) in place: the region's noise.
  std::function<void(Rng&, Eigen::Ref<Eigen::VectorXf>)> perturb;
  /// Optional: makes a state consistent again after the noise or a local-search move (e.g. a
  /// feature computed from others, a physical bound); applied after `perturb` too.
  std::function<void(Eigen::Ref<Eigen::VectorXf>)> project;
  /// Optional: the domain's dangerous test computed from the observation, for (c).
  std::function<bool(const Eigen::Ref<const Eigen::VectorXf>&)> is_unsafe;
  std::string is_unsafe_description;
  std::string region_description;  // what `perturb` does, for reports
};

/// The check's problem on an arm plug-in:
///  - dynamics: `environment`'s ShieldModel(), owned by *dynamics (OwnedShieldModel);
///  - action box: [-1, 1]^action_dim (the Franka plug-ins clip every action to it);
///  - dt, class-K and gain: `shield`'s;
///  - region: a state of `safe` or of `near_dangerous` (each with probability 1/2), perturbed by
///    spec.perturb, then spec.project;
///  - (c): spec.is_unsafe (none if empty); (b) and the held-out accuracy: `near_dangerous` and
///    `safe`, which must be observations of `environment` (the problem keeps copies).
/// @throws secure::Error on states of another dimension, empty or non-finite sets, invalid
///   shield options, or a spec without `perturb`.
cbf::BarrierCheckProblem ArmCheckProblem(const ArmCheckSpec& spec,
                                         std::unique_ptr<Environment> environment,
                                         const shield::ShieldOptions& shield,
                                         const data::StateSet& safe,
                                         const data::StateSet& near_dangerous,
                                         std::unique_ptr<DynamicsModel>* dynamics);

/// Marks held-out check states (Domain::CheckHeldOut) in their sources: appends
/// " (held out, data_seed N)" to safe->source and near_dangerous->source.
void MarkHeldOut(std::uint64_t data_seed, data::StateSet* safe, data::StateSet* near_dangerous);

/// Adds N(0, sd^2) to each of the `count` features from `offset`.
void AddNoise(Rng& rng, double sd, int offset, int count, Eigen::Ref<Eigen::VectorXf> state);

}  // namespace secure::domains::franka
