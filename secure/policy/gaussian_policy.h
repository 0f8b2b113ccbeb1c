#pragma once
// A Gaussian policy pi(a | o) = N(mu(o), diag(sigma^2)): an MLP for the mean and a
// state-independent log standard deviation (the form of the paper's AIRL policy and of the
// authors' garage GaussianMLPPolicy), stored in the secure model file format and evaluated
// without LibTorch, so that a shielded controller needs no training library at run time.
//
//   policy::GaussianPolicy pi = policy::GaussianPolicy::Load("bc.model");
//   policy::PolicyEvaluator eval(pi);           // one per thread; Mean() allocates nothing
//   eval.Mean(observation, mu);                 // mu = mu(o)
//   const Eigen::VectorXf& sigma = eval.sigma();
//   eval.Sample(observation, rng, action);      // a ~ N(mu(o), diag(sigma^2))
//
// Model file (kind "gaussian_policy", nn/model_file.h): tensors "mean.layer<i>.weight/.bias"
// (nn::AddMlp("mean")), "input.mean" / "input.scale" (the observation normaliser) and "log_std"
// [action_dim]; metadata "observation_features", "action_features", "provenance", and
// "input_features" when the mean network reads only some of the observation's features.
//
// Input features: a policy maps whole observations, but its mean network may read a subset of
// them (BcOptions::input_features), e.g. positions without velocities, so that it cannot copy
// the current velocity into the action (the "copycat" problem of behaviour cloning from
// observation histories; docs/RESULTS.md, Panda). The evaluator picks those rows itself: callers
// always pass whole observations.
//
// Training lives in secure::policy_train (bc_trainer.h, airl_trainer.h).
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"

namespace secure::policy {

inline constexpr const char* kGaussianPolicyKind = "gaussian_policy";

struct GaussianPolicy {
  nn::MlpParams mean;       // observation_dim -> ... -> action_dim, linear output
  nn::Normalizer input;     // applied to the input features before `mean`
  Eigen::VectorXf log_std;  // (action_dim)
  std::vector<std::string> observation_features;
  // The features the mean network reads, in observation order; empty: all of them.
  std::vector<std::string> input_features;
  std::vector<std::string> action_features;
  nlohmann::json provenance = nlohmann::json::object();  // training options, data, summary

  int observation_dim() const { return static_cast<int>(observation_features.size()); }
  int input_dim() const { return mean.spec.input_dim; }
  int action_dim() const { return mean.spec.output_dim; }
  /// The observation row of each input feature (ascending); empty when it reads them all.
  std::vector<int> InputRows() const;

  /// Checks shapes, feature counts (input features: known, distinct, in observation order)
  /// and finiteness; `what` prefixes the message.
  void Validate(const std::string& what = "Gaussian policy") const;
  /// Atomic write / checked read (kind "gaussian_policy"); errors name the file.
  void Save(const std::string& path) const;
  static GaussianPolicy Load(const std::string& path);

  /// Throws unless the policy's observation/action feature names equal the given ones (same
  /// names, same order); the message names `source` and both lists.
  void CheckFeatures(const std::vector<std::string>& observation_features,
                     const std::vector<std::string>& action_features,
                     const std::string& source) const;
};

/// What the mean network reads of `observations` (features x N): the rows `rows`, in that order,
/// or every row when `rows` is empty (GaussianPolicy::InputRows() of a policy that reads all).
Eigen::MatrixXf PolicyInputs(const Eigen::Ref<const Eigen::MatrixXf>& observations,
                             const std::vector<int>& rows);

/// log N(action; mu, diag(exp(log_std)^2)) summed over the action dimensions, in double.
double GaussianLogDensity(const Eigen::Ref<const Eigen::VectorXf>& action,
                          const Eigen::Ref<const Eigen::VectorXf>& mu,
                          const Eigen::Ref<const Eigen::VectorXf>& log_std);

/// Evaluates a policy: mu(o) without allocation (one evaluator per thread).
class PolicyEvaluator {
 public:
  /// Means() evaluates batches larger than `chunk` in chunks of `chunk` columns, so no call
  /// allocates after construction.
  static constexpr int kDefaultChunk = 256;

  explicit PolicyEvaluator(const GaussianPolicy& policy, int chunk = kDefaultChunk);
  int observation_dim() const;
  int action_dim() const;
  /// mu = mu(observation). @throws secure::Error on wrong dimensions.
  void Mean(const Eigen::Ref<const Eigen::VectorXf>& observation, Eigen::Ref<Eigen::VectorXf> mu);
  /// Batched means: observations (observation_dim x N) -> mus (action_dim x N).
  void Means(const Eigen::Ref<const Eigen::MatrixXf>& observations,
             Eigen::Ref<Eigen::MatrixXf> mus);
  /// exp(log_std).
  const Eigen::VectorXf& sigma() const { return sigma_; }
  const Eigen::VectorXf& log_std() const { return log_std_; }
  /// a = mu(o) + sigma .* eps, eps ~ N(0, I) from `rng` (one rng.Normal() per action dimension,
  /// in order).
  void Sample(const Eigen::Ref<const Eigen::VectorXf>& observation, Rng& rng,
              Eigen::Ref<Eigen::VectorXf> action);
  /// log pi(action | observation). @throws secure::Error on wrong dimensions.
  double LogProb(const Eigen::Ref<const Eigen::VectorXf>& observation,
                 const Eigen::Ref<const Eigen::VectorXf>& action);

 private:
  // The input features' rows of one chunk of observations (empty when all are read).
  const Eigen::MatrixXf& Gather(const Eigen::Ref<const Eigen::MatrixXf>& observations);

  nn::InferenceMlp net_;
  nn::InferenceMlp::Workspace workspace_;
  int observation_dim_ = 0;
  std::vector<int> input_rows_;  // empty: every row, in order
  Eigen::MatrixXf gathered_;     // input_dim x chunk
  Eigen::VectorXf sigma_;
  Eigen::VectorXf log_std_;
  Eigen::VectorXf mu_;  // scratch for Sample / LogProb
};

}  // namespace secure::policy
