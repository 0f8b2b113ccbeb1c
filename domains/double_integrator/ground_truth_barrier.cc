#include "domains/double_integrator/ground_truth_barrier.h"

#include <sstream>

namespace secure::domains::double_integrator {

GroundTruthBarrier::GroundTruthBarrier(const GroundTruth& truth) : truth_(truth) {
  truth_.Validate();
}

std::string GroundTruthBarrier::Describe() const {
  std::ostringstream s;
  s << "double-integrator ground truth (obstacle (" << truth_.obstacle_x << ", "
    << truth_.obstacle_y << "), r = " << truth_.radius << ", gamma = " << truth_.gamma << ")";
  return s.str();
}

void GroundTruthBarrier::DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                    Eigen::Ref<Eigen::VectorXf> h) {
  for (Eigen::Index i = 0; i < states.cols(); ++i)
    h[i] = static_cast<float>(truth_.H(states(0, i), states(1, i), states(2, i), states(3, i)));
}

cbf::StateSource GridStates(const Grid& grid) {
  grid.Validate();
  return {kStateDim, grid.size(),
          [&grid](long first, long n, Eigen::Ref<Eigen::MatrixXf> out) { grid.Fill(first, n, out); }};
}

cbf::Confusion ValidateAgainstGroundTruth(
    const std::function<std::unique_ptr<cbf::Barrier>()>& make_barrier, const GroundTruth& truth,
    const Grid& grid, const cbf::GridValidationOptions& options) {
  truth.Validate();
  return cbf::ValidateOnGrid(
      make_barrier, [&truth] { return std::make_unique<GroundTruthBarrier>(truth); },
      GridStates(grid), options);
}

}  // namespace secure::domains::double_integrator
