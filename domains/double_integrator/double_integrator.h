#pragma once
// The 2-D double integrator of the paper's Section 5: state s = (x, y, vx, vy), a circular
// obstacle, and its ground-truth control barrier function
//
//   h(s) = gamma * [(x - xo)^2 + (y - yo)^2 - r^2] + 2 * [(x - xo) vx + (y - yo) vy]
//        = gamma * b(s) + db/dt,   b = |p - po|^2 - r^2,
//
// with a state safe iff h(s) >= 0. The paper gives neither the obstacle nor gamma; our defaults
// are obstacle (5, 5), r = 2, gamma = 1, and every value is configurable.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/domains/dynamics.h"

namespace secure::domains::double_integrator {

inline constexpr int kStateDim = 4;
/// Feature names of the state, as used in CSV files and model files.
const std::vector<std::string>& StateFeatures();

struct GroundTruth {
  double obstacle_x = 5.0;
  double obstacle_y = 5.0;
  double radius = 2.0;
  double gamma = 1.0;

  /// Throws secure::Error naming the field (radius and gamma must be > 0, all finite).
  void Validate() const;
  double H(double x, double y, double vx, double vy) const {
    const double dx = x - obstacle_x, dy = y - obstacle_y;
    return gamma * (dx * dx + dy * dy - radius * radius) + 2.0 * (dx * vx + dy * vy);
  }
  /// h of every column of `states` (4 x N), computed in double precision.
  void H(const Eigen::Ref<const Eigen::MatrixXf>& states, Eigen::Ref<Eigen::VectorXd> h) const;
};

/// The state box the paper samples and validates in: x, y in [0, 10), vx, vy in [-1.5, 1.5).
struct StateBox {
  std::array<double, kStateDim> lo{0.0, 0.0, -1.5, -1.5};
  std::array<double, kStateDim> hi{10.0, 10.0, 1.5, 1.5};
  void Validate() const;
};

/// States drawn uniformly from `box` and labelled by the ground truth, by rejection until each
/// class has its count (the paper: 800 safe + 800 unsafe).
struct LabelledStates {
  Eigen::MatrixXf safe;    // (4 x n_safe), h >= 0
  Eigen::MatrixXf unsafe;  // (4 x n_unsafe), h < 0
  long draws = 0;          // uniform draws used (to report the unsafe fraction of the box)
};
/// @throws secure::Error if a count is negative, or if the box holds (almost) no state of a
///   requested class (gives up after 1000 draws per requested state).
LabelledStates SampleLabelled(const GroundTruth& truth, const StateBox& box, long n_safe,
                              long n_unsafe, Rng& rng);

/// The paper's validation grid: 100 x 100 x 30 x 30 = 9,000,000 states, step 0.1, half-open
/// ranges starting at the box's lower corner (x = 0, 0.1, ..., 9.9; v = -1.5, ..., 1.4).
struct Grid {
  std::array<double, kStateDim> start{0.0, 0.0, -1.5, -1.5};
  std::array<double, kStateDim> step{0.1, 0.1, 0.1, 0.1};
  std::array<long, kStateDim> count{100, 100, 30, 30};

  long size() const { return count[0] * count[1] * count[2] * count[3]; }
  void Validate() const;
  /// Writes states [first, first + n) of the grid (x slowest, vy fastest) into out (4 x n).
  void Fill(long first, long n, Eigen::Ref<Eigen::MatrixXf> out) const;
  /// The grid state with linear index `index`, in double precision.
  std::array<double, kStateDim> State(long index) const;
};

inline constexpr int kActionDim = 2;

/// The exact zero-order-hold discretisation of the double integrator with acceleration action
/// a = (ax, ay) held for dt:  p' = p + v dt + a dt^2 / 2,  v' = v + a dt.
/// The action is not clipped here (a bound is the policy's or environment's business).
class Dynamics final : public DynamicsModel {
 public:
  explicit Dynamics(double dt = 0.1);
  int state_dim() const override { return kStateDim; }
  int action_dim() const override { return kActionDim; }
  std::string Describe() const override;
  double dt() const { return dt_; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  double dt_;
};

/// The transition of an environment with bounded acceleration as a DynamicsModel: clip each
/// action component to [-accel_bound, accel_bound], then the exact step of Dynamics. A shield
/// given this model checks exactly the next state that will happen. Step() allocates nothing
/// (batches are clipped in chunks through a preallocated buffer), which makes an object usable
/// from one thread at a time only.
class ClippedDoubleIntegrator final : public DynamicsModel {
 public:
  /// @throws secure::Error unless dt > 0 and accel_bound > 0 (both finite).
  ClippedDoubleIntegrator(double dt, double accel_bound);
  int state_dim() const override { return kStateDim; }
  int action_dim() const override { return kActionDim; }
  std::string Describe() const override;
  double dt() const { return exact_.dt(); }
  double accel_bound() const { return bound_; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  static constexpr int kChunk = 64;
  Dynamics exact_;
  float bound_;
  mutable Eigen::MatrixXf clipped_;  // (action_dim x kChunk) scratch
};

}  // namespace secure::domains::double_integrator
