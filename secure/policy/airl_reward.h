#pragma once
// AIRL's learned reward as a run-time model: the discriminator's reward g(s) and shaping V(s)
// (airl_trainer.h), exported after training so that the shield can rank actions by the task
// (shield::Aggregation::kTopQ, as the authors' code does; official-code-facts.md §4.5):
//
//   Q(s, a) = g(s) + gamma V(T(s, a))        (gamma: AIRL's RL discount, 0.99 by default)
//
// with T(s, a) the shield model's predicted next state. Both networks read the same normalised
// input features as the AIRL policy they were trained with. No LibTorch.
//
//   policy::AirlRewardModel reward = policy::AirlRewardModel::Load("airl_reward.model");
//   policy::AirlActionValue value(reward, env.ObservationFeatures(), /*max_batch=*/64);
//   shield.SetActionValue(&value);                  // with ShieldOptions::aggregation = top-q
//
// Model file (kind "airl_reward", nn/model_file.h): tensors "reward.layer<i>.weight/.bias",
// "shaping.layer<i>.weight/.bias" (nn::AddMlp), "input.mean" / "input.scale"; metadata
// "observation_features", "input_features" (when the networks read only some of them),
// "discount" and "provenance".

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"
#include "secure/shield/shield.h"

namespace secure::policy {

inline constexpr const char* kAirlRewardKind = "airl_reward";

struct AirlRewardModel {
  nn::MlpParams reward;    // g: input_dim -> 1
  nn::MlpParams shaping;   // V: input_dim -> 1
  nn::Normalizer input;    // applied to the input features before both networks
  double discount = 0.99;  // gamma in Q = g(s) + gamma V(s+)
  std::vector<std::string> observation_features;
  std::vector<std::string> input_features;  // in observation order; empty: all of them
  nlohmann::json provenance = nlohmann::json::object();

  int observation_dim() const { return static_cast<int>(observation_features.size()); }
  /// The observation row of each input feature; empty when the networks read them all.
  std::vector<int> InputRows() const;
  /// Shapes, feature names, finiteness and discount in [0, 1]; `what` prefixes the message.
  void Validate(const std::string& what = "AIRL reward model") const;
  /// Atomic write / checked read (kind "airl_reward"); errors name the file.
  void Save(const std::string& path) const;
  static AirlRewardModel Load(const std::string& path);
};

/// Q(s, a) = g(s) + gamma V(s+) of an AirlRewardModel as the shield's task value. The shield
/// model's states must be the model's observations (same features, same order). Evaluate()
/// allocates nothing for up to `max_batch` next states (one evaluator per shield).
class AirlActionValue final : public shield::ActionValue {
 public:
  /// `state_features`: the features of the states the shield sees (its dynamics model's).
  /// @throws secure::Error if they differ from the model's observation features.
  AirlActionValue(const AirlRewardModel& model, const std::vector<std::string>& state_features,
                  int max_batch);
  void Evaluate(const Eigen::Ref<const Eigen::VectorXf>& state,
                const Eigen::Ref<const Eigen::MatrixXf>& next_states,
                Eigen::Ref<Eigen::VectorXd> q) override;
  std::string Describe() const override;

 private:
  // What the networks read of `states`: the input rows (gathered into gathered_), or `states`.
  Eigen::Ref<const Eigen::MatrixXf> Inputs(const Eigen::Ref<const Eigen::MatrixXf>& states);

  nn::InferenceMlp reward_, shaping_;
  nn::InferenceMlp::Workspace reward_workspace_, shaping_workspace_;
  double discount_ = 0.99;
  int state_dim_ = 0;
  std::vector<int> input_rows_;
  Eigen::MatrixXf gathered_;  // input_dim x max_batch (only with input rows)
  Eigen::MatrixXf out_;       // 1 x max_batch
};

}  // namespace secure::policy
