#include "secure/domains/linear_dynamics.h"

#include <cmath>
#include <sstream>

#include "secure/common/error.h"

namespace secure::domains {
namespace {

void CheckFinite(const Eigen::Ref<const Eigen::MatrixXf>& m, const char* name) {
  for (Eigen::Index j = 0; j < m.cols(); ++j)
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      SECURE_CHECK(std::isfinite(m(i, j)), "LinearDynamics: " << name << "[" << i << ", " << j
                                                              << "] = " << m(i, j)
                                                              << ", must be finite");
}

}  // namespace

LinearDynamics::LinearDynamics(const Eigen::Ref<const Eigen::MatrixXf>& a,
                               const Eigen::Ref<const Eigen::MatrixXf>& b)
    : a_(a), b_(b) {
  SECURE_CHECK(a.rows() >= 1 && a.rows() == a.cols(),
               "LinearDynamics: A is " << a.rows() << " x " << a.cols()
                                       << ", must be square (state x state) and non-empty");
  SECURE_CHECK(b.rows() == a.rows() && b.cols() >= 1,
               "LinearDynamics: B is " << b.rows() << " x " << b.cols() << ", must be " << a.rows()
                                       << " x n (state x action) with n >= 1");
  CheckFinite(a, "A");
  CheckFinite(b, "B");
  as_.resize(a.rows());
}

std::string LinearDynamics::Describe() const {
  std::ostringstream out;
  out << "linear dynamics s' = A s + B a (state " << state_dim() << ", action " << action_dim()
      << ")";
  return out.str();
}

void LinearDynamics::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                            const Eigen::Ref<const Eigen::MatrixXf>& actions,
                            Eigen::Ref<Eigen::MatrixXf> next_states) const {
  as_.noalias() = a_ * state;
  next_states.noalias() = b_ * actions;
  next_states.colwise() += as_;
}

}  // namespace secure::domains
