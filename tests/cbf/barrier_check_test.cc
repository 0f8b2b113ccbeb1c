// The pre-deployment barrier check (cbf/barrier_check.h) on the double integrator, with
// barriers whose failures are known: a constant +1, the analytic ground truth, and a hand-made
// barrier that is "safe" where no bounded action can keep it so.
#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/cbf/barrier_check.h"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>

#include "domains/double_integrator/domain.h"
#include "domains/double_integrator/double_integrator.h"
#include "secure/cbf/barrier.h"
#include "tests/test_util.h"

namespace secure::cbf {
namespace {

namespace di = domains::double_integrator;
using test::ErrorOf;

// A barrier given by a function of one state.
class FunctionBarrier final : public Barrier {
 public:
  FunctionBarrier(int dim, std::function<float(const Eigen::Ref<const Eigen::VectorXf>&)> f)
      : dim_(dim), f_(std::move(f)) {}
  int state_dim() const override { return dim_; }
  std::string Describe() const override { return "test barrier"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    for (long i = 0; i < states.cols(); ++i) h[i] = f_(states.col(i));
  }

 private:
  int dim_;
  std::function<float(const Eigen::Ref<const Eigen::VectorXf>&)> f_;
};

// The double integrator's problem as the domain gives it (MakeDoubleIntegratorCheckProblem, what
// `cbf check` and the experiments use): the validation box, the ground truth as the unsafe test,
// the clipped dynamics with |a_i| <= 3, alpha(h) = h, dt = 0.1; here with 200 + 200 states
// labelled by the ground truth.
struct DiSetup {
  di::GroundTruth truth;
  std::unique_ptr<domains::DynamicsModel> owned;
  BarrierCheckProblem problem = Make(truth, &owned);
  const domains::DynamicsModel& dynamics = *owned;

  static BarrierCheckProblem Make(const di::GroundTruth& truth,
                                  std::unique_ptr<domains::DynamicsModel>* dynamics) {
    Rng rng(99);
    di::LabelledStates l = di::SampleLabelled(truth, di::StateBox{}, 200, 200, rng);
    const data::StateSet safe{"drawn", di::StateFeatures(), l.safe};
    const data::StateSet unsafe{"drawn", di::StateFeatures(), l.unsafe};
    di::ReachAvoidOptions task;
    task.truth = truth;
    return di::MakeDoubleIntegratorCheckProblem(task, shield::ShieldOptions{}, safe, unsafe,
                                                dynamics);
  }
};

BarrierCheckOptions SmallOptions() {
  BarrierCheckOptions o;
  o.region_samples = 600;
  o.near_samples = 300;
  return o;
}

TEST(BarrierCheckTest, ConstantPositiveBarrierIsFlaggedForUnsafeStates) {
  DiSetup setup;
  FunctionBarrier one(4, [](const auto&) { return 1.0f; });
  const CheckReport r = CheckBarrier(one, setup.dynamics, setup.problem, SmallOptions());
  ASSERT_TRUE(r.unsafe.available);
  EXPECT_GT(r.unsafe.checked, 0);
  EXPECT_EQ(r.unsafe.counterexamples, r.unsafe.checked);  // every unsafe state has h = 1
  EXPECT_DOUBLE_EQ(r.unsafe.rate(), 1.0);
  EXPECT_DOUBLE_EQ(r.near_dangerous.rate(), 1.0);
  EXPECT_DOUBLE_EQ(r.accuracy_near_dangerous, 0.0);
  EXPECT_DOUBLE_EQ(r.accuracy_safe, 1.0);
  // h is constant, so g = alpha(1) = 1 for every action: (a) finds nothing.
  EXPECT_EQ(r.no_safe_action.counterexamples, 0);
  EXPECT_TRUE(r.flagged);
  EXPECT_EQ(r.Verdict(), "flagged");
  bool has_c = false;
  for (const CheckExample& e : r.worst) {
    if (e.kind != CheckKind::kUnsafe) continue;
    has_c = true;
    EXPECT_TRUE(setup.problem.is_unsafe(e.state)) << e.state.transpose();
    EXPECT_EQ(e.h, 1.0);
  }
  EXPECT_TRUE(has_c);
}

TEST(BarrierCheckTest, GroundTruthPassesTheUnsafeTestAndHasFewStatesWithoutAction) {
  DiSetup setup;
  domains::double_integrator::GroundTruthBarrier truth(setup.truth);
  BarrierCheckOptions o = SmallOptions();
  o.region_samples = 2000;
  const CheckReport r = CheckBarrier(truth, setup.dynamics, setup.problem, o);
  EXPECT_GT(r.unsafe.checked, 0);
  EXPECT_EQ(r.unsafe.counterexamples, 0);
  EXPECT_EQ(r.unsafe.search_counterexamples, 0);
  EXPECT_LT(r.unsafe.worst_objective, 0.0);
  // (b) perturbs unsafe states by up to 0.05 std: only those within that of the boundary can
  // cross it.
  EXPECT_LE(r.near_dangerous.rate(), 0.05) << r.Summary();
  EXPECT_DOUBLE_EQ(r.accuracy_safe, 1.0);
  EXPECT_DOUBLE_EQ(r.accuracy_near_dangerous, 1.0);
  // With |a_i| <= 3 the ground truth keeps an admissible action in (almost) every state with
  // h >= 0 (measured: none in 2000 samples; the search may find states right at the boundary).
  EXPECT_LE(r.no_safe_action.rate(), 0.005) << r.Summary();
  EXPECT_FALSE(r.flagged) << r.Summary();
  std::cout << r.Summary();  // the documented numbers (secure/cbf/README.md)
}

// h(s) = 5 - x: "safe" left of x = 5. g = -(vx + a_x dt / 2) + (5 - x), so max_a g =
// (5 - x) - vx + 0.15: moving right faster than 5 - x + 0.15, no action with |a_x| <= 3 keeps
// g >= 0. Analytic rate among states with h >= 0: (1.35^2 / 2) / (5 * 3) = 0.061.
TEST(BarrierCheckTest, FindsStatesCalledSafeWithoutAnAdmissibleAction) {
  DiSetup setup;
  FunctionBarrier wall(4, [](const auto& s) { return 5.0f - s[0]; });
  BarrierCheckOptions o = SmallOptions();
  o.region_samples = 2000;
  const CheckReport r = CheckBarrier(wall, setup.dynamics, setup.problem, o);
  EXPECT_NEAR(r.no_safe_action.rate(), 0.061, 0.02) << r.Summary();
  EXPECT_GT(r.no_safe_action.search_counterexamples, 0);
  EXPECT_TRUE(r.flagged);
  ASSERT_FALSE(r.worst.empty());
  const CheckExample& worst = r.worst.front();
  EXPECT_EQ(worst.kind, CheckKind::kNoSafeAction);
  EXPECT_GE(worst.h, 0.0);
  EXPECT_LT(worst.objective, 0.0);
  // The worst one agrees with the analytic max_a g.
  const double analytic = (5.0 - worst.state[0]) - worst.state[2] + 0.15;
  EXPECT_NEAR(worst.objective, analytic, 1e-3);

  Rng rng(1);
  Eigen::VectorXf s(4);
  s << 4.9f, 5.0f, 1.4f, 0.0f;
  EXPECT_NEAR(MaxCbfCondition(wall, setup.dynamics, setup.problem, o, s, rng), -1.15, 1e-4);
}

TEST(BarrierCheckTest, IsDeterministicForASeed) {
  DiSetup setup;
  FunctionBarrier wall(4, [](const auto& s) { return 5.0f - s[0] + 0.1f * s[3]; });
  const BarrierCheckOptions o = SmallOptions();
  const CheckReport a = CheckBarrier(wall, setup.dynamics, setup.problem, o);
  const CheckReport b = CheckBarrier(wall, setup.dynamics, setup.problem, o);
  EXPECT_EQ(a.ToJson(), b.ToJson());
  ASSERT_EQ(a.worst.size(), b.worst.size());
  for (std::size_t i = 0; i < a.worst.size(); ++i) {
    EXPECT_EQ(a.worst[i].state, b.worst[i].state);
    EXPECT_EQ(a.worst[i].objective, b.worst[i].objective);
  }
  BarrierCheckOptions other = o;
  other.seed = o.seed + 1;
  const CheckReport c = CheckBarrier(wall, setup.dynamics, setup.problem, other);
  EXPECT_NE(a.worst.front().state, c.worst.front().state);
}

TEST(BarrierCheckTest, WritesTheWorstExamplesAsCsvThatReadsBackForAugmentation) {
  DiSetup setup;
  FunctionBarrier one(4, [](const auto&) { return 1.0f; });
  BarrierCheckOptions o = SmallOptions();
  o.worst_examples = 5;
  const CheckReport r = CheckBarrier(one, setup.dynamics, setup.problem, o);
  const std::string path =
      ::testing::TempDir() + "/barrier_check_test_" + std::to_string(::getpid()) + ".csv";
  r.WriteCsv(path);
  std::ifstream in(path);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "kind,found_by,x,y,vx,vy,h,objective");
  const data::StateSet states = ReadCheckStates(path, di::StateFeatures());
  EXPECT_EQ(states.size(), static_cast<long>(r.worst.size()));
  EXPECT_EQ(r.worst.size(), 10u);  // 5 of (b) and 5 of (c)
  EXPECT_EQ(states.states.col(0), r.worst.front().state);

  // No counterexamples: a header-only file, which adds no states; a wrong feature is an error.
  FunctionBarrier minus(4, [](const auto&) { return -1.0f; });
  const CheckReport none = CheckBarrier(minus, setup.dynamics, setup.problem, o);
  EXPECT_TRUE(none.worst.empty());
  none.WriteCsv(path);
  EXPECT_EQ(ReadCheckStates(path, di::StateFeatures()).size(), 0);
  EXPECT_NE(ErrorOf([&] {
              ReadCheckStates(path, {"x", "speed"});
            }).find("'speed'"),
            std::string::npos);
  std::remove(path.c_str());  // the test's scratch file is not left in the temporary directory
}

TEST(BarrierCheckTest, RejectsBadInputs) {
  DiSetup setup;
  FunctionBarrier one(4, [](const auto&) { return 1.0f; });
  const BarrierCheckOptions o = SmallOptions();

  FunctionBarrier three(3, [](const auto&) { return 1.0f; });
  EXPECT_NE(ErrorOf([&] {
              CheckBarrier(three, setup.dynamics, setup.problem, o);
            }).find("state dimension 3"),
            std::string::npos);

  BarrierCheckProblem p = setup.problem;
  p.action_lo = Eigen::VectorXf::Constant(3, -1.0f);
  EXPECT_NE(ErrorOf([&] { CheckBarrier(one, setup.dynamics, p, o); }).find("action box"),
            std::string::npos);

  p = setup.problem;
  p.near_dangerous.states.resize(4, 0);
  EXPECT_NE(ErrorOf([&] { CheckBarrier(one, setup.dynamics, p, o); }).find("near-dangerous"),
            std::string::npos);

  p = setup.problem;
  p.near_dangerous = {"nd.csv", {"x", "y", "vx"}, Eigen::MatrixXf::Zero(3, 5)};
  EXPECT_NE(ErrorOf([&] { CheckBarrier(one, setup.dynamics, p, o); }).find("3 features"),
            std::string::npos);

  p = setup.problem;
  p.sample_region = nullptr;
  EXPECT_NE(ErrorOf([&] { CheckBarrier(one, setup.dynamics, p, o); }).find("region sampler"),
            std::string::npos);

  p = setup.problem;
  p.sample_region = [](Rng&, Eigen::Ref<Eigen::VectorXf> s) {
    s.setConstant(std::numeric_limits<float>::quiet_NaN());
  };
  EXPECT_NE(ErrorOf([&] { CheckBarrier(one, setup.dynamics, p, o); }).find("non-finite"),
            std::string::npos);

  const double nan = std::numeric_limits<double>::quiet_NaN();
  BarrierCheckOptions bad = o;
  bad.thresholds.no_safe_action = nan;
  EXPECT_NE(ErrorOf([&] {
              CheckBarrier(one, setup.dynamics, setup.problem, bad);
            }).find("CheckThresholds::no_safe_action = nan"),
            std::string::npos);
  bad = o;
  bad.thresholds.unsafe = 1.5;
  EXPECT_NE(ErrorOf([&] { bad.Validate(); }).find("unsafe = 1.5"), std::string::npos);
  bad = o;
  bad.near_radius = nan;
  EXPECT_NE(ErrorOf([&] { bad.Validate(); }).find("near_radius = nan"), std::string::npos);
  bad = o;
  bad.region_samples = 0;
  EXPECT_NE(ErrorOf([&] { bad.Validate(); }).find("region_samples = 0"), std::string::npos);
}

TEST(BarrierCheckTest, OptionsFromYaml) {
  BarrierCheckOptions o;
  o.ApplyYaml(YAML::Load("{region_samples: 50, near_radius: 0.1, thresholds: {unsafe: 0.2}}"),
              "c.yaml");
  EXPECT_EQ(o.region_samples, 50);
  EXPECT_DOUBLE_EQ(o.near_radius, 0.1);
  EXPECT_DOUBLE_EQ(o.thresholds.unsafe, 0.2);
  EXPECT_DOUBLE_EQ(o.thresholds.no_safe_action, 0.01);
  EXPECT_NE(ErrorOf([&] {
              o.ApplyYaml(YAML::Load("{samples: 3}"), "c.yaml");
            }).find("unknown field 'samples'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              o.ApplyYaml(YAML::Load("{thresholds: {d: 3}}"), "c.yaml");
            }).find("thresholds.d"),
            std::string::npos);
}

}  // namespace
}  // namespace secure::cbf
