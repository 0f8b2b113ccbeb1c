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
/// An ensemble of K >= 2 barrier MLPs on the same features: h(s) = min over the members.
inline constexpr const char* kBarrierEnsembleModelKind = "barrier_ensemble";
/// The most members an ensemble file may hold.
inline constexpr int kMaxBarrierEnsemble = 64;
/// Whether a model file of `kind` is read by BarrierNet::Load (one MLP or an ensemble).
inline bool IsFlatBarrierKind(const std::string& kind) {
  return kind == kBarrierModelKind || kind == kBarrierEnsembleModelKind;
}

/// One network of a barrier: h_k(s) = mlp((s - mean) / scale).
struct BarrierMember {
  nn::MlpParams mlp;          // output_dim == 1
  nn::Normalizer normalizer;  // applied to raw states before the MLP
};

/// A learned barrier: one MLP, or an ensemble of K MLPs trained from different initialisations
/// on the same labels (BarrierTrainerOptions::ensemble), h(s) = min_k h_k(s): pessimistic where
/// the members disagree. Member 0 is `mlp` / `normalizer` (a single barrier is exactly member
/// 0); members 1..K-1 are `more_members`. Every consumer evaluates the whole ensemble through
/// MakeEvaluator / MakeEvaluatorFor (a MinBarrier, min_barrier.h) or MakeDifferentiableBarrier.
struct BarrierNet {
  nn::MlpParams mlp;                                     // member 0; output_dim == 1
  nn::Normalizer normalizer;                             // member 0's, applied to raw states
  std::vector<BarrierMember> more_members;               // members 1..K-1 (empty: one MLP)
  std::vector<std::string> features;                     // names of the rows it reads, in order
  nlohmann::json provenance = nlohmann::json::object();  // training options, summary, data

  int state_dim() const { return mlp.spec.input_dim; }
  /// K: 1 + more_members.size().
  int members() const { return 1 + static_cast<int>(more_members.size()); }
  /// Member k (0: mlp / normalizer) as a BarrierMember copy. @throws secure::Error if out of range.
  BarrierMember Member(int k) const;

  /// Checks internal consistency (dims of every member's mlp and normalizer, features; finite
  /// weights); a member's message names it ("<what> member 2: ...").
  void Validate(const std::string& what = "barrier") const;

  /// Throws unless `data_features` equals features (same names, same order); the message names
  /// `source` and the first mismatch ("states.csv has 3 features (x, y, vx); model.bin expects 4
  /// (x, y, vx, vy)").
  void CheckFeatures(const std::vector<std::string>& data_features, const std::string& source,
                     const std::string& model_name = "the model") const;

  /// Atomic write / checked read in the secure model file format (nn/model_file.h). One MLP is
  /// kind "barrier_mlp" (MLP "barrier", normaliser "input"); an ensemble is kind
  /// "barrier_ensemble" with metadata "members" = K and member k's MLP / normaliser under
  /// "barrier" / "input" (k = 0) or "barrier<k>" / "input<k>". Load reads either kind.
  void Save(const std::string& path) const;
  static BarrierNet Load(const std::string& path);

  /// An evaluator with preallocated buffers for batches of up to `chunk` states; larger batches
  /// are evaluated in chunks. One MLP: a BarrierNetEvaluator; an ensemble: a MinBarrier over
  /// one per member.
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
  /// Member 0 of `net` (MakeEvaluator wraps one per member of an ensemble in a MinBarrier).
  BarrierNetEvaluator(const BarrierNet& net, int chunk);
  BarrierNetEvaluator(const BarrierMember& member, int chunk);
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
