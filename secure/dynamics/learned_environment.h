#pragma once
// An environment whose shield model is a learned dynamics ensemble: every method delegates to the
// wrapped environment except ShieldModel() (an EnsembleModel of its own) and ShieldModelIsExact()
// (false). `secure eval --dynamics PATH` and `secure experiment model-source` shield through it;
// the evaluation harness pairs the barrier with it through dynamics::ForShieldModel (pessimistic
// over the members).

#include <memory>
#include <string>
#include <vector>

#include "secure/domains/forwarding_environment.h"
#include "secure/dynamics/ensemble.h"

namespace secure::dynamics {

class LearnedModelEnvironment final : public domains::ForwardingEnvironment {
 public:
  /// @throws secure::Error if the model's state / action features are not the environment's
  ///   observation / action features (in order), naming `source` (the model file).
  LearnedModelEnvironment(std::unique_ptr<domains::Environment> inner,
                          std::shared_ptr<const EnsembleDynamics> model, const std::string& source,
                          int max_batch = 1024, PessimismOptions pessimism = {});

  std::string Describe() const override;
  const domains::DynamicsModel& ShieldModel() const override { return model_; }
  bool ShieldModelIsExact() const override { return false; }
  std::unique_ptr<domains::Environment> Clone() const override;

  const EnsembleModel& learned_model() const { return model_; }

 private:
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
