// The learned dynamics ensemble (secure/dynamics): model file, batched inference against the
// reference, training (a linear system, determinism), the pessimistic barrier, transitions files.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <memory>
#include <string>

#include "secure/common/rng.h"
#include "secure/dynamics/ensemble.h"
#include "secure/dynamics/learned_environment.h"
#include "secure/dynamics/trainer.h"
#include "secure/dynamics/transitions.h"
#include "secure/nn/mlp.h"
#include "secure/shield/shield.h"
#include "tests/test_util.h"

namespace secure::dynamics {
namespace {

// A random ensemble: K members (s, a) -> Δs with hidden layers, small output layers.
EnsembleDynamics RandomEnsemble(int d, int a, int k, std::vector<int> hidden, unsigned seed) {
  EnsembleDynamics e;
  for (int i = 0; i < d; ++i) e.state_features.push_back("s" + std::to_string(i));
  for (int i = 0; i < a; ++i) e.action_features.push_back("a" + std::to_string(i));
  for (int m = 0; m < k; ++m) {
    nn::MlpParams p = nn::RandomMlpParams(nn::MlpSpec{d + a, hidden, d, nn::Activation::kTanh},
                                          seed + 17 * m);
    e.members.push_back(p);
  }
  e.input = nn::Normalizer::Identity(d + a);
  e.input.mean.setConstant(0.1f);
  e.input.scale.setConstant(2.0f);
  e.delta = nn::Normalizer::Identity(d);
  e.delta.scale.setConstant(0.05f);
  e.delta.mean.setConstant(0.01f);
  e.provenance = {{"test", true}};
  return e;
}

// rows x cols standard normal draws.
Eigen::MatrixXf Normal(Rng& rng, int rows, int cols) {
  Eigen::MatrixXf x(rows, cols);
  for (Eigen::Index j = 0; j < x.size(); ++j) x(j) = static_cast<float>(rng.Normal());
  return x;
}

// h(s) = c . s + b.
class LinearBarrier final : public cbf::Barrier {
 public:
  LinearBarrier(Eigen::VectorXf c, float b) : c_(std::move(c)), b_(b) {}
  int state_dim() const override { return static_cast<int>(c_.size()); }
  std::string Describe() const override { return "linear"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    h = (c_.transpose() * states).transpose().array() + b_;
  }

 private:
  Eigen::VectorXf c_;
  float b_;
};

// A barrier that counts the states (columns) it evaluates, around another.
class CountingBarrier final : public cbf::Barrier {
 public:
  CountingBarrier(std::unique_ptr<cbf::Barrier> inner, long* columns)
      : inner_(std::move(inner)), columns_(columns) {}
  int state_dim() const override { return inner_->state_dim(); }
  std::string Describe() const override { return inner_->Describe(); }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    *columns_ += states.cols();
    inner_->Evaluate(states, h);
  }

 private:
  std::unique_ptr<cbf::Barrier> inner_;
  long* columns_;
};

// h(s) = 1 − |s|² (curved: the first-order pessimism is not exact on it).
class QuadraticBarrier final : public cbf::Barrier {
 public:
  explicit QuadraticBarrier(int d) : d_(d) {}
  int state_dim() const override { return d_; }
  std::string Describe() const override { return "quadratic"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    h = (1.0f - states.colwise().squaredNorm().array()).transpose();
  }

 private:
  int d_;
};

class DynamicsTest : public test::TempDirTest {};

TEST_F(DynamicsTest, ModelFileRoundTripsAndStepMatchesTheReference) {
  const EnsembleDynamics e = RandomEnsemble(4, 2, 3, {16, 16}, 5);
  const std::string path = PathOf("dyn.model");
  e.Save(path);
  const EnsembleDynamics back = EnsembleDynamics::Load(path);
  EXPECT_EQ(back.state_features, e.state_features);
  EXPECT_EQ(back.action_features, e.action_features);
  ASSERT_EQ(back.num_members(), 3);
  for (int k = 0; k < 3; ++k)
    for (std::size_t l = 0; l < e.members[k].layers.size(); ++l) {
      EXPECT_EQ(back.members[k].layers[l].weight, e.members[k].layers[l].weight);
      EXPECT_EQ(back.members[k].layers[l].bias, e.members[k].layers[l].bias);
    }
  EXPECT_EQ(back.input.scale, e.input.scale);
  EXPECT_EQ(back.delta.mean, e.delta.mean);
  EXPECT_EQ(back.provenance, e.provenance);
  // Saving what was read gives the same bytes.
  back.Save(PathOf("again.model"));
  std::ifstream f1(path, std::ios::binary), f2(PathOf("again.model"), std::ios::binary);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(f1), {}),
            std::string(std::istreambuf_iterator<char>(f2), {}));

  // Step = mean of the members; StepMembers = each member; both against the double reference.
  auto shared = std::make_shared<const EnsembleDynamics>(back);
  const EnsembleModel model(shared, 64);
  Rng rng(3);
  const Eigen::VectorXf s = Normal(rng, 4, 1);
  const Eigen::MatrixXf actions = Normal(rng, 2, 40);
  Eigen::MatrixXf next(4, 40), members(4, 120);
  model.Step(s, actions, next);
  model.StepMembers(s, actions, members);
  Eigen::MatrixXd mean = Eigen::MatrixXd::Zero(4, 40);
  const Eigen::MatrixXf states = s.replicate(1, 40);
  for (int k = 0; k < 3; ++k) {
    const Eigen::MatrixXd ref = back.ReferenceNext(k, states, actions);
    mean += ref / 3.0;
    EXPECT_LT((members.middleCols(40 * k, 40).cast<double>() - ref).cwiseAbs().maxCoeff(), 1e-5)
        << "member " << k;
  }
  EXPECT_LT((next.cast<double>() - mean).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_HAS(model.Describe(), "ensemble of 3");
}

TEST_F(DynamicsTest, LoadRejectsAnotherKindAndACorruptFile) {
  const std::string path = PathOf("dyn.model");
  RandomEnsemble(2, 1, 2, {8}, 1).Save(path);
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes[bytes.size() / 2] ^= 0x5a;
  const std::string bad = Write("bad.model", bytes);
  EXPECT_HAS(test::ErrorOf([&] { EnsembleDynamics::Load(bad); }), "bad.model");
  EXPECT_HAS(test::ErrorOf([&] { EnsembleDynamics::Load(PathOf("none.model")); }), "none.model");
}

// s' = A s + B a: an ensemble of linear members (no hidden layer) learns it to within 1e-3 on
// held-out states; with hidden layers the error is small too.
TEST_F(DynamicsTest, LearnsALinearSystemToWithin1e3) {
  Eigen::Matrix2f a;
  a << 1.0f, 0.1f, -0.05f, 0.98f;
  Eigen::Vector2f b(0.0f, 0.1f);
  auto make = [&](long n, std::uint64_t seed) {
    Transitions t;
    t.source = "linear";
    t.state_features = {"x", "v"};
    t.action_features = {"u"};
    t.states.resize(2, n);
    t.actions.resize(1, n);
    Rng rng(seed);
    for (long j = 0; j < n; ++j) {
      t.states(0, j) = static_cast<float>(rng.Uniform(-2, 2));
      t.states(1, j) = static_cast<float>(rng.Uniform(-1, 1));
      t.actions(0, j) = static_cast<float>(rng.Uniform(-3, 3));
      t.lines.push_back(j + 2);
    }
    t.next_states = a * t.states + b * t.actions;
    return t;
  };
  const Transitions train = make(2000, 1), held_out = make(500, 2);
  DynamicsTrainerOptions o;
  o.members = 2;
  o.hidden = {};
  o.epochs = 150;
  o.batch_size = 32;
  o.learning_rate = 1e-2;
  o.final_learning_rate = 1e-4;
  o.seed = 4;
  DynamicsTrainingSummary summary;
  const EnsembleDynamics e = TrainDynamics(o, train, &summary);
  EXPECT_EQ(summary.train_transitions + summary.validation_transitions, 2000);
  const EnsembleModel model(std::make_shared<const EnsembleDynamics>(e), 1);
  double worst = 0.0;
  Eigen::MatrixXf next(2, 1);
  for (long j = 0; j < held_out.size(); ++j) {
    model.Step(held_out.states.col(j), held_out.actions.col(j), next);
    worst = std::max(worst, double((next.col(0) - held_out.next_states.col(j)).cwiseAbs().maxCoeff()));
  }
  EXPECT_LT(worst, 1e-3);

  // Same seed, same data: the same model bytes (the summary in the file has no timing).
  e.Save(PathOf("one.model"));
  TrainDynamics(o, train).Save(PathOf("two.model"));
  std::ifstream f1(PathOf("one.model"), std::ios::binary), f2(PathOf("two.model"), std::ios::binary);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(f1), {}),
            std::string(std::istreambuf_iterator<char>(f2), {}));

  // A small tanh network gets close as well (relative to the change's spread).
  o.hidden = {32};
  o.members = 1;
  o.epochs = 60;
  const EnsembleModel mlp(std::make_shared<const EnsembleDynamics>(TrainDynamics(o, train)), 1);
  double err = 0.0;
  for (long j = 0; j < held_out.size(); ++j) {
    mlp.Step(held_out.states.col(j), held_out.actions.col(j), next);
    err = std::max(err, double((next.col(0) - held_out.next_states.col(j)).cwiseAbs().maxCoeff()));
  }
  EXPECT_LT(err, 2e-2);
}

// min over members is never above any member's h, equals one of them, and other states get the
// inner barrier unchanged.
TEST_F(DynamicsTest, PessimisticBarrierIsTheMinimumOverMembers) {
  auto shared = std::make_shared<const EnsembleDynamics>(RandomEnsemble(4, 2, 5, {32, 32}, 9));
  const EnsembleModel model(shared, 128);
  Eigen::VectorXf c(4);
  c << 1.0f, -2.0f, 0.5f, 3.0f;
  PessimisticBarrier pessimistic(std::make_unique<LinearBarrier>(c, 0.2f), model);
  LinearBarrier plain(c, 0.2f);
  Rng rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const int m = 1 + trial * 6;
    Eigen::VectorXf s(4);
    for (int i = 0; i < 4; ++i) s[i] = static_cast<float>(rng.Normal());
    Eigen::MatrixXf actions(2, m);
    for (Eigen::Index j = 0; j < actions.size(); ++j)
      actions(j) = static_cast<float>(3 * rng.Normal());
    Eigen::MatrixXf next(4, m), members(4, 5 * m);
    model.StepMembers(s, actions, members);
    model.Step(s, actions, next);
    Eigen::VectorXf h(m), hk(5 * m), h_mean(m);
    pessimistic.Evaluate(next, h);
    plain.Evaluate(members, hk);
    plain.Evaluate(next, h_mean);
    for (int i = 0; i < m; ++i) {
      float lowest = std::numeric_limits<float>::infinity();
      for (int k = 0; k < 5; ++k) {
        EXPECT_LE(h[i], hk[k * m + i]) << "member " << k << " column " << i;
        lowest = std::min(lowest, hk[k * m + i]);
      }
      EXPECT_EQ(h[i], lowest);
      EXPECT_LE(h[i], h_mean[i] + 1e-5f);  // h linear: the mean's h is the members' mean
    }
    // A copy of the same values in another buffer is not the last step: the inner h.
    const Eigen::MatrixXf copy = next;
    Eigen::VectorXf h_copy(m);
    pessimistic.Evaluate(copy, h_copy);
    EXPECT_EQ(h_copy, h_mean);
  }
  // In the shield: g of the pessimistic barrier is g of the worst member.
  shield::ShieldOptions options;
  options.num_samples = 32;
  shield::Shield sh(options, pessimistic, model);
  Eigen::VectorXf s = Eigen::VectorXf::Constant(4, 0.3f);
  Eigen::MatrixXf actions = Eigen::MatrixXf::Random(2, 16);
  Eigen::VectorXd g(16);
  const double h_s = sh.EvaluateH(s);
  Eigen::VectorXf h_plain(1);
  plain.Evaluate(Eigen::MatrixXf(s), h_plain);
  EXPECT_FLOAT_EQ(static_cast<float>(h_s), h_plain[0]);
  sh.EvaluateG(s, h_s, actions, g);
  Eigen::MatrixXf members(4, 80);
  model.StepMembers(s, actions, members);
  Eigen::VectorXf hk(80);
  plain.Evaluate(members, hk);
  for (int i = 0; i < 16; ++i) {
    double worst = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 5; ++k) worst = std::min(worst, double(hk[k * 16 + i]));
    EXPECT_NEAR(g[i], (worst - h_s) / options.dt + options.class_k_gain * h_s, 1e-4);
  }
}

TEST_F(DynamicsTest, PessimisticGradientIsTheInnerOnesAndItsValueThePessimisticOne) {
  auto shared = std::make_shared<const EnsembleDynamics>(RandomEnsemble(4, 2, 5, {32, 32}, 9));
  const EnsembleModel model(shared, 64);
  long inner_columns = 0;
  PessimisticBarrier pessimistic(
      std::make_unique<CountingBarrier>(std::make_unique<QuadraticBarrier>(4), &inner_columns),
      model);
  QuadraticBarrier curved(4);
  EXPECT_FALSE(pessimistic.analytic_gradient());  // the inner one's (central differences here)
  Rng rng(3);
  Eigen::VectorXf s(4);
  for (int i = 0; i < 4; ++i) s[i] = static_cast<float>(0.3 * rng.Normal());
  Eigen::MatrixXf actions(2, 3);
  for (Eigen::Index j = 0; j < actions.size(); ++j) actions(j) = static_cast<float>(rng.Normal());
  Eigen::MatrixXf next(4, 3);
  model.Step(s, actions, next);
  // On the last step's states: the pessimistic value, the inner h's slope at the members' mean
  // (h = 1 - |s|^2: gradient -2 s).
  Eigen::VectorXf h(3), h_pessimistic(3), h_mean(3);
  Eigen::MatrixXf gradients(4, 3);
  pessimistic.Evaluate(next, h_pessimistic);
  curved.Evaluate(next, h_mean);
  inner_columns = 0;
  pessimistic.EvaluateGradient(next, h, gradients);
  EXPECT_EQ(h, h_pessimistic);
  for (int i = 0; i < 3; ++i) EXPECT_LT(h[i], h_mean[i]);  // the minimum of a concave h's members
  EXPECT_TRUE(gradients.isApprox(-2.0f * next, 1e-2f)) << gradients << "\n" << -2.0f * next;
  // The inner barrier's central differences (2d + 1 states per column) and the K M members.
  EXPECT_EQ(inner_columns, 3 * (2 * 4 + 1) + 5 * 3);
  // Elsewhere: the inner h and its gradient.
  const Eigen::MatrixXf copy = next;
  pessimistic.EvaluateGradient(copy, h, gradients);
  EXPECT_TRUE(h.isApprox(h_mean, 1e-6f)) << h << "\n" << h_mean;  // another batch: tolerance
  EXPECT_TRUE(gradients.isApprox(-2.0f * copy, 1e-2f));
}

TEST_F(DynamicsTest, PessimismMeanStdAndLinearOptions) {
  auto shared = std::make_shared<const EnsembleDynamics>(RandomEnsemble(4, 2, 5, {32, 32}, 9));
  const EnsembleModel model(shared, 64);
  Eigen::VectorXf c(4);
  c << 1.0f, -2.0f, 0.5f, 3.0f;
  PessimismOptions mean_std;
  mean_std.aggregate = PessimismOptions::Aggregate::kMeanStd;
  mean_std.kappa = 1.5;
  PessimismOptions linear;
  linear.linear = true;
  long exact_columns = 0, linear_columns = 0;
  PessimisticBarrier soft(std::make_unique<LinearBarrier>(c, 0.2f), model, mean_std);
  PessimisticBarrier exact(
      std::make_unique<CountingBarrier>(std::make_unique<QuadraticBarrier>(4), &exact_columns),
      model);
  PessimisticBarrier first_order(
      std::make_unique<CountingBarrier>(std::make_unique<QuadraticBarrier>(4), &linear_columns),
      model, linear);
  PessimisticBarrier first_order_affine(std::make_unique<LinearBarrier>(c, 0.2f), model, linear);
  LinearBarrier plain(c, 0.2f);
  QuadraticBarrier curved(4);
  Rng rng(5);
  const int m = 40;
  Eigen::VectorXf s(4);
  for (int i = 0; i < 4; ++i) s[i] = static_cast<float>(0.3 * rng.Normal());
  Eigen::MatrixXf actions(2, m);
  for (Eigen::Index j = 0; j < actions.size(); ++j) actions(j) = static_cast<float>(rng.Normal());
  Eigen::MatrixXf next(4, m), members(4, 5 * m);
  model.StepMembers(s, actions, members);
  Eigen::VectorXf hk(5 * m), hq(5 * m);
  plain.Evaluate(members, hk);
  curved.Evaluate(members, hq);
  model.Step(s, actions, next);
  Eigen::VectorXf h_soft(m), h_exact(m), h_linear(m), h_affine(m);
  soft.Evaluate(next, h_soft);
  exact.Evaluate(next, h_exact);
  first_order.Evaluate(next, h_linear);
  first_order_affine.Evaluate(next, h_affine);
  // The exact path evaluates K M states, the first-order one M (and the gradient's few at s).
  EXPECT_EQ(exact_columns, 5 * m);
  EXPECT_LT(linear_columns, m + 2 * 4 + 2);
  const Eigen::VectorXf grad = -2.0f * s;
  for (int i = 0; i < m; ++i) {
    double sum = 0, sum_sq = 0, lowest = 1e30, lowest_first_order = 1e30;
    for (int k = 0; k < 5; ++k) sum += hk[k * m + i];
    for (int k = 0; k < 5; ++k) sum_sq += std::pow(hk[k * m + i] - sum / 5, 2);
    // mean − κ std of the members' h.
    EXPECT_NEAR(h_soft[i], sum / 5 - 1.5 * std::sqrt(sum_sq / 5), 1e-4) << i;
    for (int k = 0; k < 5; ++k) {
      lowest = std::min(lowest, double(hk[k * m + i]));
      const Eigen::VectorXf dev = members.col(k * m + i) - next.col(i);
      lowest_first_order = std::min(lowest_first_order, double(grad.dot(dev)));
    }
    // An affine barrier: first order is exact, so the linear path is the minimum.
    EXPECT_NEAR(h_affine[i], lowest, 1e-3) << i;
    // A curved one: h(s̄⁺) plus the smallest first-order deviation through ∇h(s) (finite
    // differences: 1e-3 tolerance), which differs from the exact minimum by the curvature.
    const double h_mean = 1.0 - next.col(i).squaredNorm();
    EXPECT_NEAR(h_linear[i], h_mean + lowest_first_order, 2e-3) << i;
    double exact_lowest = 1e30;
    for (int k = 0; k < 5; ++k) exact_lowest = std::min(exact_lowest, double(hq[k * m + i]));
    EXPECT_EQ(h_exact[i], static_cast<float>(exact_lowest));
  }
  // Bad options: one line naming the field and the value.
  PessimismOptions bad;
  bad.kappa = -1;
  EXPECT_HAS(test::ErrorOf([&] { bad.Validate(); }), "pessimism: kappa = -1");
  EXPECT_HAS(test::ErrorOf([&] { PessimismOptions::ParseAggregate("max", "--pessimism"); }),
             "--pessimism = 'max', must be min | mean-std");
  EXPECT_HAS(test::ErrorOf([&] { EnsembleModel(shared, 8, nn::MatmulBackend::kAuto, bad); }),
             "kappa = -1");
  // ForShieldModel takes the model's pessimism.
  const EnsembleModel soft_model(shared, 8, nn::MatmulBackend::kAuto, mean_std);
  EXPECT_HAS(ForShieldModel(std::make_unique<LinearBarrier>(c, 0.2f), soft_model)->Describe(),
             "mean-1.5std over the 5 members");
}

// mean-std with κ = 0 on the first-order path: the members' deviations average to zero, so h is
// the inner h at the members' mean, from the M mean states alone (no gradient at s: the
// finite-difference gradient of the old path evaluated 2d + 1 more states per decision).
TEST_F(DynamicsTest, LinearMeanWithKappaZeroIsHAtTheMembersMeanWithoutAGradient) {
  auto shared = std::make_shared<const EnsembleDynamics>(RandomEnsemble(4, 2, 5, {32, 32}, 11));
  const EnsembleModel model(shared, 64);
  PessimismOptions mean;
  mean.aggregate = PessimismOptions::Aggregate::kMeanStd;
  mean.kappa = 0;
  mean.linear = true;
  long columns = 0;
  PessimisticBarrier barrier(
      std::make_unique<CountingBarrier>(std::make_unique<QuadraticBarrier>(4), &columns), model,
      mean);
  QuadraticBarrier curved(4);
  Rng rng(6);
  const int m = 30;
  Eigen::VectorXf s(4);
  for (int i = 0; i < 4; ++i) s[i] = static_cast<float>(0.3 * rng.Normal());
  const Eigen::MatrixXf actions = Normal(rng, 2, m);
  Eigen::MatrixXf next(4, m), members(4, 5 * m);
  model.Step(s, actions, next);
  Eigen::VectorXf h(m), h_mean(m), h_members(5 * m);
  barrier.Evaluate(next, h);
  EXPECT_EQ(columns, m);
  curved.Evaluate(next, h_mean);
  model.StepMembers(s, actions, members);
  curved.Evaluate(members, h_members);
  double spread = 0;
  for (int i = 0; i < m; ++i) {
    EXPECT_FLOAT_EQ(h[i], h_mean[i]) << i;
    for (int k = 1; k < 5; ++k) spread = std::max(spread, double(std::abs(h_members[k * m + i] - h_members[i])));
  }
  EXPECT_GT(spread, 1e-3);  // the members differ: the test would see a per-member path
  // Off the last step it is the inner barrier, as on the other paths.
  Eigen::VectorXf h_off(1), h_inner(1);
  barrier.Evaluate(s, h_off);
  curved.Evaluate(s, h_inner);
  EXPECT_FLOAT_EQ(h_off[0], h_inner[0]);
}

// hold = H: one Step is each member applied H times from s with the action held, against the
// double reference chained by hand; the members of the last Step are those chains' ends, so the
// pessimistic barrier is the minimum over them; hold = 1 is the plain model, bit for bit.
TEST_F(DynamicsTest, AHeldActionChainsEachMemberAndThePessimismIsAtItsEnd) {
  auto shared = std::make_shared<const EnsembleDynamics>(RandomEnsemble(4, 2, 3, {16, 16}, 5));
  PessimismOptions held;
  held.hold = 3;
  const EnsembleModel model(shared, 64, nn::MatmulBackend::kAuto, held);
  const EnsembleModel one_step(shared, 64);
  Rng rng(7);
  const Eigen::VectorXf s = Normal(rng, 4, 1);
  const Eigen::MatrixXf actions = Normal(rng, 2, 24);
  Eigen::MatrixXf next(4, 24), members(4, 72), once(4, 24);
  model.Step(s, actions, next);
  model.StepMembers(s, actions, members);
  one_step.Step(s, actions, once);
  Eigen::MatrixXd mean = Eigen::MatrixXd::Zero(4, 24);
  for (int k = 0; k < 3; ++k) {
    Eigen::MatrixXd chain = s.replicate(1, 24).cast<double>();
    for (int step = 0; step < 3; ++step)
      chain = shared->ReferenceNext(k, chain.cast<float>(), actions);
    mean += chain / 3.0;
    EXPECT_LT((members.middleCols(24 * k, 24).cast<double>() - chain).cwiseAbs().maxCoeff(), 1e-4)
        << "member " << k;
  }
  EXPECT_LT((next.cast<double>() - mean).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_GT((next - once).cwiseAbs().maxCoeff(), 1e-3);  // three steps are not one
  Eigen::VectorXf c(4);
  c << 1.0f, -2.0f, 0.5f, 3.0f;
  PessimisticBarrier pessimistic(std::make_unique<LinearBarrier>(c, 0.2f), model);
  LinearBarrier plain(c, 0.2f);
  model.Step(s, actions, next);
  Eigen::VectorXf h(24), hk(72);
  pessimistic.Evaluate(next, h);
  plain.Evaluate(members, hk);
  for (int i = 0; i < 24; ++i)
    EXPECT_EQ(h[i], std::min({hk[i], hk[24 + i], hk[48 + i]})) << i;
  // hold 1 is the model as trained; the range is checked and the hold is named.
  PessimismOptions single;
  const EnsembleModel plain_model(shared, 64, nn::MatmulBackend::kAuto, single);
  Eigen::MatrixXf again(4, 24);
  plain_model.Step(s, actions, again);
  EXPECT_EQ(again, once);
  EXPECT_EQ(held.Describe(), "min, hold 3");
  EXPECT_EQ(single.Describe(), "min");
  for (int bad : {0, kMaxHold + 1}) {
    PessimismOptions wrong;
    wrong.hold = bad;
    EXPECT_HAS(test::ErrorOf([&] { wrong.Validate(); }), "hold = " + std::to_string(bad));
  }
}

TEST_F(DynamicsTest, ForShieldModelWrapsOnlyAnEnsemble) {
  auto shared = std::make_shared<const EnsembleDynamics>(RandomEnsemble(2, 1, 2, {8}, 2));
  const EnsembleModel model(shared, 8);
  auto wrapped = ForShieldModel(std::make_unique<LinearBarrier>(Eigen::Vector2f(1, 1), 0), model);
  EXPECT_NE(dynamic_cast<PessimisticBarrier*>(wrapped.get()), nullptr);
  EXPECT_HAS(wrapped->Describe(), "min over the 2 members");
  Eigen::MatrixXf big(1, 9);
  Eigen::MatrixXf out(2, 9);
  EXPECT_HAS(test::ErrorOf([&] { model.Step(Eigen::Vector2f(0, 0), big.setZero(), out); }),
             "exceeds the model's max_batch 8");
}

TEST_F(DynamicsTest, ReadsTriplesAndTrajectories) {
  const std::string triples = Write("t.csv",
                                    "x,v,u,next_x,next_v,extra\n"
                                    "0,1,0.5,0.1,1.05,7\n"
                                    "1,0,-1,1,-0.1,7\n");
  const Transitions t = ReadTransitions(triples, {"x", "v"}, {"u"});
  ASSERT_EQ(t.size(), 2);
  EXPECT_FLOAT_EQ(t.next_states(1, 0), 1.05f);
  EXPECT_FLOAT_EQ(t.actions(0, 1), -1.0f);
  EXPECT_TRUE(t.run_begin.empty());
  const std::string demos = Write("demos.csv",
                                  "episode,step,x,v,u\n"
                                  "0,0,0,0,1\n0,1,0,0.1,1\n0,2,0.01,0.2,1\n"
                                  "1,0,5,5,0\n1,1,5,5,0\n");
  const Transitions d = ReadTransitions(demos, {"x", "v"}, {"u"});
  ASSERT_EQ(d.size(), 3);  // 2 + 1
  EXPECT_FLOAT_EQ(d.next_states(1, 1), 0.2f);
  EXPECT_EQ(d.lines[2], 5);  // episode 1's first row is line 5
  EXPECT_EQ(d.run_begin, (std::vector<long>{0, 2, 3}));
  // Round trip as triples.
  WriteTransitions(PathOf("out.csv"), d);
  const Transitions back = ReadTransitions(PathOf("out.csv"), {"x", "v"}, {"u"});
  EXPECT_EQ(back.states, d.states);
  EXPECT_EQ(back.next_states, d.next_states);
}

TEST_F(DynamicsTest, BadInputsGiveOneLineNamingFileAndRow) {
  const std::string nan = Write("nan.csv", "x,u,next_x\n0,1,2\n1,nan,3\n");
  const std::string m1 = test::ErrorOf([&] { ReadTransitions(nan, {"x"}, {"u"}); });
  EXPECT_HAS(m1, "nan.csv:3");
  EXPECT_EQ(m1.find('\n'), std::string::npos);
  const std::string inf = Write("inf.csv", "x,u,next_x\n0,1,2\n1,2,1e300\n");
  const std::string m2 = test::ErrorOf([&] { ReadTransitions(inf, {"x"}, {"u"}); });
  EXPECT_HAS(m2, "inf.csv:3");
  const std::string names = Write("names.csv", "y,u,next_y\n0,1,2\n");
  const std::string m3 = test::ErrorOf([&] { ReadTransitions(names, {"x"}, {"u"}); });
  EXPECT_HAS(m3, "names.csv");
  EXPECT_HAS(m3, "next_x");
  const std::string wrong_action = Write("act.csv", "x,w,next_x\n0,1,2\n");
  EXPECT_HAS(test::ErrorOf([&] { ReadTransitions(wrong_action, {"x"}, {"u"}); }), "'u'");
  const std::string few = Write("few.csv", "x,u,next_x\n0,1,2\n1,1,2\n");
  const Transitions t = ReadTransitions(few, {"x"}, {"u"});
  const std::string m4 = test::ErrorOf([&] { TrainDynamics(DynamicsTrainerOptions{}, t); });
  EXPECT_HAS(m4, "few.csv: 2 transitions, need at least 20");
  DynamicsTrainerOptions o;
  o.members = 0;
  EXPECT_HAS(test::ErrorOf([&] { o.Validate(); }), "DynamicsTrainerOptions::members = 0");
}

TEST_F(DynamicsTest, LearnedModelEnvironmentChecksFeatures) {
  const EnsembleDynamics e = RandomEnsemble(2, 1, 2, {8}, 2);
  EXPECT_NO_THROW(CheckModelFeatures(e, {"s0", "s1"}, {"a0"}, "m.model"));
  const std::string m = test::ErrorOf([&] { CheckModelFeatures(e, {"s0", "x"}, {"a0"}, "m.model"); });
  EXPECT_HAS(m, "m.model: the learned dynamics predicts 2 features (s0, s1)");
  EXPECT_HAS(test::ErrorOf([&] { CheckModelFeatures(e, {"s0", "s1"}, {"b"}, "m.model"); }),
             "reads 1 actions (a0)");
}

}  // namespace
}  // namespace secure::dynamics
