#pragma once
// A learned one-step dynamics model: an ensemble of K small MLPs, each predicting the observation
// change Δs = s' − s from (s, a) (issue 36). The shield uses it where no hand-written model
// exists, pessimistically: g(a) takes the minimum over members of h(member's s⁺)
// (PessimisticBarrier below).
//
//   EnsembleDynamics    immutable plain data (features, K MLPs, the input and Δs normalisers);
//                       Save / Load in the model file format (nn/model_file.h, kind
//                       "dynamics_ensemble", feature names and checksum). Trained by
//                       dynamics::TrainDynamics (trainer.h, LibTorch), evaluated without it.
//   EnsembleModel       a domains::DynamicsModel over it (one per thread / shield): K
//                       InferenceMlp forwards (LIBXSMM) per Step, no allocation. Step() writes the
//                       members' mean; the K predictions of the last Step stay available.
//   PessimisticBarrier  a cbf::Barrier around the shield's barrier: evaluated on the next states
//                       the EnsembleModel just wrote, it returns min_k h(s⁺_k) (one inner forward
//                       over K·M columns); on any other states (h(s), the look-ahead's chained
//                       steps) the inner h. So the shield itself is unchanged.
//
// The member networks see the normalised input x' = ((s, a) − mean) / scale and predict the
// normalised change y = (Δs − delta.mean) / delta.scale; s' = s + delta.mean + delta.scale ⊙ y.

#include <Eigen/Core>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/domains/dynamics.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"

namespace secure::dynamics {

inline constexpr const char* kEnsembleModelKind = "dynamics_ensemble";
/// The largest ensemble (members) and the largest batch of actions an EnsembleModel takes.
inline constexpr int kMaxMembers = 64;
inline constexpr int kMaxBatch = 4096;
/// The longest PessimismOptions::hold.
inline constexpr int kMaxHold = 20;

/// How PessimisticBarrier turns the members' h(s⁺_k) into one h per action.
///   aggregate   min: min_k (never above any member); mean-std: mean_k − κ·std_k (population
///               std; softer: a member far below the others lowers h by κ·std, not to its value)
///   linear      false: h on all K·M predicted states (one forward of K·M columns);
///               true: first order around the step's state s: h_k ≈ h(s̄⁺) + ∇h(s)·(s⁺_k − s̄⁺),
///               with s̄⁺ the members' mean: h on the M mean states plus one gradient per state s
///               (cached), so the decision costs about what the hand-written model's does.
///               An approximation: exact for a barrier affine in s, otherwise off by the
///               curvature times the members' spread. With mean-std and κ = 0 the deviations
///               average out: h is h(s̄⁺), with no gradient (the cheapest pessimism: M states).
///   hold        the action held for this many model steps inside one Step(), each member on its
///               own chain (s⁺_k = member k applied `hold` times), the pessimism over the
///               members at the end: a model that looks as far as a hand-written one that holds
///               the action (Derby's holds it 3 periods), with the shield's one-step condition
///               (its bound b₁), instead of the shield's look-ahead chaining the members' mean.
///               1: one step (the model as trained).
struct PessimismOptions {
  enum class Aggregate { kMin, kMeanStd };
  Aggregate aggregate = Aggregate::kMin;
  double kappa = 1.0;  // mean-std only, >= 0
  bool linear = false;
  int hold = 1;  // in [1, kMaxHold]

  /// @throws secure::Error naming the field and value.
  void Validate() const;
  /// "min", "mean-1.5std", "linear min", ...
  std::string Describe() const;
  /// "min" | "mean-std"; @throws secure::Error naming `what` and the value.
  static Aggregate ParseAggregate(const std::string& text, const std::string& what);
};

struct EnsembleDynamics {
  std::vector<std::string> state_features;   // the rows of s (and of s')
  std::vector<std::string> action_features;  // the rows of a
  std::vector<nn::MlpParams> members;        // (state + action) -> ... -> state, each
  nn::Normalizer input;                      // over (s, a) stacked
  nn::Normalizer delta;                      // over Δs
  nlohmann::json provenance = nlohmann::json::object();

  int state_dim() const { return static_cast<int>(state_features.size()); }
  int action_dim() const { return static_cast<int>(action_features.size()); }
  int num_members() const { return static_cast<int>(members.size()); }

  /// Checks shapes, names and finiteness; `what` prefixes the message (the file name).
  void Validate(const std::string& what) const;
  void Save(const std::string& path) const;
  /// @throws secure::Error naming the file on a wrong kind, missing field or bad shape.
  static EnsembleDynamics Load(const std::string& path);

  /// Member k's next states for a batch (state_dim x N states, action_dim x N actions), in
  /// double precision column by column: slow, the reference for tests and `dynamics validate`.
  Eigen::MatrixXd ReferenceNext(int member, const Eigen::Ref<const Eigen::MatrixXf>& states,
                                const Eigen::Ref<const Eigen::MatrixXf>& actions) const;
};

class EnsembleModel final : public domains::DynamicsModel {
 public:
  /// Buffers for batches of up to `max_batch` actions (the shield's max(M, N)).
  /// @throws secure::Error if max_batch is outside [1, kMaxBatch] or the model is invalid.
  explicit EnsembleModel(std::shared_ptr<const EnsembleDynamics> model, int max_batch = 1024,
                         nn::MatmulBackend backend = nn::MatmulBackend::kAuto,
                         PessimismOptions pessimism = {});

  int state_dim() const override { return model_->state_dim(); }
  int action_dim() const override { return model_->action_dim(); }
  std::string Describe() const override;
  int num_members() const { return model_->num_members(); }
  int max_batch() const { return max_batch_; }
  const EnsembleDynamics& model() const { return *model_; }
  const std::shared_ptr<const EnsembleDynamics>& shared_model() const { return model_; }
  /// How a PessimisticBarrier over this model aggregates the members (ForShieldModel reads it).
  const PessimismOptions& pessimism() const { return pessimism_; }

  /// members (state_dim x K·M): member k's next states in columns [k M, (k + 1) M).
  /// @throws secure::Error on wrong dimensions or M > max_batch().
  void StepMembers(const Eigen::Ref<const Eigen::VectorXf>& state,
                   const Eigen::Ref<const Eigen::MatrixXf>& actions,
                   Eigen::Ref<Eigen::MatrixXf> members) const;

  /// Whether `states` are the next states the last Step() wrote (the same buffer, size and
  /// values): then last_members() holds the K predictions behind them.
  bool IsLastStep(const Eigen::Ref<const Eigen::MatrixXf>& states) const;
  /// The K predictions of the last Step(): (state_dim x K·M), member k in columns [k M, (k+1) M).
  Eigen::Ref<const Eigen::MatrixXf> last_members() const {
    return members_.leftCols(static_cast<Eigen::Index>(last_cols_) * num_members());
  }
  /// The state s of the last Step() (valid while IsLastStep holds).
  const Eigen::VectorXf& last_state() const { return last_state_; }

 protected:
  /// next_states = the members' mean.
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  // All K predictions into members_ (columns [k M, (k + 1) M)); with pessimism_.hold > 1 each
  // member's own chain over the hold.
  void Predict(const Eigen::Ref<const Eigen::VectorXf>& state,
               const Eigen::Ref<const Eigen::MatrixXf>& actions) const;

  std::shared_ptr<const EnsembleDynamics> model_;
  std::vector<nn::InferenceMlp> nets_;
  int max_batch_;
  PessimismOptions pessimism_;
  Eigen::VectorXf delta_mean_, delta_scale_;
  // Scratch (mutable: Step is const by the DynamicsModel interface; one thread per object).
  mutable std::vector<nn::InferenceMlp::Workspace> workspaces_;
  mutable Eigen::MatrixXf inputs_;   // (state + action) x max_batch
  mutable Eigen::MatrixXf outputs_;  // state x max_batch
  mutable Eigen::MatrixXf members_;  // state x (K max_batch)
  mutable Eigen::VectorXf offset_;  // delta.mean + s
  mutable Eigen::MatrixXf mean_;     // state x max_batch: the last Step's output, as written
  mutable Eigen::VectorXf last_state_;  // the last Step's s
  mutable const float* last_data_ = nullptr;
  mutable Eigen::Index last_cols_ = 0, last_stride_ = 0;
};

/// h(s⁺) pessimistic over the ensemble: on the next states `model` last wrote, the members'
/// h(member's s⁺) aggregated by `options` (default: the minimum; the inner barrier sees K·M
/// columns at once); on other states, inner h.
class PessimisticBarrier final : public cbf::SkippingBarrier {
 public:
  /// `model` must outlive this barrier; `inner` reads model.state_dim() rows.
  /// @throws secure::Error if the state dimensions differ or the options are invalid.
  PessimisticBarrier(std::unique_ptr<cbf::Barrier> inner, const EnsembleModel& model,
                     PessimismOptions options = {});
  int state_dim() const override { return inner_->state_dim(); }
  std::string Describe() const override;
  cbf::Barrier& inner() { return *inner_; }
  /// The inner barrier's (EvaluateGradient below).
  bool analytic_gradient() const override { return inner_->analytic_gradient(); }

 protected:
  void DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::Ref<Eigen::VectorXf> h, bool dense) override;
  /// The inner barrier's gradient (analytic where the inner one is). Off the last Step's states
  /// h is the inner h, so value and gradient are exact; on them h is the pessimistic value and
  /// the gradient that of the inner h at the members' mean (the shield's linearisation of g
  /// takes the slope so). Before, central differences of the inner h: the same slope, 2d + 1
  /// states.
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> gradients) override;

 private:
  // h_members_ for the linear path: h(s̄⁺_i) + ∇h(s)·(s⁺_ik − s̄⁺_i).
  void LinearMembers(const Eigen::Ref<const Eigen::MatrixXf>& states,
                     Eigen::Ref<Eigen::VectorXf> h, bool dense);
  // h[i] from h_members_ (member k of action i at k m + i).
  void AggregateMembers(Eigen::Index m, Eigen::Ref<Eigen::VectorXf> h) const;
  std::unique_ptr<cbf::Barrier> inner_;
  const EnsembleModel& model_;
  PessimismOptions options_;
  Eigen::VectorXf h_members_;  // (K max_batch)
  // The linear path's gradient ∇h(s), cached for the state it was taken at.
  Eigen::VectorXf gradient_state_, gradient_h_;
  Eigen::MatrixXf gradient_;
  bool gradient_valid_ = false;
};

/// The barrier a shield over `dynamics` should use: `barrier` wrapped in a PessimisticBarrier
/// (with the model's pessimism()) when `dynamics` is an EnsembleModel, else `barrier` itself. (The evaluation harness and the
/// Python module call this where they pair a barrier with an environment's shield model.)
std::unique_ptr<cbf::Barrier> ForShieldModel(std::unique_ptr<cbf::Barrier> barrier,
                                             const domains::DynamicsModel& dynamics);

}  // namespace secure::dynamics
