#include "secure/cbf/barrier.h"

#include <sstream>

#include "secure/common/error.h"

namespace secure::cbf {

void Barrier::Evaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                       Eigen::Ref<Eigen::VectorXf> h) {
  SECURE_CHECK(states.rows() == state_dim(), Describe() << ": states have " << states.rows()
                                                        << " rows, expected " << state_dim());
  SECURE_CHECK(h.size() == states.cols(), Describe()
                                              << ": output has " << h.size() << " entries for "
                                              << states.cols() << " states");
  DoEvaluate(states, h);
}

DoubleIntegratorGroundTruth::DoubleIntegratorGroundTruth(
    const domains::double_integrator::GroundTruth& truth)
    : truth_(truth) {
  truth_.Validate();
}

std::string DoubleIntegratorGroundTruth::Describe() const {
  std::ostringstream s;
  s << "double-integrator ground truth (obstacle (" << truth_.obstacle_x << ", "
    << truth_.obstacle_y << "), r = " << truth_.radius << ", gamma = " << truth_.gamma << ")";
  return s.str();
}

void DoubleIntegratorGroundTruth::DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                             Eigen::Ref<Eigen::VectorXf> h) {
  for (Eigen::Index i = 0; i < states.cols(); ++i)
    h[i] = static_cast<float>(truth_.H(states(0, i), states(1, i), states(2, i), states(3, i)));
}

}  // namespace secure::cbf
