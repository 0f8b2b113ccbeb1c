#pragma once
// An environment whose shield model is a learned dynamics ensemble: every method delegates to the
// wrapped environment except ShieldModel() (an EnsembleModel of its own) and ShieldModelIsExact()
// (false). `secure eval --dynamics PATH` and `secure experiment model-source` shield through it;
// the evaluation harness pairs the barrier with it through dynamics::ForShieldModel (pessimistic
// over the members).

#include <memory>
#include <string>
#include <vector>

#include "secure/domains/environment.h"
#include "secure/dynamics/ensemble.h"

namespace secure::dynamics {

class LearnedModelEnvironment final : public domains::Environment {
 public:
  /// @throws secure::Error if the model's state / action features are not the environment's
  ///   observation / action features (in order), naming `source` (the model file).
  LearnedModelEnvironment(std::unique_ptr<domains::Environment> inner,
                          std::shared_ptr<const EnsembleDynamics> model, const std::string& source,
                          int max_batch = 1024, PessimismOptions pessimism = {});

  int observation_dim() const override { return inner_->observation_dim(); }
  int action_dim() const override { return inner_->action_dim(); }
  std::vector<std::string> ObservationFeatures() const override {
    return inner_->ObservationFeatures();
  }
  std::vector<std::string> ActionFeatures() const override { return inner_->ActionFeatures(); }
  int max_steps() const override { return inner_->max_steps(); }
  std::string Describe() const override;
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    inner_->Reset(rng, observation);
  }
  domains::StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                            Eigen::Ref<Eigen::VectorXf> observation) override {
    return inner_->Step(action, observation);
  }
  const domains::DynamicsModel& ShieldModel() const override { return model_; }
  bool ShieldModelIsExact() const override { return false; }
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override {
    return inner_->BackupAction(observation, action);
  }
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low,
                    Eigen::Ref<Eigen::VectorXf> high) const override {
    inner_->ActionBounds(low, high);
  }
  double control_period() const override { return inner_->control_period(); }
  bool CanRender() const override { return inner_->CanRender(); }
  void Render(int width, int height, domains::Frame* frame) override {
    inner_->Render(width, height, frame);
  }
  std::unique_ptr<domains::Environment> Clone() const override;

  const EnsembleModel& learned_model() const { return model_; }
  domains::Environment& inner() { return *inner_; }

 private:
  std::unique_ptr<domains::Environment> inner_;
  std::string source_;
  EnsembleModel model_;
};

/// The features check LearnedModelEnvironment makes: the model's state and action features are
/// `observation_features` and `action_features`. @throws secure::Error naming `source`.
void CheckModelFeatures(const EnsembleDynamics& model,
                        const std::vector<std::string>& observation_features,
                        const std::vector<std::string>& action_features,
                        const std::string& source);

}  // namespace secure::dynamics
