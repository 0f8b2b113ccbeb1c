#pragma once
// CarBarrierNet: a permutation-invariant, per-obstacle ("per-car") barrier for multi-agent
// domains such as Demolition Derby — the architecture of the authors' released Derby CBF (a
// point-wise MLP shared by all obstacles, "akin to macbf"), with its masking made continuous.
//
// For every obstacle j of an observation the per-car features are
//   x_j = (dx, dy, d - r [, dvx, dvy])
// where (dx, dy) = p_j - p_ego and (dvx, dvy) = v_j - v_ego are read from the observation (see
// ObstacleLayout), d = sqrt(dx^2 + dy^2 + eps) with eps = 2e-4 as released (it keeps d and its
// gradient finite at d -> 0), and r is the collision radius. One MLP (default 3 -> 64 -> 128 ->
// 64 -> 1, ReLU) maps x_j to h_j. Cars with d > R (the sensing radius) are ignored, and
//
//   h(s) = min(cap, min over cars j with d_j <= R of h_j)        (= cap if no car is in range).
//
// Why the cap: the released network masks far entries to exactly 0 and takes the minimum over all
// entries, so h(s) <= 0 whenever any of the 12 cars is out of range — a state with a distant car
// can never be certified safe (the released accuracy on safe entries is ~0.62 for this reason).
// Ignoring far cars fixes that, and capping at `cap` = the trainer's safe margin keeps h
// continuous when a car crosses the sensing radius, provided the trained h_j >= cap there (the
// safe entries near d = R are pushed to h_j >= safe_margin by the loss): the car's h_j then
// enters the minimum above the cap and changes nothing until it comes closer.
//
// The released features use p_ego - p_j and append an ego-self indicator (always 0 for the
// obstacles); ours use the observation's p_j - p_ego directly and drop the constant indicator
// (an equivalent network up to the sign of the first layer's columns).
//
// Non-finite observations: a car whose distance is NaN counts as in range, so NaN propagates to
// h(s) (and a shield's "h >= 0" test fails) instead of the car being silently ignored.
//
// Immutable once trained; evaluate it through MakeEvaluator(), one evaluator per thread. The
// trainer is in car_barrier_trainer.h; a differentiable LibTorch forward in
// internal/car_barrier_torch.h.

#include <Eigen/Core>
#include <array>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"

namespace secure::cbf {

inline constexpr const char* kCarBarrierModelKind = "car_barrier";

/// Where the obstacles sit in an observation vector: obstacle i (0-based, nearest first) is the
/// block starting at first_obstacle_offset + i * obstacle_stride; within a block, the relative
/// position (p_obstacle - p_ego, 2 values) starts at position_offset and the relative velocity
/// (v_obstacle - v_ego, 2 values) at velocity_offset (-1: the observation has none).
///
/// There is no default layout: a default-constructed ObstacleLayout (all fields 0) is "unset",
/// and Validate() rejects it. The layout belongs to the domain's observation and is given by its
/// plug-in (Demolition Derby: domains::derby::ObstacleLayoutOfObservation(), the domain's
/// Preset().per_obstacle_barrier.input.layout); a saved model stores its own.
struct ObstacleLayout {
  int obs_dim = 0;
  int first_obstacle_offset = 0;
  int obstacle_stride = 0;
  int num_obstacles = 0;
  int position_offset = 0;
  int velocity_offset = 0;

  /// The fields above by name, in order: ToJson, FromJson, operator== and the trainer's YAML
  /// reader go through this one list.
  struct Field {
    const char* name;
    int ObstacleLayout::*member;
  };
  static const std::array<Field, 6> kFields;

  /// False for the default-constructed (all-zero) layout, which Validate() rejects.
  bool IsSet() const { return *this != ObstacleLayout{}; }

  /// Index of obstacle i's relative x position / x velocity in the observation.
  int PositionIndex(int i) const {
    return first_obstacle_offset + i * obstacle_stride + position_offset;
  }
  int VelocityIndex(int i) const {
    return first_obstacle_offset + i * obstacle_stride + velocity_offset;
  }

  /// Throws secure::Error naming `what`, the field, its value and the rule (e.g.
  /// "model.bin: layout.num_obstacles = 0, must be > 0"); the layout must be set (IsSet()),
  /// every block must fit into obs_dim and the position and velocity pairs must lie inside their
  /// block without overlapping.
  void Validate(const std::string& what = "ObstacleLayout") const;
  nlohmann::json ToJson() const;
  /// Reads the fields written by ToJson (all required); `source` names the file in messages.
  static ObstacleLayout FromJson(const nlohmann::json& json, const std::string& source);
  bool operator==(const ObstacleLayout& other) const;
  bool operator!=(const ObstacleLayout& other) const { return !(*this == other); }
};

/// How an observation becomes per-car features: shared by the model, its evaluator, the
/// trainer and the LibTorch forward.
struct CarFeatureSpec {
  ObstacleLayout layout;
  double collision_radius = 0.07;  // r: the feature d - r (Derby DIST_MIN_THRES)
  double sensing_radius = 1.0;     // R: cars with d > R are ignored (Derby OBS_RADIUS)
  double distance_epsilon = 2e-4;  // d = sqrt(dx^2 + dy^2 + distance_epsilon), as released
  bool use_velocity = false;       // append (dvx, dvy); false = released (positions only)

  int feature_dim() const { return use_velocity ? 5 : 3; }
  /// "dx", "dy", "d_minus_r" [, "dvx", "dvy"].
  std::vector<std::string> FeatureNames() const;
  /// Layout valid, radii and epsilon finite with r >= 0, R > 0, eps >= 0, and a velocity offset
  /// when use_velocity. With `allow_unset_layout`, an unset layout passes (and the layout checks
  /// are skipped): options not yet bound to a domain's observation.
  void Validate(const std::string& what = "CarFeatureSpec", bool allow_unset_layout = false) const;
  nlohmann::json ToJson() const;
  static CarFeatureSpec FromJson(const nlohmann::json& json, const std::string& source);
  bool operator==(const CarFeatureSpec& other) const;
};

/// Per-car features of the observations `states` (obs_dim x N) into `features`
/// (feature_dim x (N * num_obstacles), column i * num_obstacles + j = car j of state i) and
/// `in_range` (N * num_obstacles, 1 if d <= R or d is NaN). Reference/diagnostic path (the
/// evaluator fuses this with the gather); allocates the outputs.
void ComputeCarFeatures(const CarFeatureSpec& spec, const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::MatrixXf* features, Eigen::Matrix<bool, Eigen::Dynamic, 1>* in_range);

struct CarBarrierNet {
  CarFeatureSpec input;
  double cap = 0.05;   // h(s) when no car is in range, and its upper bound (see the top)
  nn::MlpParams mlp;   // per-car network: input.feature_dim() -> ... -> 1
  nn::Normalizer normalizer;  // on the per-car features (identity if not normalised)
  std::vector<std::string> features;  // names of the observation rows (obs_dim), or empty
  nlohmann::json provenance = nlohmann::json::object();  // training options, summary, data

  int state_dim() const { return input.layout.obs_dim; }

  /// Checks internal consistency (feature spec, cap finite, mlp input = feature_dim and one
  /// output, normalizer dimension, finite weights, `features` empty or obs_dim names).
  void Validate(const std::string& what = "car barrier") const;

  /// Throws unless `data_features` equals features (skipped if features is empty); the message
  /// names `source` and both lists.
  void CheckFeatures(const std::vector<std::string>& data_features, const std::string& source,
                     const std::string& model_name = "the model") const;

  /// "car_barrier 3-64-128-64-1 relu, 12 cars, r 0.07, R 1, cap 0.05, positions".
  std::string Describe() const;

  /// Atomic write / checked read in the secure model file format (nn/model_file.h, kind
  /// "car_barrier"). Load rejects another kind, a bad layout or radii, wrong shapes and
  /// non-finite values with a message naming the file and the field.
  void Save(const std::string& path) const;
  static CarBarrierNet Load(const std::string& path);

  /// Per-car values h_j (num_obstacles x N) of `states`, +infinity for cars out of range; slow
  /// (allocates), for diagnostics and tests.
  Eigen::MatrixXf EntryValues(const Eigen::Ref<const Eigen::MatrixXf>& states) const;

  /// An evaluator with buffers preallocated for batches of up to `max_states` states (all cars
  /// in range); larger batches are evaluated in chunks.
  std::unique_ptr<Barrier> MakeEvaluator(int max_states = 256) const;
};

/// The evaluator behind CarBarrierNet::MakeEvaluator, exposed for the shield's hot path: per
/// chunk it gathers the features of every in-range car of every state into one matrix, runs one
/// InferenceMlp forward over them, and min-reduces per state. No allocation after construction.
/// EvaluateDense gathers every car, in range or not, and masks afterwards (the authors' masked
/// network's work, the same values).
class CarBarrierEvaluator final : public SkippingBarrier {
 public:
  CarBarrierEvaluator(const CarBarrierNet& net, int max_states);
  int state_dim() const override { return layout_.obs_dim; }
  std::string Describe() const override { return description_; }
  int max_states() const { return max_states_; }
  /// Cars run through the network in the last chunk evaluated: those in range, or every car
  /// after EvaluateDense (diagnostics, benchmarks).
  long last_entries() const { return last_entries_; }
  bool analytic_gradient() const override { return true; }
  /// States per backward pass of EvaluateGradient: the forward over every in-range car finds
  /// each state's active (arg-min) car, then one backward pass runs over those cars only.
  static constexpr int kGradientChunk = 64;

 protected:
  /// Chunk by chunk; dense: every car's MLP, masked afterwards (else only the in-range cars).
  void DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::Ref<Eigen::VectorXf> h, bool dense) override;
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> gradients) override;

 private:
  // Gathers the cars of states first..first+m-1 into features_ (in-range cars; dense: every
  // car, with in_range_ per entry), their counts per state into count_, and with record_cars
  // each entry's car into entry_car_. Returns the entries gathered.
  Eigen::Index GatherCars(const Eigen::Ref<const Eigen::MatrixXf>& states, Eigen::Index first,
                          Eigen::Index m, bool dense, bool record_cars);

  ObstacleLayout layout_;
  bool use_velocity_;
  float r_, big_r_, eps_, cap_;
  int max_states_;
  nn::InferenceMlp mlp_;
  nn::InferenceMlp::Workspace workspace_;
  Eigen::MatrixXf features_;  // feature_dim x (max_states * num_obstacles)
  Eigen::VectorXf entry_h_;   // max_states * num_obstacles
  std::vector<int> count_;    // in-range cars per state of the chunk (every car if dense)
  std::vector<char> in_range_;  // per gathered entry of a dense chunk (unused otherwise)
  long last_entries_ = 0;
  std::string description_;
  // EvaluateGradient: each state's active car (-1: at the cap), its features and gradients.
  nn::InferenceMlp::GradientWorkspace gradient_workspace_;
  std::vector<int> active_;              // kGradientChunk: the active entry, -1 at the cap
  std::vector<int> entry_car_;           // kGradientChunk * num_obstacles: each entry's car
  Eigen::MatrixXf active_features_;      // feature_dim x kGradientChunk
  Eigen::VectorXf active_h_;             // kGradientChunk
  Eigen::MatrixXf active_gradients_;     // feature_dim x kGradientChunk
};

}  // namespace secure::cbf
