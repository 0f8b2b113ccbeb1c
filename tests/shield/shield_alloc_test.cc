// Shield::Decide() must not allocate (shield.h: "construct once, then Decide() allocates
// nothing"). This executable replaces the global operator new/delete (every variant) with counting
// versions, and also interposes the C allocator (tests/malloc_counter.h, plus posix_memalign):
// Eigen allocates its heap buffers (e.g. GEMM packing blocks) with std::malloc, not operator new,
// so counting operator new alone would miss them. Counting is off except inside CountDuring().
//
// The interposition forwards to glibc's __libc_* entry points, so it is glibc-specific (as is the
// project: Debian 12).

#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "domains/derby/derby.h"
#include "domains/derby/domain.h"
#include "domains/double_integrator/double_integrator.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/dynamics/ensemble.h"
#include "secure/nn/mlp.h"
#include "secure/policy/airl_reward.h"
#include "tests/malloc_counter.h"

// ------------------------------------------------------------------------------------------------
// Counting allocators.

namespace {

std::atomic<long> new_calls{0};  // operator new / new[] (all variants)

void CountNew() {
  if (secure::test::malloc_counting.load(std::memory_order_relaxed))
    new_calls.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

// malloc, calloc, realloc, memalign and aligned_alloc count through tests/malloc_counter.h; this
// executable adds posix_memalign (Eigen's aligned allocations may take it) and operator new.
extern "C" {
void* __libc_malloc(std::size_t size);
void __libc_free(void* pointer);

int posix_memalign(void** pointer, std::size_t alignment, std::size_t size) noexcept {
  secure::test::CountMalloc();
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return 22;  // EINVAL
  void* p = __libc_memalign(alignment, size);
  if (p == nullptr && size != 0) return 12;  // ENOMEM
  *pointer = p;
  return 0;
}
void free(void* pointer) noexcept { __libc_free(pointer); }
}  // extern "C"

namespace {

void* NewOrThrow(std::size_t size) {
  CountNew();
  void* p = __libc_malloc(size == 0 ? 1 : size);
  if (p == nullptr) throw std::bad_alloc();
  return p;
}
void* AlignedNewOrThrow(std::size_t size, std::align_val_t alignment) {
  CountNew();
  void* p = __libc_memalign(static_cast<std::size_t>(alignment), size == 0 ? 1 : size);
  if (p == nullptr) throw std::bad_alloc();
  return p;
}

}  // namespace

void* operator new(std::size_t size) { return NewOrThrow(size); }
void* operator new[](std::size_t size) { return NewOrThrow(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  CountNew();
  return __libc_malloc(size == 0 ? 1 : size);
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  CountNew();
  return __libc_malloc(size == 0 ? 1 : size);
}
void* operator new(std::size_t size, std::align_val_t alignment) {
  return AlignedNewOrThrow(size, alignment);
}
void* operator new[](std::size_t size, std::align_val_t alignment) {
  return AlignedNewOrThrow(size, alignment);
}
void* operator new(std::size_t size, std::align_val_t alignment, const std::nothrow_t&) noexcept {
  CountNew();
  return __libc_memalign(static_cast<std::size_t>(alignment), size == 0 ? 1 : size);
}
void* operator new[](std::size_t size, std::align_val_t alignment, const std::nothrow_t&) noexcept {
  CountNew();
  return __libc_memalign(static_cast<std::size_t>(alignment), size == 0 ? 1 : size);
}
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { __libc_free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { __libc_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { __libc_free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  __libc_free(p);
}

// ------------------------------------------------------------------------------------------------

namespace secure::shield {
namespace {

namespace di = domains::double_integrator;

struct Allocations {
  long news = 0;
  long mallocs = 0;
  long total() const { return news + mallocs; }
};

/// Runs `fn` with counting on; no gtest assertion may run inside.
template <typename Fn>
Allocations CountDuring(Fn&& fn) {
  new_calls.store(0);
  secure::test::BeginCountingMalloc();
  fn();
  const long mallocs = secure::test::EndCountingMalloc();
  return {new_calls.load(), mallocs};
}

std::string Describe(const Allocations& a) {
  return std::to_string(a.total()) + " allocations (" + std::to_string(a.news) + " operator new, " +
         std::to_string(a.mallocs) + " malloc-family)";
}

using test::IntegratorDynamics;
using test::Vec;

/// h(s) = inner(s) + slope * (s[row] - offset): a (random) barrier network tilted so that one
/// action direction is unsafe, which makes the resampling and fallback paths reachable. The
/// network is evaluated on every batch, so its allocations are what the tests measure.
class TiltedBarrier final : public cbf::Barrier {
 public:
  TiltedBarrier(cbf::Barrier& inner, int row, float slope, float offset)
      : inner_(inner), row_(row), slope_(slope), offset_(offset) {}
  int state_dim() const override { return inner_.state_dim(); }
  std::string Describe() const override { return "tilted " + inner_.Describe(); }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    inner_.Evaluate(states, h);
    for (Eigen::Index i = 0; i < states.cols(); ++i) h[i] += slope_ * (states(row_, i) - offset_);
  }
  // The inner barrier's gradient (analytic for the learned ones), tilted.
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> gradients) override {
    inner_.EvaluateGradient(states, h, gradients);
    for (Eigen::Index i = 0; i < states.cols(); ++i) {
      h[i] += slope_ * (states(row_, i) - offset_);
      gradients(row_, i) += slope_;
    }
  }

 private:
  cbf::Barrier& inner_;
  int row_;
  float slope_, offset_;
};

cbf::BarrierNet MakeNet(int input_dim, std::vector<int> hidden, unsigned long long seed) {
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams(nn::MlpSpec{input_dim, std::move(hidden), 1, nn::Activation::kTanh},
                                seed);
  net.normalizer = nn::Normalizer::Identity(input_dim);
  for (int i = 0; i < input_dim; ++i) net.features.push_back("s" + std::to_string(i));
  return net;
}

constexpr int kWarmUp = 5;
constexpr int kDecisions = 1000;

/// One decision problem and what its warm-up decisions must show (so that each test really
/// exercises the path it is named after).
struct Scenario {
  std::string name;
  Eigen::VectorXf state, mu, sigma;
  ShieldOptions options;
  bool with_backup = false;
  Eigen::VectorXf backup;
  ActionValue* value = nullptr;  // aggregation = top-q's task value
  Eigen::VectorXf low, high;     // the actuator box (empty: none)
  // Expected of the warm-up decisions:
  bool expect_resampling = false;  // iterations > 1
  bool expect_fallback = false;    // a no-safe-sample decision (fallback != none)
  bool expect_invalid = false;     // kInvalidInput
};

/// Warm-up decisions (checked), then `decisions` counted decisions.
void ExpectNoAllocations(const Scenario& s, cbf::Barrier& barrier,
                         const domains::DynamicsModel& dynamics, int decisions = kDecisions,
                         const std::string& note = "") {
  SCOPED_TRACE(s.name);
  Shield shield(s.options, barrier, dynamics);
  if (s.low.size() > 0) shield.SetActionBounds(s.low, s.high);
  if (s.with_backup) shield.SetBackupAction(s.backup);
  shield.SetActionValue(s.value);
  for (int i = 0; i < kWarmUp; ++i) {
    const Decision& d = shield.Decide(s.state, s.mu, s.sigma);
    ASSERT_TRUE(d.action.allFinite());
    if (s.expect_invalid) {
      ASSERT_EQ(d.status, Status::kInvalidInput);
    } else {
      ASSERT_NE(d.status, Status::kInvalidInput);
    }
    if (s.options.proposal != Proposal::kNone) {
      // The CBF-QP projection was tried; it decided (no sampling round) or sampling followed.
      if (!s.expect_invalid) ASSERT_NE(d.qp, QpOutcome::kNotTried) << d.ToJson().dump();
      continue;
    }
    if (s.expect_resampling) {
      ASSERT_GT(d.iterations, 1) << d.ToJson().dump();
    }
    if (s.expect_fallback) {
      ASSERT_NE(d.fallback, Fallback::kNone) << d.ToJson().dump();
    }
    if (!s.expect_resampling && !s.expect_fallback && !s.expect_invalid) {
      ASSERT_EQ(d.iterations, 1) << d.ToJson().dump();
    }
  }
  double checksum = 0.0;
  const Allocations a = CountDuring([&] {
    for (int i = 0; i < decisions; ++i) checksum += shield.Decide(s.state, s.mu, s.sigma).g;
  });
  EXPECT_EQ(a.total(), 0) << Describe(a) << " in " << decisions << " decisions" << note;
  (void)checksum;
}

/// The four paths of Decide() on the double integrator (ground-truth or learned barrier), plus
/// the two ablations.
std::vector<Scenario> DoubleIntegratorScenarios(bool learned) {
  std::vector<Scenario> scenarios;
  const Eigen::VectorXf far = Vec({1.0f, 1.0f, 0.0f, 0.0f});
  const Eigen::VectorXf close = Vec({5.0f, 7.6f, 0.0f, -1.5f});

  Scenario none;
  none.name = "no resampling";
  none.state = far;
  none.mu = Vec({0.3f, -0.2f});
  none.sigma = Vec({0.5f, 0.5f});
  scenarios.push_back(none);

  Scenario resampling;
  resampling.name = "resampling";
  resampling.state = close;
  resampling.mu = Vec({0.0f, -5.0f});
  resampling.sigma = Vec({0.05f, 0.05f});
  resampling.options.max_iterations = learned ? 6 : 50;
  resampling.expect_resampling = true;
  scenarios.push_back(resampling);

  Scenario fallback = resampling;
  fallback.name = "no safe action, backup";
  fallback.options.max_iterations = 2;
  fallback.options.sigma_step = 1e-3;
  fallback.options.safe_ratio = 0.99;
  fallback.with_backup = true;
  fallback.backup = Vec({0.0f, -4.0f});
  fallback.expect_fallback = true;
  fallback.expect_resampling = true;
  scenarios.push_back(fallback);

  Scenario invalid = none;
  invalid.name = "invalid input";
  invalid.state = Vec({1.0f, std::numeric_limits<float>::quiet_NaN(), 0.0f, 0.0f});
  invalid.with_backup = true;
  invalid.backup = Vec({0.0f, 1.0f});
  invalid.expect_invalid = true;
  scenarios.push_back(invalid);

  Scenario random_safe = resampling;
  random_safe.name = "random-safe aggregation";
  random_safe.options.aggregation = Aggregation::kRandomSafe;
  scenarios.push_back(random_safe);

  // Q = x of the predicted next state (static: the scenarios outlive this function).
  static test::LinearActionValue progress(Vec({1.0f, 0.0f, 0.0f, 0.0f}));
  Scenario top_q = resampling;
  top_q.name = "top-q aggregation";
  top_q.options.aggregation = Aggregation::kTopQ;
  top_q.value = &progress;
  scenarios.push_back(top_q);
  Scenario top_q_far = none;
  top_q_far.name = "top-q aggregation, no resampling";
  top_q_far.options.aggregation = Aggregation::kTopQ;
  top_q_far.value = &progress;
  scenarios.push_back(top_q_far);

  Scenario lookahead = resampling;
  lookahead.name = "lookahead_steps = 3";
  lookahead.options.lookahead_steps = 3;
  scenarios.push_back(lookahead);

  Scenario policy_draw = none;
  policy_draw.name = "policy-draw aggregation";
  policy_draw.options.aggregation = Aggregation::kPolicyDraw;
  scenarios.push_back(policy_draw);

  Scenario policy_mean = resampling;  // an unsafe mean: Algorithm 1 after the mean's check
  policy_mean.name = "policy-mean aggregation, unsafe mean";
  policy_mean.options.aggregation = Aggregation::kPolicyMean;
  scenarios.push_back(policy_mean);
  Scenario policy_mean_safe = none;  // a safe mean: returned after one evaluation
  policy_mean_safe.name = "policy-mean aggregation, safe mean";
  policy_mean_safe.options.aggregation = Aggregation::kPolicyMean;
  scenarios.push_back(policy_mean_safe);

  // The first-safe sampler: the policy's draw when safe (one evaluation), else the first safe
  // sample of a round (adaptive resampling here), else, with the policy's own sigma, the fallback.
  Scenario first_safe[3] = {none, resampling, resampling};
  const char* const first_safe_names[3] = {"safe draw", "resampling", "resampling = none"};
  for (int k = 0; k < 3; ++k) {
    first_safe[k].name = std::string("first-safe aggregation, ") + first_safe_names[k];
    first_safe[k].options.aggregation = Aggregation::kFirstSafe;
  }
  first_safe[2].options.resampling = Resampling::kNone;
  first_safe[2].options.max_iterations = 3;
  first_safe[2].with_backup = true;
  first_safe[2].backup = Vec({0.0f, -4.0f});
  first_safe[2].expect_fallback = true;
  scenarios.insert(scenarios.end(), first_safe, first_safe + 3);

  Scenario no_resampling = resampling;
  no_resampling.name = "resampling = none";
  no_resampling.options.resampling = Resampling::kNone;
  no_resampling.options.max_iterations = 3;
  no_resampling.expect_fallback = true;
  scenarios.push_back(no_resampling);

  // The actuator box cutting into the decision: mu = (0, -5) lies below it.
  for (ActionBounds mode : {ActionBounds::kClip, ActionBounds::kReject}) {
    const std::string bounds = ToString(kActionBoundsNames, mode);
    Scenario boxed = resampling;
    boxed.name = "actuator box, " + bounds;
    boxed.options.action_bounds = mode;
    boxed.low = Vec({-1.0f, -4.9f});
    boxed.high = Vec({1.0f, 1.0f});
    scenarios.push_back(boxed);
    Scenario boxed_mean = boxed;
    boxed_mean.name = "actuator box, " + bounds + ", policy-mean";
    boxed_mean.options.aggregation = Aggregation::kPolicyMean;
    scenarios.push_back(boxed_mean);
    Scenario boxed_random = boxed;  // ablation 2's random sample, clipped if rejected
    boxed_random.name = "actuator box, " + bounds + ", resampling = none";
    boxed_random.options.resampling = Resampling::kNone;
    boxed_random.options.max_iterations = 3;
    boxed_random.expect_fallback = true;
    scenarios.push_back(boxed_random);
  }

  Scenario cubic = resampling;
  cubic.name = "cubic class-K, time budget";
  cubic.options.class_k = ClassK::kCubic;
  cubic.options.time_budget_us = 1e6;
  scenarios.push_back(cubic);

  // The CBF-QP projection first (proposal qp: sampling follows a rejected one) or alone
  // (qp-only), with a safe and an unsafe mean, with and without the box; re-linearised too.
  for (Proposal proposal : {Proposal::kQp, Proposal::kQpOnly, Proposal::kRefine}) {
    const std::string name = "proposal " + std::string(ToString(kProposalNames, proposal));
    Scenario safe = none;
    safe.name = name + ", safe mean";
    safe.options.proposal = proposal;
    scenarios.push_back(safe);
    Scenario unsafe = resampling;
    unsafe.name = name + ", unsafe mean";
    unsafe.options.proposal = proposal;
    unsafe.options.qp_iterations = 3;
    unsafe.expect_resampling = false;
    scenarios.push_back(unsafe);
    Scenario boxed = unsafe;
    boxed.name = name + ", unsafe mean, actuator box";
    boxed.low = Vec({-1.0f, -4.9f});
    boxed.high = Vec({1.0f, 1.0f});
    boxed.options.qp_margin = 0.5;
    scenarios.push_back(boxed);
    if (proposal == Proposal::kRefine) continue;
    for (Scenario searched : {unsafe, boxed}) {  // secant steps along a rejected projection
      searched.name += ", qp_line_search 3";
      searched.options.qp_line_search = 3;
      scenarios.push_back(searched);
      searched.name += ", qp_bisection 4";  // and bisection back along an overshooting one
      searched.options.qp_bisection = 4;
      scenarios.push_back(searched);
      searched.name += ", qp_smoothing 2";  // and a last round on the slope over sigma
      searched.options.qp_smoothing = 2.0;
      scenarios.push_back(searched);
    }
    for (Scenario metric : {unsafe, boxed}) {  // the projection in the policy's metric
      metric.name += ", qp_metric policy";
      metric.options.qp_metric = QpMetric::kPolicy;
      scenarios.push_back(metric);
    }
  }

  // Every path again with the other samplers (odd M for the antithetic one: an unpaired column).
  const std::size_t iid_count = scenarios.size();
  for (Sampler sampler : {Sampler::kAntithetic, Sampler::kQmc}) {
    for (std::size_t i = 0; i < iid_count; ++i) {
      Scenario s = scenarios[i];
      s.name += ", sampler = " + std::string(ToString(kSamplerNames, sampler));
      s.options.sampler = sampler;
      if (sampler == Sampler::kAntithetic) s.options.num_samples = 63;
      scenarios.push_back(s);
    }
  }
  return scenarios;
}

TEST(ShieldAllocTest, CounterSeesOperatorNewMallocAndEigen) {
  volatile long sink = 0;
  const Allocations a = CountDuring([&] {
    int* p = new int(3);
    sink = sink + *p;
    delete p;
    void* m = std::malloc(64);
    sink = sink + (m != nullptr);
    std::free(m);
    Eigen::MatrixXf big(256, 256);  // Eigen allocates with malloc
    big.setOnes();
    sink = sink + static_cast<long>(big.sum());
    std::vector<double> v(10);
    sink = sink + static_cast<long>(v.size());
  });
  EXPECT_EQ(a.news, 2);     // new int, the vector
  EXPECT_EQ(a.mallocs, 2);  // malloc, Eigen
  EXPECT_EQ(CountDuring([] {}).total(), 0);
}

TEST(ShieldAllocTest, GroundTruthDecisionsDoNotAllocate) {
  const di::Dynamics dynamics(0.1);
  domains::double_integrator::GroundTruthBarrier barrier{di::GroundTruth{}};
  for (const Scenario& s : DoubleIntegratorScenarios(false))
    ExpectNoAllocations(s, barrier, dynamics);
}

TEST(ShieldAllocTest, SmallLearnedBarrierDecisionsDoNotAllocate) {
  const cbf::BarrierNet net = MakeNet(4, {64, 64}, 7);
  const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator();
  // + 100 (vy + 1.5): braking (ay > 0) is needed at the "close" state, where vy = -1.5.
  TiltedBarrier barrier(*evaluator, 3, 100.0f, -1.5f);
  const di::Dynamics dynamics(0.1);
  for (const Scenario& s : DoubleIntegratorScenarios(true))
    ExpectNoAllocations(s, barrier, dynamics);
}

// A barrier on some of the state's features (BarrierNet::MakeEvaluatorFor: rows picked by name
// into a preallocated buffer) allocates nothing per evaluation, at batches up to and beyond its
// chunk, nor in the shield's decisions.
TEST(ShieldAllocTest, ABarrierOnSomeStateFeaturesDoesNotAllocate) {
  const cbf::BarrierNet small = MakeNet(2, {16, 16}, 9);  // s0, s1
  const std::unique_ptr<cbf::Barrier> picker =
      small.MakeEvaluatorFor({"a", "s1", "b", "s0"}, "the test states", "the net", 64);
  for (int batch : {1, 64, 200}) {
    const Eigen::MatrixXf states = Eigen::MatrixXf::Random(4, batch);
    Eigen::VectorXf h(batch);
    picker->Evaluate(states, h);  // warm-up
    EXPECT_EQ(CountDuring([&] { picker->Evaluate(states, h); }).total(), 0) << "batch " << batch;
  }
  // The double integrator's decisions with a barrier that reads its rows in another order.
  const cbf::BarrierNet net = MakeNet(4, {64, 64}, 7);
  const std::unique_ptr<cbf::Barrier> evaluator =
      net.MakeEvaluatorFor({"s3", "s2", "s1", "s0"}, "the test states", "the net");
  ASSERT_EQ(dynamic_cast<cbf::SelectRows*>(evaluator.get()) != nullptr, true);
  TiltedBarrier barrier(*evaluator, 3, 100.0f, -1.5f);
  const di::Dynamics dynamics(0.1);
  for (const Scenario& s : DoubleIntegratorScenarios(true))
    ExpectNoAllocations(s, barrier, dynamics);
}

// A Panda-sized barrier (9 inputs, ten hidden layers up to 256 wide) at M = 128. inference_mlp.h
// documents a known gap (Eigen's GEMM allocates its packing buffers for wide layers); this test
// asserts the contract (0 allocations) and reports the count when it is violated, with the count
// of one barrier evaluation per batch size. Measured (Eigen 3.4, -march=native): 1 malloc per
// 256 -> 256 layer per evaluation at any batch >= 2 (its 256 x 256 float packed block exceeds
// EIGEN_STACK_ALLOCATION_LIMIT = 128 KiB); 128-wide layers do not allocate; batch 1 (the mean
// action) does not allocate. So 3 per evaluation here, 9 per decision (2 sample rounds + 1 probe
// round).
TEST(ShieldAllocTest, PandaSizedLearnedBarrierDecisionsDoNotAllocate) {
  const cbf::BarrierNet net = MakeNet(9, {32, 128, 128, 256, 256, 256, 256, 128, 128, 32}, 11);
  const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator();
  const IntegratorDynamics dynamics(9, 0.1);
  Scenario s;
  s.name = "panda-sized, M = 128, resampling";
  s.state = Eigen::VectorXf::LinSpaced(9, -0.5f, 0.5f);
  // - 100 (s0 - state0): a0 > 0 is unsafe; mu0 = 0.2 makes most samples unsafe, so that a probe
  // round (N = 64) and a second sample round run.
  TiltedBarrier barrier(*evaluator, 0, -100.0f, s.state[0]);
  s.mu = Eigen::VectorXf::Constant(9, 0.2f);
  s.sigma = Eigen::VectorXf::Constant(9, 0.3f);
  s.options.num_samples = 128;
  s.options.safe_ratio = 0.5;
  s.options.max_iterations = 2;
  s.expect_resampling = true;

  // Where the allocations come from: one barrier evaluation per batch size Decide() uses (M
  // samples, N probes, the single mean action).
  std::string note = "; per barrier evaluation:";
  for (int batch : {128, 64, 1}) {
    const Eigen::MatrixXf states = Eigen::MatrixXf::Random(9, batch);
    Eigen::VectorXf h(batch);
    evaluator->Evaluate(states, h);  // warm-up
    const Allocations a = CountDuring([&] { evaluator->Evaluate(states, h); });
    note += " batch " + std::to_string(batch) + ": " + std::to_string(a.total());
  }
  // Fewer decisions than the other tests: one costs ~5 ms (3 batched passes of a 300k-MAC net).
  ExpectNoAllocations(s, barrier, dynamics, 200, note);
  // The other samplers, 9-dimensional actions (QMC: a 9-D Sobol table built in the constructor).
  for (Sampler sampler : {Sampler::kAntithetic, Sampler::kQmc}) {
    Scenario other = s;
    other.name += ", sampler = " + std::string(ToString(kSamplerNames, sampler));
    other.options.sampler = sampler;
    ExpectNoAllocations(other, barrier, dynamics, 50, note);
  }
  // The gradient-first shield: the projection (the MLP's backward pass at one state), then
  // Algorithms 1-2 if it is rejected.
  Scenario qp = s;
  qp.name += ", proposal qp";
  qp.options.proposal = Proposal::kQp;
  ExpectNoAllocations(qp, barrier, dynamics, 50, note);
  // The gradient refinement (proposal refine) and the first-safe sampler.
  Scenario refine = s;
  refine.name += ", proposal refine";
  refine.options.proposal = Proposal::kRefine;
  ExpectNoAllocations(refine, barrier, dynamics, 50, note);
  Scenario first_safe = s;
  first_safe.name += ", first-safe";
  first_safe.options.aggregation = Aggregation::kFirstSafe;
  first_safe.expect_resampling = false;  // a quarter of the draws are safe: round 1 has some
  ExpectNoAllocations(first_safe, barrier, dynamics, 50, note);
}

// Top-q with AIRL's task value (policy::AirlActionValue: the reward and shaping MLPs on the
// predicted next states), on all features and on some of them (rows gathered into a buffer).
TEST(ShieldAllocTest, TopQWithAirlsTaskValueDoesNotAllocate) {
  const di::Dynamics dynamics(0.1);
  domains::double_integrator::GroundTruthBarrier barrier{di::GroundTruth{}};
  for (const std::vector<std::string>& inputs :
       {std::vector<std::string>{}, std::vector<std::string>{"s0", "s2"}}) {
    policy::AirlRewardModel model;
    const int in = inputs.empty() ? 4 : static_cast<int>(inputs.size());
    model.reward = nn::RandomMlpParams(nn::MlpSpec{in, {32, 32}, 1, nn::Activation::kRelu}, 21);
    model.shaping = nn::RandomMlpParams(nn::MlpSpec{in, {32, 32}, 1, nn::Activation::kRelu}, 22);
    model.input = nn::Normalizer::Identity(in);
    model.observation_features = {"s0", "s1", "s2", "s3"};
    model.input_features = inputs;
    policy::AirlActionValue value(model, model.observation_features, 64);
    for (Scenario s : DoubleIntegratorScenarios(false)) {
      if (s.options.aggregation != Aggregation::kTopQ) continue;
      s.value = &value;
      s.name += ", AIRL task value on " + std::to_string(in) + " features";
      ExpectNoAllocations(s, barrier, dynamics);
    }
  }
}

// Demolition Derby: the per-car barrier (3-64-128-64-1 over the 12 observed cars, min over cars
// in range) with the shield's constant-velocity model, M = 64, resampling.
TEST(ShieldAllocTest, DerbyPerCarBarrierDecisionsDoNotAllocate) {
  cbf::CarBarrierNet net;
  net.input.layout = domains::derby::ObstacleLayoutOfObservation();
  net.mlp = nn::RandomMlpParams(nn::MlpSpec{3, {64, 128, 64}, 1, nn::Activation::kRelu}, 5);
  net.normalizer = nn::Normalizer::Identity(3);
  net.cap = 0.05;
  const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator(256);
  // An observation with cars around the ego, the nearest one just ahead on the x axis.
  Scenario s;
  s.name = "derby per-car, M = 64, resampling";
  s.state = Eigen::VectorXf::Zero(domains::derby::kObservationDim);
  s.state << 1.0f, 1.0f, 0.6f, 0.0f;
  for (int i = 0; i < domains::derby::kObservedCars; ++i) {
    const float angle = 0.5f * static_cast<float>(i);
    const float distance = 0.12f + 0.07f * static_cast<float>(i);
    s.state[4 + 4 * i] = distance * std::cos(angle);
    s.state[5 + 4 * i] = distance * std::sin(angle);
  }
  // h tilted by -100 (ego vx - 0.6): accelerating along +x is unsafe, so resampling runs.
  TiltedBarrier barrier(*evaluator, 2, -100.0f, 0.6f);
  s.mu = Eigen::Vector2f(2.0f, 0.0f);
  s.sigma = Eigen::Vector2f(0.3f, 0.3f);
  s.options.num_samples = 64;
  s.options.max_iterations = 3;
  s.expect_resampling = true;
  const domains::derby::DerbyShieldModel model(0.1, 3.0, 3);
  ExpectNoAllocations(s, barrier, model, 300);
  for (Proposal proposal : {Proposal::kQp, Proposal::kQpOnly, Proposal::kRefine}) {
    Scenario qp = s;
    qp.name += ", proposal " + std::string(ToString(kProposalNames, proposal));
    qp.options.proposal = proposal;
    ExpectNoAllocations(qp, barrier, model, 300);
    if (proposal == Proposal::kRefine) continue;
    qp.name += ", qp_metric policy";
    qp.options.qp_metric = QpMetric::kPolicy;
    ExpectNoAllocations(qp, barrier, model, 300);
  }
  s.name += ", sampler = qmc";
  s.options.sampler = Sampler::kQmc;
  ExpectNoAllocations(s, barrier, model, 300);
}


// The learned dynamics (secure/dynamics): a K = 5 ensemble as the shield model and the barrier
// wrapped pessimistically (min over the members' next states, one forward over K M columns), at
// Panda size (9-D states and actions, M = 128, members 18-64-64-9): no allocation per decision,
// in a round without resampling and in one with resampling (probes included).
TEST(ShieldAllocTest, LearnedDynamicsEnsembleDecisionsDoNotAllocate) {
  auto ensemble = std::make_shared<dynamics::EnsembleDynamics>();
  for (int i = 0; i < 9; ++i) {
    ensemble->state_features.push_back("s" + std::to_string(i));
    ensemble->action_features.push_back("a" + std::to_string(i));
  }
  for (int k = 0; k < 5; ++k)
    ensemble->members.push_back(
        nn::RandomMlpParams(nn::MlpSpec{18, {64, 64}, 9, nn::Activation::kTanh}, 40 + k));
  ensemble->input = nn::Normalizer::Identity(18);
  ensemble->delta = nn::Normalizer::Identity(9);
  ensemble->delta.scale.setConstant(0.02f);
  const dynamics::EnsembleModel model(ensemble, 128);
  const cbf::BarrierNet net = MakeNet(9, {64, 64}, 13);
  Scenario s;
  s.state = Eigen::VectorXf::LinSpaced(9, -0.5f, 0.5f);
  s.mu = Eigen::VectorXf::Constant(9, 0.2f);
  s.sigma = Eigen::VectorXf::Constant(9, 0.3f);
  s.options.num_samples = 128;
  {
    // h far above 0 everywhere: every sample safe, one round.
    const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator();
    dynamics::PessimisticBarrier barrier(
        std::make_unique<TiltedBarrier>(*evaluator, 0, 1.0f, -1000.0f), model);
    s.name = "learned ensemble K = 5, M = 128, safe";
    ExpectNoAllocations(s, barrier, model, 200);
  }
  {
    // Steeply tilted through the state: about half the samples unsafe, so resampling runs.
    const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator();
    dynamics::PessimisticBarrier barrier(
        std::make_unique<TiltedBarrier>(*evaluator, 0, -1000.0f, s.state[0]), model);
    s.name = "learned ensemble K = 5, M = 128, resampling";
    s.options.safe_ratio = 0.99;
    s.options.max_iterations = 3;
    s.expect_resampling = true;
    ExpectNoAllocations(s, barrier, model, 100);
  }
  {
    // The other pessimism options (issue 36): mean − κ std, and first order through the
    // barrier's gradient at s (finite differences here: its buffers are sized at the first call).
    const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator();
    dynamics::PessimismOptions pessimism;
    pessimism.aggregate = dynamics::PessimismOptions::Aggregate::kMeanStd;
    pessimism.linear = true;
    dynamics::PessimisticBarrier barrier(
        std::make_unique<TiltedBarrier>(*evaluator, 0, -1000.0f, s.state[0]), model, pessimism);
    s.name = "learned ensemble K = 5, M = 128, resampling, linear mean-std";
    ExpectNoAllocations(s, barrier, model, 100);
  }
  {
    // A model that holds the action 3 steps, each member on its own chain (--dynamics-hold).
    dynamics::PessimismOptions held;
    held.hold = 3;
    const dynamics::EnsembleModel holding(ensemble, 128, nn::MatmulBackend::kAuto, held);
    const std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator();
    dynamics::PessimisticBarrier barrier(
        std::make_unique<TiltedBarrier>(*evaluator, 0, -1000.0f, s.state[0]), holding);
    s.name = "learned ensemble K = 5, M = 128, resampling, hold 3";
    ExpectNoAllocations(s, barrier, holding, 100);
  }
}

}  // namespace
}  // namespace secure::shield
