#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/cbf/validation.h"

#include <gtest/gtest.h>

#include "secure/common/error.h"
#include "tests/test_util.h"

namespace secure::cbf {
namespace {

namespace di = domains::double_integrator;
using di::ValidateAgainstGroundTruth;

// A barrier with a constant answer, to pin the confusion bookkeeping.
class ConstantBarrier final : public Barrier {
 public:
  explicit ConstantBarrier(float value) : value_(value) {}
  int state_dim() const override { return 4; }
  std::string Describe() const override { return "constant"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>&,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    h.setConstant(value_);
  }

 private:
  float value_;
};

di::Grid SmallGrid() {
  di::Grid grid;
  grid.count = {20, 20, 6, 6};
  grid.step = {0.5, 0.5, 0.5, 0.5};
  return grid;
}

TEST(ValidateOnGridTest, GroundTruthAgainstItselfIsPerfect) {
  const di::GroundTruth truth;
  const Confusion c = ValidateAgainstGroundTruth(
      [&] { return std::make_unique<domains::double_integrator::GroundTruthBarrier>(truth); }, truth, SmallGrid());
  EXPECT_EQ(c.total(), 20 * 20 * 6 * 6);
  EXPECT_EQ(c.safe_as_unsafe, 0);
  EXPECT_EQ(c.unsafe_as_safe, 0);
  EXPECT_GT(c.truly_safe(), 0);
  EXPECT_GT(c.truly_unsafe(), 0);
  EXPECT_DOUBLE_EQ(c.SafeCorrect(), 1.0);
  EXPECT_DOUBLE_EQ(c.UnsafeCorrect(), 1.0);
}

TEST(ValidateOnGridTest, AlwaysSafeIsFullyUnderConservative) {
  const di::GroundTruth truth;
  const Confusion c =
      ValidateAgainstGroundTruth([] { return std::make_unique<ConstantBarrier>(1.0f); }, truth, SmallGrid());
  EXPECT_DOUBLE_EQ(c.OverConservative(), 0.0);
  EXPECT_DOUBLE_EQ(c.UnderConservative(), 1.0);
  const Confusion d =
      ValidateAgainstGroundTruth([] { return std::make_unique<ConstantBarrier>(-1.0f); }, truth, SmallGrid());
  EXPECT_DOUBLE_EQ(d.OverConservative(), 1.0);
  EXPECT_DOUBLE_EQ(d.UnderConservative(), 0.0);
  EXPECT_EQ(c.truly_safe(), d.truly_safe());
}

// The counts on a grid shifted off the obstacle: the ground truth labels of a different obstacle
// disagree with this barrier in a region we can count independently.
TEST(ValidateOnGridTest, CountsAgreeWithABruteForceLoop) {
  di::GroundTruth truth, other;
  other.obstacle_x = 6.0;
  other.radius = 1.5;
  const di::Grid grid = SmallGrid();
  Confusion expected;
  for (long i = 0; i < grid.size(); ++i) {
    const auto s = grid.State(i);
    const auto f = [](double v) { return static_cast<double>(static_cast<float>(v)); };
    const bool truly = truth.H(f(s[0]), f(s[1]), f(s[2]), f(s[3])) >= 0;
    const bool pred = static_cast<float>(other.H(f(s[0]), f(s[1]), f(s[2]), f(s[3]))) >= 0.0f;
    ++(truly ? (pred ? expected.safe_as_safe : expected.safe_as_unsafe)
             : (pred ? expected.unsafe_as_safe : expected.unsafe_as_unsafe));
  }
  for (int threads : {1, 2, 3}) {
    for (long chunk : {1L, 97L, 4096L}) {
      GridValidationOptions options;
      options.threads = threads;
      options.chunk = chunk;
      const Confusion c =
          ValidateAgainstGroundTruth([&] { return std::make_unique<domains::double_integrator::GroundTruthBarrier>(other); },
                         truth, grid, options);
      EXPECT_EQ(c.safe_as_safe, expected.safe_as_safe) << threads << " " << chunk;
      EXPECT_EQ(c.safe_as_unsafe, expected.safe_as_unsafe) << threads << " " << chunk;
      EXPECT_EQ(c.unsafe_as_safe, expected.unsafe_as_safe) << threads << " " << chunk;
      EXPECT_EQ(c.unsafe_as_unsafe, expected.unsafe_as_unsafe) << threads << " " << chunk;
    }
  }
  EXPECT_GT(expected.safe_as_unsafe, 0);
  EXPECT_GT(expected.unsafe_as_safe, 0);
}

TEST(ValidateOnGridTest, RejectsBarriersOfTheWrongDimension) {
  class ThreeD final : public Barrier {
   public:
    int state_dim() const override { return 3; }
    std::string Describe() const override { return "three-d"; }

   protected:
    void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>&,
                    Eigen::Ref<Eigen::VectorXf>) override {}
  };
  EXPECT_HAS(test::ErrorOf([] {
               ValidateAgainstGroundTruth([] { return std::make_unique<ThreeD>(); },
                                          di::GroundTruth{}, SmallGrid());
             }),
             "three-d takes 3-dimensional states");
}

TEST(ValidateOnGridTest, AnErrorInAWorkerThreadReachesTheCaller) {
  class Failing final : public Barrier {
   public:
    int state_dim() const override { return 4; }
    std::string Describe() const override { return "failing"; }

   protected:
    void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>&,
                    Eigen::Ref<Eigen::VectorXf>) override {
      SECURE_THROW("evaluation failed");
    }
  };
  GridValidationOptions options;
  options.threads = 2;
  EXPECT_THROW(ValidateAgainstGroundTruth([] { return std::make_unique<Failing>(); }, di::GroundTruth{},
                              SmallGrid(), options),
               Error);
}

TEST(ConfusionTest, RatesAndJson) {
  Confusion c;
  c.safe_as_safe = 90;
  c.safe_as_unsafe = 10;
  c.unsafe_as_safe = 5;
  c.unsafe_as_unsafe = 45;
  EXPECT_DOUBLE_EQ(c.OverConservative(), 0.1);
  EXPECT_DOUBLE_EQ(c.UnderConservative(), 0.1);
  EXPECT_DOUBLE_EQ(c.SafeCorrect(), 0.9);
  EXPECT_DOUBLE_EQ(c.UnsafeCorrect(), 0.9);
  const auto j = c.ToJson();
  EXPECT_EQ(j["states"], 150);
  EXPECT_DOUBLE_EQ(j["over_conservative"].get<double>(), 0.1);
  EXPECT_DOUBLE_EQ(Confusion{}.OverConservative(), 0.0);  // empty class: 0, not NaN
}

TEST(EvaluateAccuracyTest, CountsEachClass) {
  ConstantBarrier positive(0.0f);  // h = 0 counts as safe
  const ClassAccuracy a =
      EvaluateAccuracy(positive, Eigen::MatrixXf::Zero(4, 3), Eigen::MatrixXf::Zero(4, 5));
  EXPECT_DOUBLE_EQ(a.safe, 1.0);
  EXPECT_DOUBLE_EQ(a.near_dangerous, 0.0);
  EXPECT_DOUBLE_EQ(a.Balanced(), 0.5);
}

}  // namespace
}  // namespace secure::cbf
