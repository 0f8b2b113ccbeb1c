// realtime_loop: a shielded policy in a fixed-rate control loop, built against an installed
// SECURE (find_package(secure)). Every period (1 ms by default) the loop wakes at an absolute
// deadline (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)), asks the policy for its Gaussian
// N(mu, sigma) at the plant's state, lets the CBF shield pick a safe action with a learned
// barrier, and applies it to a simulated 2-D double integrator heading for a goal past a circular
// obstacle. At the end it reports deadline misses and decision-latency percentiles.
//
//   realtime_loop --barrier di.model [--policy bc.model] [--duration 5] [--rate 1000]
//                 [--samples 64] [--max-iterations 20] [--time-budget-us 0] [--realtime]
//
// Nothing is allocated inside the loop: the shield, the barrier evaluator and the policy
// evaluator allocate their buffers when constructed, and the latency records are sized before
// the loop starts. docs/EMBEDDING.md (in the SECURE repository) has the contract.
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <time.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/domains/dynamics.h"
#include "secure/policy/gaussian_policy.h"
#include "secure/shield/shield.h"

namespace {

// ------------------------------------------------------------------------------------------
// Options.

struct Options {
  std::string barrier;      // barrier model file (secure cbf train), features x, y, vx, vy
  std::string policy;       // optional Gaussian policy model file (secure policy train)
  double duration_s = 5.0;  // wall time of the loop
  int rate_hz = 1000;
  int samples = 64;         // M
  int max_iterations = 20;  // K
  double time_budget_us = 0.0;
  bool realtime = false;  // mlockall + SCHED_FIFO (each optional: a note if not permitted)
  int priority = 80;      // SCHED_FIFO priority with --realtime
  std::uint64_t seed = 1;
};

constexpr const char* kUsage =
    "usage: realtime_loop --barrier FILE [--policy FILE] [--duration SECONDS] [--rate HZ]\n"
    "                     [--samples M] [--max-iterations K] [--time-budget-us US]\n"
    "                     [--realtime] [--priority 1..99] [--seed N]\n";

double ParseNumber(const std::string& flag, const char* text) {
  char* end = nullptr;
  errno = 0;
  const double value = std::strtod(text, &end);
  if (end == text || *end != '\0' || errno != 0 || !std::isfinite(value))
    throw std::runtime_error(flag + " = '" + text + "' is not a number");
  return value;
}

int ParseInt(const std::string& flag, const char* text, int lo, int hi) {
  const double value = ParseNumber(flag, text);
  if (value != std::floor(value) || value < lo || value > hi)
    throw std::runtime_error(flag + " = " + text + ", must be an integer in [" +
                             std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return static_cast<int>(value);
}

// Returns nullopt after printing the usage for --help.
std::optional<Options> ParseOptions(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "-h" || flag == "--help") {
      std::fputs(kUsage, stdout);
      return std::nullopt;
    }
    if (flag == "--realtime") {
      o.realtime = true;
      continue;
    }
    if (i + 1 >= argc) throw std::runtime_error(flag + " needs a value (see --help)");
    const char* value = argv[++i];
    if (flag == "--barrier") {
      o.barrier = value;
    } else if (flag == "--policy") {
      o.policy = value;
    } else if (flag == "--duration") {
      o.duration_s = ParseNumber(flag, value);
      if (!(o.duration_s > 0 && o.duration_s <= 3600))
        throw std::runtime_error("--duration = " + std::string(value) + ", must be in (0, 3600]");
    } else if (flag == "--rate") {
      o.rate_hz = ParseInt(flag, value, 1, 100000);
    } else if (flag == "--samples") {
      o.samples = ParseInt(flag, value, 1, 1 << 20);
    } else if (flag == "--max-iterations") {
      o.max_iterations = ParseInt(flag, value, 1, 1000000);
    } else if (flag == "--time-budget-us") {
      o.time_budget_us = ParseNumber(flag, value);
    } else if (flag == "--priority") {
      o.priority = ParseInt(flag, value, 1, 99);
    } else if (flag == "--seed") {
      o.seed = static_cast<std::uint64_t>(ParseInt(flag, value, 0, 1 << 30));
    } else {
      throw std::runtime_error("unknown option '" + flag + "' (see --help)");
    }
  }
  if (o.barrier.empty()) throw std::runtime_error("--barrier FILE is required (see --help)");
  return o;
}

// ------------------------------------------------------------------------------------------
// The plant: a 2-D double integrator, state (x, y, vx, vy), action (ax, ay) clipped to
// [-kAccelBound, kAccelBound] and held for dt (exact zero-order hold). The same model is the
// shield's one-step look-ahead T(s, a), so the shield checks exactly the next state.

constexpr int kStateDim = 4;
constexpr int kActionDim = 2;
constexpr float kAccelBound = 1.0f;
constexpr float kObstacleX = 5.0f, kObstacleY = 5.0f, kRadius = 2.0f;  // `secure cbf train`
constexpr float kStartX = 1.0f, kStartY = 1.0f, kGoalX = 9.0f, kGoalY = 9.0f;

inline void StepPlant(const float* s, float ax, float ay, float dt, float* out) {
  ax = std::clamp(ax, -kAccelBound, kAccelBound);
  ay = std::clamp(ay, -kAccelBound, kAccelBound);
  out[0] = s[0] + s[2] * dt + 0.5f * ax * dt * dt;
  out[1] = s[1] + s[3] * dt + 0.5f * ay * dt * dt;
  out[2] = s[2] + ax * dt;
  out[3] = s[3] + ay * dt;
}

class DoubleIntegrator final : public secure::domains::DynamicsModel {
 public:
  explicit DoubleIntegrator(float dt) : dt_(dt) {}
  int state_dim() const override { return kStateDim; }
  int action_dim() const override { return kActionDim; }
  std::string Describe() const override { return "double integrator (realtime_loop example)"; }

 protected:
  // Column by column, no temporaries: allocation-free, as the shield requires.
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override {
    const float s[kStateDim] = {state[0], state[1], state[2], state[3]};
    float out[kStateDim];
    for (Eigen::Index j = 0; j < actions.cols(); ++j) {
      StepPlant(s, actions(0, j), actions(1, j), dt_, out);
      for (int r = 0; r < kStateDim; ++r) next_states(r, j) = out[r];
    }
  }

 private:
  float dt_;
};

// The built-in policy when no --policy is given: a saturated PD controller toward the goal,
// straight through the obstacle (the shield has to steer around it), with noise sigma.
void GoalSeekingMean(const float* s, float* mu) {
  mu[0] = std::clamp(0.5f * (kGoalX - s[0]) - 1.2f * s[2], -kAccelBound, kAccelBound);
  mu[1] = std::clamp(0.5f * (kGoalY - s[1]) - 1.2f * s[3], -kAccelBound, kAccelBound);
}
constexpr float kBuiltinSigma = 0.3f;

// ------------------------------------------------------------------------------------------
// Time.

constexpr long kNsPerS = 1000000000L;

inline long Nanoseconds(const timespec& t) { return t.tv_sec * kNsPerS + t.tv_nsec; }
inline timespec FromNanoseconds(long ns) { return timespec{ns / kNsPerS, ns % kNsPerS}; }
inline long NowNs() {
  timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return Nanoseconds(t);
}

// Touches `bytes` of this thread's stack, so that the pages Eigen's stack buffers use are mapped
// (and locked, after mlockall(MCL_FUTURE)) before the loop rather than faulted in during it.
__attribute__((noinline)) void PrefaultStack(std::size_t bytes) {
  constexpr std::size_t kChunk = 64 * 1024;
  [[maybe_unused]] volatile unsigned char buffer[kChunk];
  for (std::size_t i = 0; i < kChunk; i += 4096) buffer[i] = 0;
  if (bytes > kChunk) PrefaultStack(bytes - kChunk);
  buffer[0] = 1;  // keeps this frame alive across the call (no tail call)
}

// ------------------------------------------------------------------------------------------
// The loop.

struct Report {
  long cycles = 0;
  long misses = 0;                 // cycles whose work ended after the next cycle's deadline
  long skipped = 0;                // whole periods dropped after a miss (the loop re-anchors)
  std::vector<long> decision_ns;   // policy + shield + plant step, per cycle
  std::vector<long> wakeup_ns;     // wake-up time minus deadline, per cycle
  std::array<long, 4> statuses{};  // by shield::Status
  long interventions = 0;
  long rounds = 0;  // sampling rounds, summed over the decisions
  int max_rounds = 0;
  long episodes = 1;
  long collision_cycles = 0;  // cycles with the plant inside the obstacle
  double min_h = INFINITY;
  std::string scheduler;
  std::string error;  // set if the loop thread failed
};

struct LoopContext {
  const Options* options;
  secure::shield::Shield* shield;
  secure::policy::PolicyEvaluator* policy;  // null: the built-in policy
  Report* report;
};

void SetUpRealtime(const Options& o, Report& r) {
  // Wake up at the deadline, not up to 50 us later (the default timer slack of SCHED_OTHER
  // threads; SCHED_FIFO threads have none).
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  r.scheduler = "SCHED_OTHER (pass --realtime for SCHED_FIFO)";
  if (!o.realtime) return;
  sched_param param{};
  param.sched_priority = o.priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  if (rc == 0) {
    r.scheduler = "SCHED_FIFO priority " + std::to_string(o.priority);
  } else {
    r.scheduler = "SCHED_OTHER";
    std::fprintf(stderr,
                 "realtime_loop: note: SCHED_FIFO not permitted (%s): running with the default "
                 "scheduler (needs CAP_SYS_NICE or an rtprio limit, e.g. `ulimit -r 99`)\n",
                 std::strerror(rc));
  }
}

void RunLoop(const LoopContext& c) {
  const Options& o = *c.options;
  Report& r = *c.report;
  secure::shield::Shield& shield = *c.shield;
  SetUpRealtime(o, r);
  PrefaultStack(2u << 20);

  const long period_ns = kNsPerS / o.rate_hz;
  const float dt = static_cast<float>(period_ns) / kNsPerS;
  const long capacity = static_cast<long>(std::ceil(o.duration_s * o.rate_hz)) + 1;
  r.decision_ns.assign(capacity, 0);
  r.wakeup_ns.assign(capacity, 0);

  Eigen::VectorXf state(kStateDim), mu(kActionDim), sigma(kActionDim), brake(kActionDim);
  state << kStartX, kStartY, 0.0f, 0.0f;
  sigma.setConstant(kBuiltinSigma);
  if (c.policy) sigma = c.policy->sigma();
  float next[kStateDim];

  // One control step: policy, shield, plant. Returns nothing; counts into r when `record`.
  auto control_step = [&](bool record) {
    if (c.policy) {
      c.policy->Mean(state, mu);
    } else {
      GoalSeekingMean(state.data(), mu.data());
    }
    brake << std::clamp(-state[2] / dt, -kAccelBound, kAccelBound),
        std::clamp(-state[3] / dt, -kAccelBound, kAccelBound);
    shield.SetBackupAction(brake);  // braking competes on g when no safe action is found
    const secure::shield::Decision& d = shield.Decide(state, mu, sigma);
    StepPlant(state.data(), d.action[0], d.action[1], dt, next);
    for (int i = 0; i < kStateDim; ++i) state[i] = next[i];
    // A new episode at the goal or outside the box the barrier was trained in.
    const bool at_goal = std::hypot(state[0] - kGoalX, state[1] - kGoalY) < 0.5f;
    const bool outside = !(state[0] >= 0 && state[0] < 10 && state[1] >= 0 && state[1] < 10 &&
                           std::abs(state[2]) < 1.5f && std::abs(state[3]) < 1.5f);
    if (at_goal || outside) state << kStartX, kStartY, 0.0f, 0.0f;
    if (!record) return;
    r.episodes += (at_goal || outside) ? 1 : 0;
    ++r.statuses[static_cast<int>(d.status)];
    r.interventions += d.intervened ? 1 : 0;
    r.rounds += d.iterations;
    r.max_rounds = std::max(r.max_rounds, d.iterations);
    if (std::isfinite(d.h)) r.min_h = std::min(r.min_h, d.h);
    if (std::hypot(state[0] - kObstacleX, state[1] - kObstacleY) < kRadius) ++r.collision_cycles;
  };

  // Warm-up (not recorded): first-touch of every buffer and code path, then a fresh start.
  for (int i = 0; i < 200; ++i) control_step(false);
  state << kStartX, kStartY, 0.0f, 0.0f;
  shield.Seed(o.seed);

  long deadline = NowNs() + period_ns;
  const long end = deadline + static_cast<long>(o.duration_s * kNsPerS);
  while (deadline < end && r.cycles < capacity) {
    const timespec wake = FromNanoseconds(deadline);
    int rc;
    while ((rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake, nullptr)) == EINTR) {
    }
    if (rc != 0) throw std::runtime_error(std::string("clock_nanosleep: ") + std::strerror(rc));
    const long start = NowNs();
    control_step(true);
    const long done = NowNs();
    r.wakeup_ns[r.cycles] = start - deadline;
    r.decision_ns[r.cycles] = done - start;
    ++r.cycles;
    // The work of this cycle must end before the next deadline; if it did not, count a miss and
    // re-anchor on the next deadline still ahead (no burst of late cycles to catch up).
    deadline += period_ns;
    if (done > deadline) {
      ++r.misses;
      while (deadline <= done) {
        deadline += period_ns;
        ++r.skipped;
      }
    }
  }
}

void* LoopThread(void* arg) {
  const auto* c = static_cast<const LoopContext*>(arg);
  try {
    RunLoop(*c);
  } catch (const std::exception& e) {
    c->report->error = e.what();
  }
  return nullptr;
}

// ------------------------------------------------------------------------------------------
// Report.

// Nearest-rank percentile of sorted values, in microseconds.
double Percentile(const std::vector<long>& sorted, double p) {
  if (sorted.empty()) return NAN;
  const std::size_t rank =
      std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(p * sorted.size())));
  return sorted[std::min(rank, sorted.size()) - 1] / 1000.0;
}

void PrintPercentiles(const char* what, std::vector<long> values) {
  std::sort(values.begin(), values.end());
  std::printf("%s (us): p50 %.1f  p90 %.1f  p99 %.1f  max %.1f\n", what, Percentile(values, 0.5),
              Percentile(values, 0.9), Percentile(values, 0.99),
              values.empty() ? NAN : values.back() / 1000.0);
}

int Run(const Options& o) {
  // The barrier: the immutable model, and this loop's evaluator (it owns scratch memory).
  const secure::cbf::BarrierNet net = secure::cbf::BarrierNet::Load(o.barrier);
  net.CheckFeatures({"x", "y", "vx", "vy"}, "the realtime_loop plant (x, y, vx, vy)", o.barrier);
  std::unique_ptr<secure::cbf::Barrier> barrier = net.MakeEvaluator();

  std::optional<secure::policy::GaussianPolicy> policy;
  std::optional<secure::policy::PolicyEvaluator> policy_eval;
  if (!o.policy.empty()) {
    policy = secure::policy::GaussianPolicy::Load(o.policy);
    if (policy->observation_dim() != kStateDim || policy->action_dim() != kActionDim)
      throw std::runtime_error(o.policy + ": the policy maps " +
                               std::to_string(policy->observation_dim()) + " observations to " +
                               std::to_string(policy->action_dim()) +
                               " actions; the plant has 4 (x, y, vx, vy) and 2 (ax, ay)");
    policy_eval.emplace(*policy);
  }

  const long period_ns = kNsPerS / o.rate_hz;
  const DoubleIntegrator dynamics(static_cast<float>(period_ns) / kNsPerS);
  secure::shield::ShieldOptions so;
  so.num_samples = o.samples;
  so.max_iterations = o.max_iterations;
  so.time_budget_us = o.time_budget_us;
  so.dt = static_cast<double>(period_ns) / kNsPerS;  // the control period
  so.seed = o.seed;
  so.Validate();
  secure::shield::Shield shield(so, *barrier, dynamics);

  Report report;
  if (o.realtime) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
      std::fprintf(stderr,
                   "realtime_loop: note: mlockall not permitted (%s): memory is not locked "
                   "(needs CAP_IPC_LOCK or a memlock limit, e.g. `ulimit -l unlimited`)\n",
                   std::strerror(errno));
  }

  // The loop runs in its own thread with an explicit stack: Eigen may put up to
  // EIGEN_STACK_ALLOCATION_LIMIT (1 MiB) of GEMM buffers on it.
  LoopContext context{&o, &shield, policy_eval ? &*policy_eval : nullptr, &report};
  pthread_attr_t attr;
  pthread_attr_init(&attr);
  pthread_attr_setstacksize(&attr, 8u << 20);
  pthread_t thread;
  const int rc = pthread_create(&thread, &attr, LoopThread, &context);
  pthread_attr_destroy(&attr);
  if (rc != 0) throw std::runtime_error(std::string("pthread_create: ") + std::strerror(rc));
  pthread_join(thread, nullptr);
  if (!report.error.empty()) throw std::runtime_error(report.error);

  const Report& r = report;
  std::printf("realtime_loop: %s; policy: %s; M = %d, K = %d, time budget %s\n",
              barrier->Describe().c_str(),
              o.policy.empty() ? "built-in goal-seeking (sigma 0.3)" : o.policy.c_str(), o.samples,
              o.max_iterations,
              o.time_budget_us > 0 ? (std::to_string(o.time_budget_us) + " us").c_str() : "none");
  std::printf("rate %d Hz for %.3g s, %s\n", o.rate_hz, o.duration_s, r.scheduler.c_str());
  std::printf("cycles %ld, deadline misses %ld (%.3f %%), skipped periods %ld\n", r.cycles,
              r.misses, r.cycles ? 100.0 * r.misses / r.cycles : 0.0, r.skipped);
  std::vector<long> decision(r.decision_ns.begin(), r.decision_ns.begin() + r.cycles);
  std::vector<long> wakeup(r.wakeup_ns.begin(), r.wakeup_ns.begin() + r.cycles);
  PrintPercentiles("decision latency", decision);
  PrintPercentiles("wake-up lateness", wakeup);
  using secure::shield::Status;
  std::printf(
      "decisions: safe %ld, safe_after_resampling %ld, no_safe_action %ld, "
      "invalid_input %ld; interventions %ld; rounds mean %.2f, max %d\n",
      r.statuses[static_cast<int>(Status::kSafe)],
      r.statuses[static_cast<int>(Status::kSafeAfterResampling)],
      r.statuses[static_cast<int>(Status::kNoSafeAction)],
      r.statuses[static_cast<int>(Status::kInvalidInput)], r.interventions,
      r.cycles ? static_cast<double>(r.rounds) / r.cycles : 0.0, r.max_rounds);
  std::printf("plant: episodes %ld, cycles inside the obstacle %ld, min h(s) %.3g\n", r.episodes,
              r.collision_cycles, r.min_h);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::optional<Options> options = ParseOptions(argc, argv);
    if (!options) return 0;
    return Run(*options);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "realtime_loop: error: %s\n", e.what());
    return 1;
  } catch (...) {
    std::fprintf(stderr, "realtime_loop: error: unknown exception\n");
    return 1;
  }
}
