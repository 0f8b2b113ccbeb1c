#include "domains/double_integrator/double_integrator.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "secure/common/error.h"

namespace secure::domains::double_integrator {

const std::vector<std::string>& StateFeatures() {
  static const std::vector<std::string> names{"x", "y", "vx", "vy"};
  return names;
}

void GroundTruth::Validate() const {
  SECURE_CHECK(std::isfinite(obstacle_x) && std::isfinite(obstacle_y),
               "obstacle = (" << obstacle_x << ", " << obstacle_y << "), must be finite");
  SECURE_CHECK(std::isfinite(radius) && radius > 0, "radius = " << radius << ", must be > 0");
  SECURE_CHECK(std::isfinite(gamma) && gamma > 0, "gamma = " << gamma << ", must be > 0");
}

void GroundTruth::H(const Eigen::Ref<const Eigen::MatrixXf>& states,
                    Eigen::Ref<Eigen::VectorXd> h) const {
  SECURE_CHECK(states.rows() == kStateDim,
               "double integrator states have " << states.rows() << " rows, expected 4");
  SECURE_CHECK(h.size() == states.cols(),
               "h has " << h.size() << " entries for " << states.cols() << " states");
  for (Eigen::Index i = 0; i < states.cols(); ++i)
    h[i] = H(states(0, i), states(1, i), states(2, i), states(3, i));
}

void StateBox::Validate() const {
  for (int d = 0; d < kStateDim; ++d)
    SECURE_CHECK(std::isfinite(lo[d]) && std::isfinite(hi[d]) && lo[d] < hi[d],
                 "state box dimension " << d << " is [" << lo[d] << ", " << hi[d]
                                        << "), must be finite with lo < hi");
}

LabelledStates SampleLabelled(const GroundTruth& truth, const StateBox& box, long n_safe,
                              long n_unsafe, Rng& rng) {
  truth.Validate();
  box.Validate();
  SECURE_CHECK(n_safe >= 0, "number of safe states = " << n_safe << ", must be >= 0");
  SECURE_CHECK(n_unsafe >= 0, "number of unsafe states = " << n_unsafe << ", must be >= 0");
  LabelledStates out;
  out.safe.resize(kStateDim, n_safe);
  out.unsafe.resize(kStateDim, n_unsafe);
  long have_safe = 0, have_unsafe = 0;
  const long max_draws = 1000 * (n_safe + n_unsafe) + 1000;
  while (have_safe < n_safe || have_unsafe < n_unsafe) {
    SECURE_CHECK(out.draws < max_draws,
                 "could not sample " << n_safe << " safe and " << n_unsafe << " unsafe states in "
                                     << max_draws << " draws (got " << have_safe << " and "
                                     << have_unsafe
                                     << "): one class is (almost) absent from the state box");
    ++out.draws;
    std::array<double, kStateDim> s;
    for (int d = 0; d < kStateDim; ++d) s[d] = rng.Uniform(box.lo[d], box.hi[d]);
    // Label the float state that is stored, so that labels and stored data agree exactly.
    std::array<float, kStateDim> sf;
    for (int d = 0; d < kStateDim; ++d) sf[d] = static_cast<float>(s[d]);
    const bool safe = truth.H(sf[0], sf[1], sf[2], sf[3]) >= 0.0;
    Eigen::MatrixXf* set = safe ? &out.safe : &out.unsafe;
    long* have = safe ? &have_safe : &have_unsafe;
    if (*have < set->cols()) {
      for (int d = 0; d < kStateDim; ++d) (*set)(d, *have) = sf[d];
      ++*have;
    }
  }
  return out;
}

void Grid::Validate() const {
  for (int d = 0; d < kStateDim; ++d) {
    SECURE_CHECK(count[d] > 0, "grid count[" << d << "] = " << count[d] << ", must be > 0");
    SECURE_CHECK(std::isfinite(step[d]) && step[d] > 0,
                 "grid step[" << d << "] = " << step[d] << ", must be > 0");
    SECURE_CHECK(std::isfinite(start[d]), "grid start[" << d << "] is not finite");
  }
}

std::array<double, kStateDim> Grid::State(long index) const {
  std::array<double, kStateDim> s;
  for (int d = kStateDim - 1; d >= 0; --d) {
    s[d] = start[d] + step[d] * static_cast<double>(index % count[d]);
    index /= count[d];
  }
  return s;
}

void Grid::Fill(long first, long n, Eigen::Ref<Eigen::MatrixXf> out) const {
  SECURE_CHECK(out.rows() == kStateDim && out.cols() >= n, "Grid::Fill: output is too small");
  SECURE_CHECK(first >= 0 && first + n <= size(), "Grid::Fill: range outside the grid");
  // Decompose the first index once, then step the odometer.
  std::array<long, kStateDim> idx;
  long rest = first;
  for (int d = kStateDim - 1; d >= 0; --d) {
    idx[d] = rest % count[d];
    rest /= count[d];
  }
  for (long i = 0; i < n; ++i) {
    for (int d = 0; d < kStateDim; ++d)
      out(d, i) = static_cast<float>(start[d] + step[d] * static_cast<double>(idx[d]));
    for (int d = kStateDim - 1; d >= 0; --d) {
      if (++idx[d] < count[d]) break;
      idx[d] = 0;
    }
  }
}

Dynamics::Dynamics(double dt) : dt_(dt) {
  SECURE_CHECK(std::isfinite(dt) && dt > 0, "double integrator dt = " << dt << ", must be > 0");
}

std::string Dynamics::Describe() const {
  return "double-integrator dynamics (dt = " + std::to_string(dt_) + ")";
}

void Dynamics::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                      const Eigen::Ref<const Eigen::MatrixXf>& actions,
                      Eigen::Ref<Eigen::MatrixXf> next_states) const {
  const float dt = static_cast<float>(dt_);
  const float half_dt2 = 0.5f * dt * dt;
  for (Eigen::Index i = 0; i < actions.cols(); ++i) {
    next_states(0, i) = state[0] + state[2] * dt + actions(0, i) * half_dt2;
    next_states(1, i) = state[1] + state[3] * dt + actions(1, i) * half_dt2;
    next_states(2, i) = state[2] + actions(0, i) * dt;
    next_states(3, i) = state[3] + actions(1, i) * dt;
  }
}

ClippedDoubleIntegrator::ClippedDoubleIntegrator(double dt, double accel_bound)
    : exact_(dt), bound_(static_cast<float>(accel_bound)), clipped_(kActionDim, kChunk) {
  SECURE_CHECK(std::isfinite(accel_bound) && accel_bound > 0,
               "ClippedDoubleIntegrator: accel_bound = " << accel_bound << ", must be > 0");
}

std::string ClippedDoubleIntegrator::Describe() const {
  std::ostringstream s;
  s << exact_.Describe() << ", actions clipped to [-" << bound_ << ", " << bound_ << "]";
  return s.str();
}

void ClippedDoubleIntegrator::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                                     const Eigen::Ref<const Eigen::MatrixXf>& actions,
                                     Eigen::Ref<Eigen::MatrixXf> next_states) const {
  for (Eigen::Index first = 0; first < actions.cols(); first += kChunk) {
    const Eigen::Index n = std::min<Eigen::Index>(kChunk, actions.cols() - first);
    clipped_.leftCols(n) = actions.middleCols(first, n).cwiseMax(-bound_).cwiseMin(bound_);
    exact_.Step(state, clipped_.leftCols(n), next_states.middleCols(first, n));
  }
}

}  // namespace secure::domains::double_integrator
