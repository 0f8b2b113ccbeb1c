#include "secure/policy/airl_reward.h"

#include <algorithm>
#include <cmath>

#include "secure/common/error.h"
#include "secure/common/strings.h"
#include "secure/nn/model_file.h"
#include "secure/policy/internal/feature_names.h"

namespace secure::policy {

using internal::RowOf;
using internal::StringList;

std::vector<int> AirlRewardModel::InputRows() const {
  std::vector<int> rows;
  for (const std::string& name : input_features) {
    const int row = RowOf(observation_features, name);
    SECURE_CHECK(row >= 0, "AIRL reward model: input feature '"
                               << name << "' is not an observation feature ("
                               << Join(observation_features) << ")");
    rows.push_back(row);
  }
  return rows;
}

void AirlRewardModel::Validate(const std::string& what) const {
  reward.Validate(what + " reward");
  shaping.Validate(what + " shaping");
  input.Validate(what + " normalizer");
  SECURE_CHECK(reward.spec.output_dim == 1 && shaping.spec.output_dim == 1,
               what << ": the reward and shaping networks must have one output (they have "
                    << reward.spec.output_dim << " and " << shaping.spec.output_dim << ")");
  SECURE_CHECK(
      reward.spec.input_dim == shaping.spec.input_dim && input.dim() == reward.spec.input_dim,
      what << ": the reward network reads " << reward.spec.input_dim
           << " inputs, the shaping network " << shaping.spec.input_dim << ", the normalizer has "
           << input.dim());
  SECURE_CHECK(std::isfinite(discount) && discount >= 0 && discount <= 1,
               what << ": discount = " << discount << ", must be in [0, 1]");
  const std::size_t reads =
      input_features.empty() ? observation_features.size() : input_features.size();
  SECURE_CHECK(static_cast<int>(reads) == reward.spec.input_dim,
               what << ": " << reads << " input feature names for a network input of "
                    << reward.spec.input_dim);
  int previous = -1;
  for (const std::string& name : input_features) {
    const int row = RowOf(observation_features, name);
    SECURE_CHECK(row > previous, what << ": input feature '" << name
                                      << "' is unknown, repeated or out of the observation's "
                                         "order ("
                                      << Join(observation_features) << ")");
    previous = row;
  }
}

void AirlRewardModel::Save(const std::string& path) const {
  Validate(path);
  nn::ModelFile file =
      internal::FeatureModelFile(kAirlRewardKind, observation_features, input_features, provenance);
  file.metadata["discount"] = discount;
  nn::AddMlp("reward", reward, &file);
  nn::AddMlp("shaping", shaping, &file);
  nn::AddNormalizer("input", input, &file);
  nn::WriteModelFile(path, file);
}

AirlRewardModel AirlRewardModel::Load(const std::string& path) {
  const nn::ModelFile file = nn::ReadModelFileOfKind(path, kAirlRewardKind);
  AirlRewardModel model;
  model.observation_features = StringList(file.metadata, "observation_features", path);
  if (file.metadata.contains("input_features"))
    model.input_features = StringList(file.metadata, "input_features", path);
  SECURE_CHECK(file.metadata.contains("discount") && file.metadata["discount"].is_number(),
               path << ": metadata field 'discount' is missing or not a number");
  model.discount = file.metadata["discount"].get<double>();
  if (file.metadata.contains("provenance")) model.provenance = file.metadata["provenance"];
  model.reward = nn::GetMlp("reward", file, path);
  model.shaping = nn::GetMlp("shaping", file, path);
  model.input = nn::GetNormalizer("input", file, path);
  model.Validate(path);
  return model;
}

AirlActionValue::AirlActionValue(const AirlRewardModel& model,
                                 const std::vector<std::string>& state_features, int max_batch)
    : reward_((model.Validate(), model.reward), model.input),
      shaping_(model.shaping, model.input),
      reward_workspace_(reward_.MakeWorkspace(1)),
      shaping_workspace_(shaping_.MakeWorkspace(std::max(max_batch, 1))),
      discount_(model.discount),
      state_dim_(model.observation_dim()),
      input_rows_(model.InputRows()),
      out_(1, std::max(max_batch, 1)) {
  SECURE_CHECK(state_features == model.observation_features,
               "AIRL reward model: it reads observations (" << Join(model.observation_features)
                                                            << "), the shield's states are ("
                                                            << Join(state_features) << ")");
  if (!input_rows_.empty()) gathered_.resize(reward_.input_dim(), std::max(max_batch, 1));
}

Eigen::Ref<const Eigen::MatrixXf> AirlActionValue::Inputs(
    const Eigen::Ref<const Eigen::MatrixXf>& states) {
  if (input_rows_.empty()) return states;
  const Eigen::Index n = states.cols();
  for (std::size_t k = 0; k < input_rows_.size(); ++k)
    gathered_.row(static_cast<Eigen::Index>(k)).head(n) = states.row(input_rows_[k]);
  return gathered_.leftCols(n);
}

void AirlActionValue::Evaluate(const Eigen::Ref<const Eigen::VectorXf>& state,
                               const Eigen::Ref<const Eigen::MatrixXf>& next_states,
                               Eigen::Ref<Eigen::VectorXd> q) {
  const Eigen::Index n = next_states.cols();
  SECURE_CHECK(state.size() == state_dim_ && next_states.rows() == state_dim_,
               "AirlActionValue: states have " << state.size() << " and " << next_states.rows()
                                               << " values, expected " << state_dim_);
  SECURE_CHECK(n <= shaping_workspace_.max_batch() && q.size() == n,
               "AirlActionValue: " << n << " next states (at most "
                                   << shaping_workspace_.max_batch() << ") and " << q.size()
                                   << " values");
  // g(s) is common to every action: it shifts Q, not the ranking, but keeps Q's scale.
  reward_.Forward(Inputs(state), reward_workspace_, out_.leftCols(1));
  const double g = out_(0, 0);
  shaping_.Forward(Inputs(next_states), shaping_workspace_, out_.leftCols(n));
  for (Eigen::Index i = 0; i < n; ++i) q[i] = g + discount_ * static_cast<double>(out_(0, i));
}

std::string AirlActionValue::Describe() const {
  return "AIRL task value Q = g(s) + " + std::to_string(discount_) + " V(T(s, a))";
}

}  // namespace secure::policy
