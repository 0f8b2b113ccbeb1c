#pragma once
// BarrierNet: the learned barrier h(s) of SECURE (paper Section 4.1) — an MLP with input
// normalisation and a scalar output, trained with the Eq. 4 hinge loss (barrier_trainer.h).
// Immutable once trained; evaluate it through MakeEvaluator(), one evaluator per thread.

#include <Eigen/Core>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"

namespace secure::cbf {

inline constexpr const char* kBarrierModelKind = "barrier_mlp";

struct BarrierNet {
  nn::MlpParams mlp;                                     // output_dim == 1
  nn::Normalizer normalizer;                             // applied to raw states before the MLP
  std::vector<std::string> features;                     // names of the rows it reads, in order
  nlohmann::json provenance = nlohmann::json::object();  // training options, summary, data

  int state_dim() const { return mlp.spec.input_dim; }

  /// Checks internal consistency (dims of mlp, normalizer, features; finite weights).
  void Validate(const std::string& what = "barrier") const;

  /// Throws unless `data_features` equals features (same names, same order); the message names
  /// `source` and the first mismatch ("states.csv has 3 features (x, y, vx); model.bin expects 4
  /// (x, y, vx, vy)").
  void CheckFeatures(const std::vector<std::string>& data_features, const std::string& source,
                     const std::string& model_name = "the model") const;

  /// Atomic write / checked read in the secure model file format (nn/model_file.h).
  void Save(const std::string& path) const;
  static BarrierNet Load(const std::string& path);

  /// An evaluator with preallocated buffers for batches of up to `chunk` states; larger batches
  /// are evaluated in chunks.
  std::unique_ptr<Barrier> MakeEvaluator(int chunk = 4096) const;

  /// An evaluator on states whose rows are `state_features` (e.g. a domain's whole observation),
  /// of which the model reads its `features` by name. If state_features == features: the plain
  /// MakeEvaluator(chunk). Otherwise a SelectRows (barrier.h) around it, of state_dim()
  /// state_features.size(), that gathers the model's rows into a buffer preallocated for `chunk`
  /// states (no allocation per Evaluate; larger batches in chunks).
  /// @throws secure::Error if a model feature is not in state_features; the message names
  ///   `source` with its features, `model_name` and the first missing feature.
  std::unique_ptr<Barrier> MakeEvaluatorFor(const std::vector<std::string>& state_features,
                                            const std::string& source,
                                            const std::string& model_name = "the model",
                                            int chunk = 4096) const;
};

/// The evaluator behind BarrierNet::MakeEvaluator, exposed for the shield's hot path.
class BarrierNetEvaluator final : public Barrier {
 public:
  BarrierNetEvaluator(const BarrierNet& net, int chunk);
  /// States per backward pass of EvaluateGradient (larger batches go in chunks).
  static constexpr int kGradientChunk = 64;
  int state_dim() const override { return mlp_.input_dim(); }
  std::string Describe() const override { return description_; }
  bool analytic_gradient() const override { return true; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override;
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> gradients) override;

 private:
  nn::InferenceMlp mlp_;
  nn::InferenceMlp::Workspace workspace_;
  nn::InferenceMlp::GradientWorkspace gradient_workspace_;  // kGradientChunk states
  std::string description_;
};

}  // namespace secure::cbf
