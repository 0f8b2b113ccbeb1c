#include "secure/dynamics/learned_environment.h"

#include <utility>

#include "secure/common/error.h"
#include "secure/common/strings.h"

namespace secure::dynamics {

void CheckModelFeatures(const EnsembleDynamics& model,
                        const std::vector<std::string>& observation_features,
                        const std::vector<std::string>& action_features,
                        const std::string& source) {
  SECURE_CHECK(model.state_features == observation_features,
               source << ": the learned dynamics predicts " << model.state_dim() << " features ("
                      << Join(model.state_features) << "), the environment observes "
                      << observation_features.size() << " (" << Join(observation_features) << ")");
  SECURE_CHECK(model.action_features == action_features,
               source << ": the learned dynamics reads " << model.action_dim() << " actions ("
                      << Join(model.action_features) << "), the environment takes "
                      << action_features.size() << " (" << Join(action_features) << ")");
}

LearnedModelEnvironment::LearnedModelEnvironment(std::unique_ptr<domains::Environment> inner,
                                                 std::shared_ptr<const EnsembleDynamics> model,
                                                 const std::string& source, int max_batch,
                                                 PessimismOptions pessimism)
    : ForwardingEnvironment(std::move(inner)),
      source_(source),
      model_(std::move(model), max_batch, nn::MatmulBackend::kAuto, pessimism) {
  SECURE_CHECK(inner_ != nullptr, "LearnedModelEnvironment: no environment");
  CheckModelFeatures(model_.model(), inner_->ObservationFeatures(), inner_->ActionFeatures(),
                     source_);
}

std::string LearnedModelEnvironment::Describe() const {
  return inner_->Describe() + "; shield model: " + model_.Describe() + " (" + source_ +
         "), pessimism " + model_.pessimism().Describe();
}

std::unique_ptr<domains::Environment> LearnedModelEnvironment::Clone() const {
  return std::make_unique<LearnedModelEnvironment>(inner_->Clone(), model_.shared_model(), source_,
                                                   model_.max_batch(), model_.pessimism());
}

}  // namespace secure::dynamics
