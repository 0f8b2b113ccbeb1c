#include "secure/policy/gaussian_policy.h"

#include <algorithm>
#include <cmath>

#include "secure/common/error.h"
#include "secure/common/strings.h"
#include "secure/data/data.h"
#include "secure/nn/model_file.h"
#include "secure/policy/internal/feature_names.h"

namespace secure::policy {

using internal::RowOf;
using internal::StringList;

void GaussianPolicy::Validate(const std::string& what) const {
  mean.Validate(what);
  input.Validate(what + " normalizer");
  SECURE_CHECK(input.dim() == mean.spec.input_dim,
               what << ": normalizer has dimension " << input.dim()
                    << ", the mean network input is " << mean.spec.input_dim);
  SECURE_CHECK(log_std.size() == mean.spec.output_dim, what << ": log_std has " << log_std.size()
                                                            << " values, the mean network has "
                                                            << mean.spec.output_dim << " outputs");
  for (Eigen::Index i = 0; i < log_std.size(); ++i)
    SECURE_CHECK(std::isfinite(log_std[i]),
                 what << ": log_std[" << i << "] = " << log_std[i] << ", must be finite");
  if (input_features.empty()) {
    SECURE_CHECK(static_cast<int>(observation_features.size()) == mean.spec.input_dim,
                 what << ": " << observation_features.size()
                      << " observation feature names for a network input of "
                      << mean.spec.input_dim);
  } else {
    SECURE_CHECK(static_cast<int>(input_features.size()) == mean.spec.input_dim,
                 what << ": " << input_features.size()
                      << " input feature names for a network input of " << mean.spec.input_dim);
    int previous = -1;
    for (const std::string& name : input_features) {
      const int row = RowOf(observation_features, name);
      SECURE_CHECK(row >= 0, what << ": input feature '" << name
                                  << "' is not an observation feature ("
                                  << Join(observation_features) << ")");
      SECURE_CHECK(row > previous, what << ": input feature '" << name
                                        << "' is repeated or out of the observation's order ("
                                        << Join(observation_features) << ")");
      previous = row;
    }
  }
  SECURE_CHECK(static_cast<int>(action_features.size()) == mean.spec.output_dim,
               what << ": " << action_features.size() << " action feature names for "
                    << mean.spec.output_dim << " network outputs");
}

std::vector<int> GaussianPolicy::InputRows() const {
  std::vector<int> rows;
  for (const std::string& name : input_features) {
    const int row = RowOf(observation_features, name);
    SECURE_CHECK(row >= 0,
                 "Gaussian policy: input feature '" << name << "' is not an observation feature");
    rows.push_back(row);
  }
  return rows;
}

Eigen::MatrixXf PolicyInputs(const Eigen::Ref<const Eigen::MatrixXf>& observations,
                             const std::vector<int>& rows) {
  return rows.empty() ? Eigen::MatrixXf(observations) : data::SelectRows(observations, rows);
}

void GaussianPolicy::CheckFeatures(const std::vector<std::string>& observation_names,
                                   const std::vector<std::string>& action_names,
                                   const std::string& source) const {
  SECURE_CHECK(observation_names == observation_features,
               source << " has observation features (" << Join(observation_names)
                      << "); the policy expects (" << Join(observation_features) << ")");
  SECURE_CHECK(action_names == action_features,
               source << " has action features (" << Join(action_names) << "); the policy expects ("
                      << Join(action_features) << ")");
}

void GaussianPolicy::Save(const std::string& path) const {
  Validate(path);
  nn::ModelFile file = internal::FeatureModelFile(kGaussianPolicyKind, observation_features,
                                                  input_features, provenance);
  file.metadata["action_features"] = action_features;
  nn::AddMlp("mean", mean, &file);
  nn::AddNormalizer("input", input, &file);
  file.tensors.push_back({"log_std",
                          {log_std.size()},
                          std::vector<float>(log_std.data(), log_std.data() + log_std.size())});
  nn::WriteModelFile(path, file);
}

GaussianPolicy GaussianPolicy::Load(const std::string& path) {
  const nn::ModelFile file = nn::ReadModelFileOfKind(path, kGaussianPolicyKind);
  GaussianPolicy policy;
  policy.observation_features = StringList(file.metadata, "observation_features", path);
  policy.action_features = StringList(file.metadata, "action_features", path);
  if (file.metadata.contains("input_features"))
    policy.input_features = StringList(file.metadata, "input_features", path);
  if (file.metadata.contains("provenance")) policy.provenance = file.metadata["provenance"];
  policy.mean = nn::GetMlp("mean", file, path);
  policy.input = nn::GetNormalizer("input", file, path);
  const nn::NamedTensor& log_std = file.Tensor("log_std");
  SECURE_CHECK(log_std.shape.size() == 1 && log_std.shape[0] == policy.mean.spec.output_dim &&
                   log_std.values.size() == static_cast<std::size_t>(log_std.shape[0]),
               path << ": tensor 'log_std' must have shape [" << policy.mean.spec.output_dim
                    << "] (the action dimension)");
  policy.log_std = Eigen::Map<const Eigen::VectorXf>(log_std.values.data(), log_std.shape[0]);
  policy.Validate(path);
  return policy;
}

double GaussianLogDensity(const Eigen::Ref<const Eigen::VectorXf>& action,
                          const Eigen::Ref<const Eigen::VectorXf>& mu,
                          const Eigen::Ref<const Eigen::VectorXf>& log_std) {
  SECURE_CHECK(action.size() == mu.size() && log_std.size() == mu.size(),
               "GaussianLogDensity: action has " << action.size() << " values, mu " << mu.size()
                                                 << ", log_std " << log_std.size());
  double sum = 0.0;
  for (Eigen::Index i = 0; i < mu.size(); ++i) {
    const double z = (static_cast<double>(action[i]) - mu[i]) / std::exp(double{log_std[i]});
    sum += -0.5 * z * z - log_std[i] - 0.5 * std::log(2.0 * M_PI);
  }
  return sum;
}

PolicyEvaluator::PolicyEvaluator(const GaussianPolicy& policy, int chunk)
    : net_((policy.Validate(), policy.mean), policy.input),
      workspace_(net_.MakeWorkspace(chunk)),
      observation_dim_(policy.observation_dim()),
      input_rows_(policy.InputRows()),
      sigma_(policy.log_std.array().exp().matrix()),
      log_std_(policy.log_std),
      mu_(policy.action_dim()) {
  if (!input_rows_.empty()) gathered_.resize(net_.input_dim(), workspace_.max_batch());
}

int PolicyEvaluator::observation_dim() const { return observation_dim_; }

const Eigen::MatrixXf& PolicyEvaluator::Gather(
    const Eigen::Ref<const Eigen::MatrixXf>& observations) {
  const Eigen::Index n = observations.cols();
  for (std::size_t k = 0; k < input_rows_.size(); ++k)
    gathered_.row(static_cast<Eigen::Index>(k)).head(n) = observations.row(input_rows_[k]);
  return gathered_;
}
int PolicyEvaluator::action_dim() const { return net_.output_dim(); }

void PolicyEvaluator::Mean(const Eigen::Ref<const Eigen::VectorXf>& observation,
                           Eigen::Ref<Eigen::VectorXf> mu) {
  SECURE_CHECK(observation.size() == observation_dim(),
               "PolicyEvaluator::Mean: observation has "
                   << observation.size() << " values, expected " << observation_dim());
  SECURE_CHECK(mu.size() == action_dim(), "PolicyEvaluator::Mean: mu has "
                                              << mu.size() << " values, expected " << action_dim());
  // Vectors are contiguous: map them as one-column matrices (no temporary).
  const Eigen::Map<const Eigen::MatrixXf> in(observation.data(), observation.size(), 1);
  Eigen::Map<Eigen::MatrixXf> out(mu.data(), mu.size(), 1);
  if (input_rows_.empty()) {
    net_.Forward(in, workspace_, out);
  } else {
    net_.Forward(Gather(in).leftCols(1), workspace_, out);
  }
}

void PolicyEvaluator::Means(const Eigen::Ref<const Eigen::MatrixXf>& observations,
                            Eigen::Ref<Eigen::MatrixXf> mus) {
  SECURE_CHECK(observations.rows() == observation_dim(),
               "PolicyEvaluator::Means: observations have "
                   << observations.rows() << " rows, expected " << observation_dim());
  SECURE_CHECK(mus.rows() == action_dim() && mus.cols() == observations.cols(),
               "PolicyEvaluator::Means: mus are " << mus.rows() << " x " << mus.cols()
                                                  << ", expected " << action_dim() << " x "
                                                  << observations.cols());
  const Eigen::Index n = observations.cols();
  const Eigen::Index chunk = workspace_.max_batch();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    if (input_rows_.empty()) {
      net_.Forward(observations.middleCols(first, m), workspace_, mus.middleCols(first, m));
    } else {
      net_.Forward(Gather(observations.middleCols(first, m)).leftCols(m), workspace_,
                   mus.middleCols(first, m));
    }
  }
}

void PolicyEvaluator::Sample(const Eigen::Ref<const Eigen::VectorXf>& observation, Rng& rng,
                             Eigen::Ref<Eigen::VectorXf> action) {
  SECURE_CHECK(action.size() == action_dim(), "PolicyEvaluator::Sample: action has "
                                                  << action.size() << " values, expected "
                                                  << action_dim());
  Mean(observation, mu_);
  for (Eigen::Index i = 0; i < mu_.size(); ++i)
    action[i] = mu_[i] + sigma_[i] * static_cast<float>(rng.Normal());
}

double PolicyEvaluator::LogProb(const Eigen::Ref<const Eigen::VectorXf>& observation,
                                const Eigen::Ref<const Eigen::VectorXf>& action) {
  SECURE_CHECK(action.size() == action_dim(), "PolicyEvaluator::LogProb: action has "
                                                  << action.size() << " values, expected "
                                                  << action_dim());
  Mean(observation, mu_);
  return GaussianLogDensity(action, mu_, log_std_);
}

}  // namespace secure::policy
