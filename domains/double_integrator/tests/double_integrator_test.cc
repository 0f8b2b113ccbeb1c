#include "domains/double_integrator/double_integrator.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::domains::double_integrator {
namespace {

using secure::test::ErrorOf;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(DoubleIntegratorTest, StateFeaturesAreXYVxVy) {
  EXPECT_EQ(StateFeatures(), (std::vector<std::string>{"x", "y", "vx", "vy"}));
  EXPECT_EQ(static_cast<int>(StateFeatures().size()), kStateDim);
}

// ---------------------------------------------------------------------------------------------
// GroundTruth

TEST(GroundTruthTest, DefaultsAreObstacleAtFiveFiveRadiusTwoGammaOne) {
  const GroundTruth truth;
  EXPECT_EQ(truth.obstacle_x, 5.0);
  EXPECT_EQ(truth.obstacle_y, 5.0);
  EXPECT_EQ(truth.radius, 2.0);
  EXPECT_EQ(truth.gamma, 1.0);
  EXPECT_NO_THROW(truth.Validate());
}

TEST(GroundTruthTest, HAtHandComputedPoints) {
  const GroundTruth truth;
  // Stationary, 3 above the centre: 1 * (0 + 9 - 4) + 0.
  EXPECT_DOUBLE_EQ(truth.H(5, 8, 0, 0), 5.0);
  // Moving toward the obstacle at speed 1: 5 + 2 * (3 * -1) = -1 (unsafe).
  EXPECT_DOUBLE_EQ(truth.H(5, 8, 0, -1), -1.0);
  // Moving away: 5 + 2 * (3 * 1) = 11.
  EXPECT_DOUBLE_EQ(truth.H(5, 8, 0, 1), 11.0);
  // Moving tangentially does not change h.
  EXPECT_DOUBLE_EQ(truth.H(5, 8, 1.5, 0), 5.0);
  // On the obstacle boundary at rest: h = 0 (safe, h >= 0).
  EXPECT_DOUBLE_EQ(truth.H(5, 7, 0, 0), 0.0);
  EXPECT_DOUBLE_EQ(truth.H(3, 5, 0, 0), 0.0);
  // At the centre: -r^2 = -4.
  EXPECT_DOUBLE_EQ(truth.H(5, 5, 1, 1), -4.0);
  // Diagonal: dx = -4, dy = 1, v = (0.5, -1): (16 + 1 - 4) + 2 * (-2 - 1) = 7.
  EXPECT_DOUBLE_EQ(truth.H(1, 6, 0.5, -1), 7.0);
}

TEST(GroundTruthTest, MovingTowardTheObstacleReducesH) {
  const GroundTruth truth;
  for (double speed : {0.5, 1.0, 1.5}) {
    // From the left, moving right (toward the centre) vs at rest vs moving left.
    EXPECT_LT(truth.H(1, 5, speed, 0), truth.H(1, 5, 0, 0));
    EXPECT_GT(truth.H(1, 5, -speed, 0), truth.H(1, 5, 0, 0));
  }
}

TEST(GroundTruthTest, HUsesEveryParameter) {
  GroundTruth truth;
  truth.obstacle_x = 1.0;
  truth.obstacle_y = 2.0;
  truth.radius = 0.5;
  truth.gamma = 3.0;
  // dx = 1, dy = 0: 3 * (1 - 0.25) + 2 * (1 * 1 + 0 * -1) = 4.25.
  EXPECT_DOUBLE_EQ(truth.H(2, 2, 1, -1), 4.25);
  // dx = 0, dy = -2: 3 * (4 - 0.25) + 2 * (0 + -2 * 0.5) = 9.25.
  EXPECT_DOUBLE_EQ(truth.H(1, 0, 7, 0.5), 9.25);
}

TEST(GroundTruthTest, BatchedHEqualsScalarH) {
  GroundTruth truth;
  truth.obstacle_x = 4.5;
  truth.gamma = 0.7;
  Rng rng(3);
  Eigen::MatrixXf states(kStateDim, 257);
  for (int c = 0; c < states.cols(); ++c) {
    states(0, c) = static_cast<float>(rng.Uniform(0, 10));
    states(1, c) = static_cast<float>(rng.Uniform(0, 10));
    states(2, c) = static_cast<float>(rng.Uniform(-1.5, 1.5));
    states(3, c) = static_cast<float>(rng.Uniform(-1.5, 1.5));
  }
  Eigen::VectorXd h(257);
  truth.H(states, h);
  for (int c = 0; c < states.cols(); ++c) {
    // Exactly equal: both evaluate in double from the same float values.
    EXPECT_EQ(h[c], truth.H(states(0, c), states(1, c), states(2, c), states(3, c))) << c;
  }
}

TEST(GroundTruthTest, BatchedHRejectsWrongShapes) {
  const GroundTruth truth;
  Eigen::VectorXd h(5);
  EXPECT_HAS(ErrorOf([&] { truth.H(Eigen::MatrixXf::Zero(3, 5), h); }), "3 rows, expected 4");
  EXPECT_HAS(ErrorOf([&] { truth.H(Eigen::MatrixXf::Zero(4, 6), h); }),
             "h has 5 entries for 6 states");
}

TEST(GroundTruthTest, ValidateRejectsNonPositiveRadiusAndGamma) {
  for (double bad : {0.0, -1.0, kNaN, kInf}) {
    GroundTruth truth;
    truth.radius = bad;
    EXPECT_HAS(ErrorOf([&] { truth.Validate(); }), "radius");
  }
  for (double bad : {0.0, -0.5, kNaN, kInf}) {
    GroundTruth truth;
    truth.gamma = bad;
    EXPECT_HAS(ErrorOf([&] { truth.Validate(); }), "gamma");
  }
}

TEST(GroundTruthTest, ValidateRejectsANonFiniteObstacle) {
  {
    GroundTruth truth;
    truth.obstacle_x = kNaN;
    EXPECT_HAS(ErrorOf([&] { truth.Validate(); }), "obstacle");
  }
  {
    GroundTruth truth;
    truth.obstacle_y = -kInf;
    EXPECT_HAS(ErrorOf([&] { truth.Validate(); }), "obstacle");
  }
}

TEST(StateBoxTest, DefaultIsThePapersBox) {
  const StateBox box;
  EXPECT_EQ(box.lo, (std::array<double, kStateDim>{0.0, 0.0, -1.5, -1.5}));
  EXPECT_EQ(box.hi, (std::array<double, kStateDim>{10.0, 10.0, 1.5, 1.5}));
  EXPECT_NO_THROW(box.Validate());
}

TEST(StateBoxTest, ValidateRejectsEmptyAndNonFiniteDimensions) {
  {
    StateBox box;
    box.hi[2] = box.lo[2];
    EXPECT_HAS(ErrorOf([&] { box.Validate(); }), "dimension 2");
  }
  {
    StateBox box;
    box.lo[1] = 11.0;
    EXPECT_HAS(ErrorOf([&] { box.Validate(); }), "dimension 1");
  }
  {
    StateBox box;
    box.hi[3] = kNaN;
    EXPECT_HAS(ErrorOf([&] { box.Validate(); }), "dimension 3");
  }
}

// ---------------------------------------------------------------------------------------------
// SampleLabelled

void ExpectInBox(const Eigen::MatrixXf& states, const StateBox& box) {
  for (int c = 0; c < states.cols(); ++c)
    for (int d = 0; d < kStateDim; ++d) {
      // <= hi: a double just below hi may round up to hi when stored as float.
      ASSERT_GE(states(d, c), static_cast<float>(box.lo[d])) << "column " << c << " dim " << d;
      ASSERT_LE(states(d, c), static_cast<float>(box.hi[d])) << "column " << c << " dim " << d;
    }
}

TEST(SampleLabelledTest, ReturnsExactCountsWithCorrectLabelsInsideTheBox) {
  const GroundTruth truth;
  const StateBox box;
  Rng rng(1);
  const LabelledStates s = SampleLabelled(truth, box, 800, 800, rng);
  ASSERT_EQ(s.safe.rows(), kStateDim);
  ASSERT_EQ(s.safe.cols(), 800);
  ASSERT_EQ(s.unsafe.rows(), kStateDim);
  ASSERT_EQ(s.unsafe.cols(), 800);
  for (int c = 0; c < 800; ++c) {
    EXPECT_GE(truth.H(s.safe(0, c), s.safe(1, c), s.safe(2, c), s.safe(3, c)), 0.0) << c;
    EXPECT_LT(truth.H(s.unsafe(0, c), s.unsafe(1, c), s.unsafe(2, c), s.unsafe(3, c)), 0.0) << c;
  }
  ExpectInBox(s.safe, box);
  ExpectInBox(s.unsafe, box);
  // Each draw yields at most one state, and unsafe states are a minority of the box.
  EXPECT_GE(s.draws, 1600);
  EXPECT_LT(s.draws, 800 * 100);
}

TEST(SampleLabelledTest, StatesSpreadOverTheBox) {
  const StateBox box;
  Rng rng(2);
  const LabelledStates s = SampleLabelled(GroundTruth{}, box, 500, 500, rng);
  for (int d = 0; d < kStateDim; ++d) {
    const double width = box.hi[d] - box.lo[d];
    // Safe states cover nearly the whole range of every dimension (not, e.g., a constant).
    EXPECT_LT(s.safe.row(d).minCoeff(), box.lo[d] + 0.05 * width) << d;
    EXPECT_GT(s.safe.row(d).maxCoeff(), box.hi[d] - 0.05 * width) << d;
  }
}

TEST(SampleLabelledTest, IsDeterministicPerSeed) {
  const GroundTruth truth;
  const StateBox box;
  Rng a(7), b(7), c(8);
  const LabelledStates sa = SampleLabelled(truth, box, 50, 60, a);
  const LabelledStates sb = SampleLabelled(truth, box, 50, 60, b);
  const LabelledStates sc = SampleLabelled(truth, box, 50, 60, c);
  EXPECT_EQ(sa.safe, sb.safe);
  EXPECT_EQ(sa.unsafe, sb.unsafe);
  EXPECT_EQ(sa.draws, sb.draws);
  EXPECT_NE(sa.safe, sc.safe);
  EXPECT_NE(sa.unsafe, sc.unsafe);
  // The generator advances: a second call gives new states.
  const LabelledStates sa2 = SampleLabelled(truth, box, 50, 60, a);
  EXPECT_NE(sa.safe, sa2.safe);
}

TEST(SampleLabelledTest, ZeroCountsGiveEmptyMatrices) {
  Rng rng(0);
  const LabelledStates none = SampleLabelled(GroundTruth{}, StateBox{}, 0, 0, rng);
  EXPECT_EQ(none.safe.rows(), kStateDim);
  EXPECT_EQ(none.safe.cols(), 0);
  EXPECT_EQ(none.unsafe.cols(), 0);
  EXPECT_EQ(none.draws, 0);
  const LabelledStates only_safe = SampleLabelled(GroundTruth{}, StateBox{}, 10, 0, rng);
  EXPECT_EQ(only_safe.safe.cols(), 10);
  EXPECT_EQ(only_safe.unsafe.cols(), 0);
}

TEST(SampleLabelledTest, RespectsACustomBox) {
  StateBox box;
  box.lo = {4.0, 4.0, -0.2, -0.2};
  box.hi = {6.5, 6.5, 0.3, 0.3};
  const GroundTruth truth;
  Rng rng(12);
  const LabelledStates s = SampleLabelled(truth, box, 100, 100, rng);
  ExpectInBox(s.safe, box);
  ExpectInBox(s.unsafe, box);
  for (int c = 0; c < 100; ++c)
    EXPECT_GE(truth.H(s.safe(0, c), s.safe(1, c), s.safe(2, c), s.safe(3, c)), 0.0) << c;
}

TEST(SampleLabelledTest, ImpossibleUnsafeRequestThrows) {
  // The obstacle is far outside the box: every state in the box is safe.
  GroundTruth truth;
  truth.obstacle_x = 100.0;
  truth.obstacle_y = 100.0;
  Rng rng(0);
  const std::string message = ErrorOf([&] { SampleLabelled(truth, StateBox{}, 10, 1, rng); });
  EXPECT_HAS(message, "could not sample");
  EXPECT_HAS(message, "absent");
}

TEST(SampleLabelledTest, ImpossibleSafeRequestThrows) {
  // An obstacle that swallows the whole box: every state is unsafe.
  GroundTruth truth;
  truth.radius = 100.0;
  Rng rng(0);
  EXPECT_HAS(ErrorOf([&] { SampleLabelled(truth, StateBox{}, 1, 0, rng); }), "could not sample");
}

TEST(SampleLabelledTest, RejectsNegativeCountsAndInvalidInputs) {
  Rng rng(0);
  EXPECT_HAS(ErrorOf([&] { SampleLabelled(GroundTruth{}, StateBox{}, -1, 5, rng); }),
             "safe states = -1");
  EXPECT_HAS(ErrorOf([&] { SampleLabelled(GroundTruth{}, StateBox{}, 5, -2, rng); }),
             "unsafe states = -2");
  GroundTruth bad_truth;
  bad_truth.gamma = 0.0;
  EXPECT_HAS(ErrorOf([&] { SampleLabelled(bad_truth, StateBox{}, 1, 1, rng); }), "gamma");
  StateBox bad_box;
  bad_box.lo[0] = 20.0;
  EXPECT_HAS(ErrorOf([&] { SampleLabelled(GroundTruth{}, bad_box, 1, 1, rng); }), "dimension 0");
}

// ---------------------------------------------------------------------------------------------
// Grid

void ExpectState(const std::array<double, kStateDim>& s, double x, double y, double vx, double vy) {
  EXPECT_NEAR(s[0], x, 1e-9);
  EXPECT_NEAR(s[1], y, 1e-9);
  EXPECT_NEAR(s[2], vx, 1e-9);
  EXPECT_NEAR(s[3], vy, 1e-9);
}

TEST(GridTest, DefaultIsThePapersNineMillionStateGrid) {
  const Grid grid;
  EXPECT_EQ(grid.size(), 9000000);
  EXPECT_NO_THROW(grid.Validate());
}

TEST(GridTest, StateEnumeratesXSlowestAndVyFastest) {
  const Grid grid;
  ExpectState(grid.State(0), 0.0, 0.0, -1.5, -1.5);
  ExpectState(grid.State(grid.size() - 1), 9.9, 9.9, 1.4, 1.4);
  ExpectState(grid.State(1), 0.0, 0.0, -1.5, -1.4);
  ExpectState(grid.State(29), 0.0, 0.0, -1.5, 1.4);
  ExpectState(grid.State(30), 0.0, 0.0, -1.4, -1.5);
  ExpectState(grid.State(900), 0.0, 0.1, -1.5, -1.5);
  ExpectState(grid.State(90000), 0.1, 0.0, -1.5, -1.5);
  // 5 * 90000 + 7 * 900 + 15 * 30 + 20: x = 0.5, y = 0.7, vx = 0.0, vy = 0.5.
  ExpectState(grid.State(5 * 90000 + 7 * 900 + 15 * 30 + 20), 0.5, 0.7, 0.0, 0.5);
}

TEST(GridTest, EveryStateLiesInTheDefaultBox) {
  const Grid grid;
  const StateBox box;
  Rng rng(5);
  for (int i = 0; i < 1000; ++i) {
    const auto s = grid.State(static_cast<long>(rng.UniformIndex(grid.size())));
    for (int d = 0; d < kStateDim; ++d) {
      EXPECT_GE(s[d], box.lo[d] - 1e-9);
      EXPECT_LT(s[d], box.hi[d]);
    }
  }
}

// Fill(first, n) column i equals State(first + i) cast to float, bit for bit.
void ExpectFillMatchesState(const Grid& grid, long first, long n) {
  Eigen::MatrixXf out(kStateDim, n);
  grid.Fill(first, n, out);
  for (long i = 0; i < n; ++i) {
    const auto s = grid.State(first + i);
    for (int d = 0; d < kStateDim; ++d)
      ASSERT_EQ(out(d, i), static_cast<float>(s[d]))
          << "first " << first << " column " << i << " dim " << d;
  }
}

TEST(GridTest, FillMatchesStateAcrossOdometerCarries) {
  const Grid grid;
  ExpectFillMatchesState(grid, 0, 1000);
  ExpectFillMatchesState(grid, 28, 4);                     // vy carries into vx
  ExpectFillMatchesState(grid, 898, 4);                    // vx carries into y
  ExpectFillMatchesState(grid, 89998, 4);                  // y carries into x
  ExpectFillMatchesState(grid, 3 * 90000 - 1, 2);          // all three carry at once
  ExpectFillMatchesState(grid, grid.size() - 1000, 1000);  // up to the last state
  ExpectFillMatchesState(grid, grid.size() - 1, 1);
  Rng rng(17);
  for (int t = 0; t < 200; ++t) {
    const long n = 1 + static_cast<long>(rng.UniformIndex(3000));
    const long first = static_cast<long>(rng.UniformIndex(grid.size() - n + 1));
    ExpectFillMatchesState(grid, first, n);
  }
}

TEST(GridTest, FillWritesOnlyTheFirstNColumns) {
  const Grid grid;
  Eigen::MatrixXf out = Eigen::MatrixXf::Constant(kStateDim, 10, -99.0f);
  grid.Fill(100, 4, out);
  for (int c = 4; c < 10; ++c) EXPECT_EQ(out.col(c), Eigen::Vector4f::Constant(-99.0f)) << c;
  grid.Fill(5, 0, out);  // n = 0 writes nothing
  EXPECT_EQ(out.col(4), Eigen::Vector4f::Constant(-99.0f));
}

TEST(GridTest, FillOfACustomGridEnumeratesEveryState) {
  Grid grid;
  grid.start = {1.0, -2.0, 0.5, 10.0};
  grid.step = {0.5, 1.0, 0.25, 2.0};
  grid.count = {2, 3, 4, 5};
  ASSERT_EQ(grid.size(), 120);
  Eigen::MatrixXf all(kStateDim, 120);
  grid.Fill(0, 120, all);
  long i = 0;
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 3; ++b)
      for (int c = 0; c < 4; ++c)
        for (int d = 0; d < 5; ++d, ++i) {
          const Eigen::Vector4f expected(1.0f + 0.5f * a, -2.0f + b, 0.5f + 0.25f * c,
                                         10.0f + 2.0f * d);
          ASSERT_EQ(all.col(i), expected) << i;
          ExpectState(grid.State(i), expected[0], expected[1], expected[2], expected[3]);
        }
  for (long first = 0; first < 120; first += 7) ExpectFillMatchesState(grid, first, 120 - first);
}

TEST(GridTest, FillOutOfRangeThrows) {
  const Grid grid;
  Eigen::MatrixXf out(kStateDim, 10);
  EXPECT_HAS(ErrorOf([&] { grid.Fill(-1, 5, out); }), "range outside the grid");
  EXPECT_HAS(ErrorOf([&] { grid.Fill(grid.size() - 4, 5, out); }), "range outside the grid");
  EXPECT_HAS(ErrorOf([&] { grid.Fill(grid.size(), 1, out); }), "range outside the grid");
  EXPECT_NO_THROW(grid.Fill(grid.size() - 5, 5, out));
}

TEST(GridTest, FillIntoATooSmallOutputThrows) {
  const Grid grid;
  Eigen::MatrixXf narrow(kStateDim, 3);
  EXPECT_HAS(ErrorOf([&] { grid.Fill(0, 4, narrow); }), "output is too small");
  Eigen::MatrixXf short_rows(3, 10);
  EXPECT_HAS(ErrorOf([&] { grid.Fill(0, 4, short_rows); }), "output is too small");
}

TEST(GridTest, ValidateNamesTheBadDimension) {
  {
    Grid grid;
    grid.count[2] = 0;
    EXPECT_HAS(ErrorOf([&] { grid.Validate(); }), "count[2] = 0");
  }
  {
    Grid grid;
    grid.step[1] = -0.1;
    EXPECT_HAS(ErrorOf([&] { grid.Validate(); }), "step[1]");
  }
  {
    Grid grid;
    grid.step[3] = kNaN;
    EXPECT_HAS(ErrorOf([&] { grid.Validate(); }), "step[3]");
  }
  {
    Grid grid;
    grid.start[0] = kInf;
    EXPECT_HAS(ErrorOf([&] { grid.Validate(); }), "start[0]");
  }
}

}  // namespace
}  // namespace secure::domains::double_integrator
