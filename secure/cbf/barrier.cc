#include "secure/cbf/barrier.h"

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

}  // namespace secure::cbf
