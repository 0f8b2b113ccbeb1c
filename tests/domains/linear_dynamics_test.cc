#include "secure/domains/linear_dynamics.h"

#include <gtest/gtest.h>

#include <limits>

#include "tests/test_util.h"

namespace secure::domains {
namespace {

using secure::test::ErrorOf;

TEST(LinearDynamics, StepIsAsPlusBaForEveryColumn) {
  Eigen::MatrixXf a(2, 2), b(2, 1);
  a << 1, 0.1f, 0, 1;
  b << 0.005f, 0.1f;
  const LinearDynamics model(a, b);
  EXPECT_EQ(model.state_dim(), 2);
  EXPECT_EQ(model.action_dim(), 1);
  Eigen::VectorXf s(2);
  s << 1, 2;
  Eigen::MatrixXf actions(1, 3);
  actions << -1, 0, 2;
  Eigen::MatrixXf next(2, 3);
  model.Step(s, actions, next);
  for (int j = 0; j < 3; ++j) {
    const Eigen::VectorXf expected = a * s + b * actions.col(j);
    EXPECT_FLOAT_EQ(next(0, j), expected[0]);
    EXPECT_FLOAT_EQ(next(1, j), expected[1]);
  }
  EXPECT_EQ(model.Describe(), "linear dynamics s' = A s + B a (state 2, action 1)");
}

TEST(LinearDynamics, RejectsBadShapesAndValues) {
  EXPECT_EQ(ErrorOf([] { LinearDynamics(Eigen::MatrixXf(2, 3), Eigen::MatrixXf(2, 1)); }),
            "LinearDynamics: A is 2 x 3, must be square (state x state) and non-empty");
  EXPECT_EQ(ErrorOf([] { LinearDynamics(Eigen::MatrixXf::Zero(2, 2), Eigen::MatrixXf(3, 1)); }),
            "LinearDynamics: B is 3 x 1, must be 2 x n (state x action) with n >= 1");
  Eigen::MatrixXf b = Eigen::MatrixXf::Zero(2, 1);
  b(1, 0) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(ErrorOf([&] { LinearDynamics(Eigen::MatrixXf::Zero(2, 2), b); }),
            "LinearDynamics: B[1, 0] = nan, must be finite");
  const LinearDynamics model(Eigen::MatrixXf::Zero(2, 2), Eigen::MatrixXf::Zero(2, 1));
  Eigen::MatrixXf next(2, 1);
  EXPECT_NE(ErrorOf([&] {
              model.Step(Eigen::VectorXf::Zero(3), Eigen::MatrixXf::Zero(1, 1), next);
            }).find("state has 3 values, expected 2"),
            std::string::npos);
}

}  // namespace
}  // namespace secure::domains
