#include "domains/panda_push/data.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>

#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"
#include "secure/domains/demonstrations.h"

namespace secure::domains::panda_push {
namespace {

bool Finite(double x) { return std::isfinite(x); }

// Along x, from the end-effector to the block's centre when the pusher touches the block: the
// pusher's front is 0.04 ahead of the end-effector, the block's back 0.04 behind its centre.
constexpr double kTouchingDistance = 0.08;

double Draw(Rng& rng, const Range& r) { return r.lo + (r.hi - r.lo) * rng.Uniform(); }

void CheckRange(const Range& r, const char* owner, const char* field, double min, double max) {
  SECURE_CHECK_FIELD(Finite(r.lo) && Finite(r.hi) && r.lo >= min && r.hi <= max && r.lo <= r.hi,
                     owner, field, "[" << r.lo << ", " << r.hi << "]",
                     "an interval lo <= hi within [" << min << ", " << max << "]");
}

// A range's field table: {lo, hi}.
YamlFields RangeField(Range* r) { return YamlFields().Field("lo", &r->lo).Field("hi", &r->hi); }

// Columns `cols` of `states`, in order.
data::StateSet Subset(const std::string& source, const Eigen::MatrixXf& states,
                      const std::vector<long>& cols) {
  data::StateSet s;
  s.source = source;
  s.features = ObservationFeatures();
  s.states = data::SelectColumns(states, cols);
  return s;
}

// `count` of `n` indices drawn without replacement. @throws secure::Error naming `what` if there
// are fewer than `count`.
std::vector<long> DrawIndices(long n, long count, Rng& rng, const std::string& what) {
  SECURE_CHECK(count <= n, what << ": " << count << " states asked for, only " << n
                                << " available (fewer states, or more demonstrations / copies)");
  std::vector<long> idx(static_cast<size_t>(n));
  std::iota(idx.begin(), idx.end(), 0L);
  for (long i = n - 1; i > 0; --i)
    std::swap(idx[i], idx[rng.UniformIndex(static_cast<std::uint64_t>(i + 1))]);
  if (count < n) idx.resize(static_cast<size_t>(count));
  return idx;
}

// The demonstration states with `copies` noisy copies each (the released noise).
Eigen::MatrixXf WithNoisyCopies(const Eigen::MatrixXf& states, int copies, Rng& rng) {
  Eigen::MatrixXf out(states.rows(), states.cols() * (1 + copies));
  out.leftCols(states.cols()) = states;
  for (int c = 0; c < copies; ++c) {
    for (long i = 0; i < states.cols(); ++i) {
      auto s = out.col(states.cols() * (1 + c) + i);
      s = states.col(i);
      s[kEePos] += static_cast<float>(rng.Uniform(-0.01, 0.0));
      s[kEePos + 1] += static_cast<float>(rng.Uniform(-0.005, 0.005));
      s[kEePos + 2] += static_cast<float>(rng.Uniform(-0.001, 0.001));
      for (int k : {kEeVel, kEeVel + 1, kEeVel + 2, kBlockVel, kBlockVel + 1, kBlockVel + 2})
        s[k] += static_cast<float>(rng.Uniform(-0.001, 0.001));
    }
  }
  return out;
}

// What continuing a state's motion does (CheckLabels' continuation, data.h).
enum class Continuation { kUnreachable, kToppled, kStayedUp };

Continuation Continue(PandaPushSim& sim, const PandaPushOptions& task,
                      const Eigen::Ref<const Eigen::VectorXf>& s, const LabelCheckOptions& options,
                      Eigen::Ref<Eigen::VectorXf> o) {
  if (sim.SetObservation(s) > 0.01) return Continuation::kUnreachable;
  const int push_steps =
      static_cast<int>(std::lround(options.push_seconds / task.tracking.control_period));
  const int hold_steps =
      static_cast<int>(std::lround(options.hold_seconds / task.tracking.control_period));
  const int stop_steps = std::max(
      1, static_cast<int>(std::lround(options.stop_seconds / task.tracking.control_period)));
  Eigen::Vector3f a;
  for (int k = 0; k < 3; ++k)
    a[k] = std::clamp(static_cast<float>(s[kEeVel + k] / options.velocity_gain), -1.0f, 1.0f);
  sim.Observe(o);
  const Eigen::Vector3f start = o.segment<3>(kEePos);
  int stop_begin = push_steps;  // the step the ramp down starts
  for (int t = 0; t < stop_begin + stop_steps + hold_steps; ++t) {
    const float scale =
        t < stop_begin ? 1.0f
                       : std::max(0.0f, 1.0f - static_cast<float>(t - stop_begin + 1) / stop_steps);
    sim.Step(scale * a);
    sim.Observe(o);
    if (t < stop_begin && (o.segment<3>(kEePos) - start).norm() >= options.push_distance)
      stop_begin = t + 1;
    if (sim.Toppled()) return Continuation::kToppled;
  }
  return Continuation::kStayedUp;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options

void PandaDemonstrationOptions::Validate() const {
  const char* o = "PandaDemonstrationOptions";
  SECURE_CHECK_FIELD(episodes >= 1 && episodes <= 10000, o, "episodes", episodes, "in [1, 10000]");
  SECURE_CHECK_FIELD(max_attempts >= episodes, o, "max_attempts", max_attempts,
                     ">= episodes (" << episodes << ")");
  CheckRange(push_height, o, "push_height", 0.0, 0.4);
  CheckRange(descend_speed, o, "descend_speed", 0.0, 1.0);
  CheckRange(approach_speed, o, "approach_speed", 0.0, 1.0);
  CheckRange(push_speed, o, "push_speed", 0.0, 1.0);
  SECURE_CHECK_FIELD(push_speed.lo > 0, o, "push_speed.lo", push_speed.lo, "> 0");
  SECURE_CHECK_FIELD(descend_speed.lo > 0, o, "descend_speed.lo", descend_speed.lo, "> 0");
  SECURE_CHECK_FIELD(approach_speed.lo > 0, o, "approach_speed.lo", approach_speed.lo, "> 0");
  SECURE_CHECK_FIELD(Finite(approach_gap) && approach_gap >= 0 && approach_gap <= 0.3, o,
                     "approach_gap", approach_gap, "in [0, 0.3] m");
  SECURE_CHECK_FIELD(Finite(action_noise) && action_noise >= 0 && action_noise <= 0.5, o,
                     "action_noise", action_noise, "in [0, 0.5]");
  SECURE_CHECK_FIELD(Finite(pause_rate) && pause_rate >= 0 && pause_rate <= 0.5, o, "pause_rate",
                     pause_rate, "in [0, 0.5]");
  CheckRange(pause_steps, o, "pause_steps", 1.0, 50.0);
  SECURE_CHECK_FIELD(Finite(dart_noise) && dart_noise >= 0 && dart_noise <= 1, o, "dart_noise",
                     dart_noise, "in [0, 1]");
  SECURE_CHECK_FIELD(Finite(dart_brake_rate) && dart_brake_rate >= 0 && dart_brake_rate <= 0.5, o,
                     "dart_brake_rate", dart_brake_rate, "in [0, 0.5]");
  CheckRange(dart_brake_steps, o, "dart_brake_steps", 1.0, 50.0);
}

YamlFields PandaDemonstrationOptions::Fields() {
  return YamlFields()
      .Field("episodes", &episodes)
      .Field("max_attempts", &max_attempts)
      .Section("push_height", RangeField(&push_height))
      .Section("descend_speed", RangeField(&descend_speed))
      .Section("approach_speed", RangeField(&approach_speed))
      .Section("push_speed", RangeField(&push_speed))
      .Field("approach_gap", &approach_gap)
      .Field("action_noise", &action_noise)
      .Field("pause_rate", &pause_rate)
      .Section("pause_steps", RangeField(&pause_steps))
      .Field("dart_noise", &dart_noise)
      .Field("dart_brake_rate", &dart_brake_rate)
      .Section("dart_brake_steps", RangeField(&dart_brake_steps));
}

SECURE_YAML_JSON_FROM_FIELDS(PandaDemonstrationOptions)

void PandaSafeOptions::Validate() const {
  SECURE_CHECK_FIELD(count >= 1 && count <= 100000000, "PandaSafeOptions", "count", count,
                     "in [1, 1e8]");
  SECURE_CHECK_FIELD(noisy_copies >= 0 && noisy_copies <= 1000, "PandaSafeOptions", "noisy_copies",
                     noisy_copies, "in [0, 1000]");
  SECURE_CHECK_FIELD(hover_copies >= 0 && hover_copies <= 1000, "PandaSafeOptions", "hover_copies",
                     hover_copies, "in [0, 1000]");
  CheckRange(hover_gap, "PandaSafeOptions", "hover_gap", 0.0, 1.0);
  CheckRange(hover_z, "PandaSafeOptions", "hover_z", 0.0, 1.0);
  SECURE_CHECK_FIELD(Finite(hover_speed) && hover_speed >= 0 && hover_speed <= 1,
                     "PandaSafeOptions", "hover_speed", hover_speed, "in [0, 1] m/s");
}

YamlFields PandaSafeOptions::Fields() {
  return YamlFields()
      .Field("count", &count)
      .Field("noisy_copies", &noisy_copies)
      .Field("hover_copies", &hover_copies)
      .Section("hover_gap", RangeField(&hover_gap))
      .Section("hover_z", RangeField(&hover_z))
      .Field("hover_speed", &hover_speed);
}

SECURE_YAML_JSON_FROM_FIELDS(PandaSafeOptions)

void PandaNearDangerousOptions::Validate() const {
  const char* o = "PandaNearDangerousOptions";
  SECURE_CHECK_FIELD(count >= 1 && count <= 100000000, o, "count", count, "in [1, 1e8]");
  SECURE_CHECK_FIELD(copies >= 1 && copies <= 1000, o, "copies", copies, "in [1, 1000]");
  SECURE_CHECK_FIELD(Finite(p_upper) && p_upper >= 0 && p_upper <= 1, o, "p_upper", p_upper,
                     "in [0, 1]");
  SECURE_CHECK_FIELD(Finite(p_fast) && p_fast >= 0 && p_upper + p_fast <= 1, o, "p_fast", p_fast,
                     ">= 0 with p_upper + p_fast <= 1");
  SECURE_CHECK_FIELD(Finite(fast_x_share) && fast_x_share >= 0 && fast_x_share <= 1, o,
                     "fast_x_share", fast_x_share, "in [0, 1]");
  CheckRange(upper_z, o, "upper_z", 0.0, 0.4);
  SECURE_CHECK_FIELD(Finite(low_z_max) && low_z_max >= 0 && low_z_max <= 0.4, o, "low_z_max",
                     low_z_max, "in [0, 0.4] m");
  CheckRange(fast_vx, o, "fast_vx", 0.0, 10.0);
  CheckRange(fast_vz, o, "fast_vz", 0.0, 10.0);
  SECURE_CHECK_FIELD(Finite(back_off) && back_off >= 0 && back_off <= 0.1, o, "back_off", back_off,
                     "in [0, 0.1] m");
  CheckRange(precursor_gap, o, "precursor_gap", 0.0, 0.3);
  SECURE_CHECK_FIELD(max_candidates >= 1 && max_candidates <= 100000000, o, "max_candidates",
                     max_candidates, "in [1, 1e8]");
}

YamlFields PandaNearDangerousOptions::Fields() {
  return YamlFields()
      .Field("count", &count)
      .Field("copies", &copies)
      .Field("p_upper", &p_upper)
      .Field("p_fast", &p_fast)
      .Field("fast_x_share", &fast_x_share)
      .Section("upper_z", RangeField(&upper_z))
      .Field("low_z_max", &low_z_max)
      .Section("fast_vx", RangeField(&fast_vx))
      .Section("fast_vz", RangeField(&fast_vz))
      .Field("back_off", &back_off)
      .Enum("generator", &generator, kNearDangerousGeneratorNames)
      .Section("precursor_gap", RangeField(&precursor_gap))
      .Field("max_candidates", &max_candidates);
}

SECURE_YAML_JSON_FROM_FIELDS(PandaNearDangerousOptions)

namespace {
constexpr EnumTable<NearDangerousScenario, 4> kScenarioNames{{
    {NearDangerousScenario::kUpper, "upper"},
    {NearDangerousScenario::kFastX, "fast-x"},
    {NearDangerousScenario::kFastZ, "fast-z"},
    {NearDangerousScenario::kBoth, "both"},
}};
}  // namespace

const char* ScenarioName(NearDangerousScenario s) { return NameOf(kScenarioNames, s); }

// ---------------------------------------------------------------------------------------------
// Demonstrations

PandaDemonstrations GeneratePandaDemonstrations(const PandaPushOptions& task,
                                                const PandaDemonstrationOptions& options) {
  task.Validate();
  options.Validate();
  PandaPushEnv env(task, PandaPushShieldModelOptions{});
  Rng rng(options.seed);
  PandaDemonstrations out;
  DemonstrationCollector collector(
      "scripted panda-push demonstrations (seed " + std::to_string(options.seed) + ")",
      ObservationFeatures(), ActionFeatures());
  Eigen::VectorXf o(kObservationDim);
  Eigen::VectorXf a(kActionDim), applied(kActionDim);  // recorded, applied
  int kept = 0;
  for (int attempt = 0; attempt < options.max_attempts && kept < options.episodes; ++attempt) {
    Rng episode_rng(rng.NextU64());
    const double h = Draw(episode_rng, options.push_height);
    const double descend = Draw(episode_rng, options.descend_speed);
    const double approach = Draw(episode_rng, options.approach_speed);
    const double push = Draw(episode_rng, options.push_speed);
    env.Reset(episode_rng, o);
    // The pauses' own stream, drawn only when there are pauses (pause_rate 0 keeps the draws).
    Rng pause_rng(options.pause_rate > 0 ? episode_rng.NextU64() : 0);
    int paused = 0;  // steps of the current pause left
    // The DART perturbations' own stream, drawn only when there are any.
    const bool dart = options.dart_noise > 0 || options.dart_brake_rate > 0;
    Rng dart_rng(dart ? episode_rng.NextU64() : 0);
    int braking = 0;  // steps of the current brake left
    long push_begin = -1;
    bool descended = false;
    const RecordedEpisode episode = RecordEpisode(
        env, collector, task.max_steps, /*stop_at_goal=*/true, o, applied, a,
        [&](const Eigen::VectorXf& obs, Eigen::VectorXf& act, Eigen::VectorXf& recorded) {
          recorded.setZero();
          const double gap = obs[kBlockPos] - obs[kEePos] - kTouchingDistance;
          if (!descended && obs[kEePos + 2] > h + 0.01) {
            recorded[2] = static_cast<float>(-descend);
          } else {
            descended = true;
            recorded[2] =
                static_cast<float>(std::clamp(0.5 * (h - obs[kEePos + 2]) / 0.05, -1.0, 1.0));
            recorded[1] = static_cast<float>(
                std::clamp(-5.0 * (obs[kEePos + 1] - obs[kBlockPos + 1]), -0.2, 0.2));
            // Fast while far, slowing down in proportion to the gap over the last approach_gap
            // metres (a keyboard user easing off), the push speed once in contact.
            const double ease = std::clamp(gap / std::max(options.approach_gap, 1e-9), 0.0, 1.0);
            recorded[0] = static_cast<float>(push + (approach - push) * ease);
            if (gap <= 0.005 && push_begin < 0) push_begin = collector.episode_steps();
            if (options.pause_rate > 0 && paused == 0 && pause_rng.Uniform() < options.pause_rate)
              paused = static_cast<int>(std::floor(Draw(pause_rng, options.pause_steps) + 0.5));
            if (paused > 0) {
              recorded[0] = 0.0f;
              --paused;
            }
          }
          for (int k = 0; k < kActionDim; ++k)
            recorded[k] = std::clamp(
                recorded[k] + static_cast<float>(options.action_noise * episode_rng.Normal()),
                -1.0f, 1.0f);
          // The applied action: the recorded one, perturbed under DART.
          act = recorded;
          if (dart && descended) {
            for (int k = 0; k < kActionDim; ++k)
              act[k] += static_cast<float>(options.dart_noise * dart_rng.Normal());
            if (push_begin >= 0 && options.dart_brake_rate > 0 && braking == 0 &&
                dart_rng.Uniform() < options.dart_brake_rate)
              braking =
                  static_cast<int>(std::floor(Draw(dart_rng, options.dart_brake_steps) + 0.5));
            if (braking > 0) {
              act[0] = 0.0f;
              --braking;
            }
            act = act.cwiseMax(-1.0f).cwiseMin(1.0f);
          }
        },
        [](const StepOutcome&) {});
    if (!KeepOrCountDiscarded(episode.collided, episode.reached_at > 0 && push_begin >= 0,
                              &out.discarded_toppled, &out.discarded_failed))
      continue;
    out.push_begin.push_back(collector.KeepEpisode() + push_begin);
    ++kept;
  }
  SECURE_CHECK(kept == options.episodes,
               "panda-push demonstrations: only "
                   << kept << " of " << options.episodes << " succeeded in " << options.max_attempts
                   << " attempts (" << out.discarded_toppled << " toppled the block, "
                   << out.discarded_failed << " missed the target)");
  out.trajectories = collector.Finish();
  return out;
}

// ---------------------------------------------------------------------------------------------
// Safe and near-dangerous states

data::StateSet PandaSafeStates(const PandaDemonstrations& demos, const PandaSafeOptions& options,
                               Rng& rng) {
  options.Validate();
  const Eigen::MatrixXf& demo = demos.trajectories.states;
  const Eigen::MatrixXf noisy = WithNoisyCopies(demo, options.noisy_copies, rng);
  Eigen::MatrixXf all(noisy.rows(), noisy.cols() + demo.cols() * options.hover_copies);
  all.leftCols(noisy.cols()) = noisy;
  for (int c = 0; c < options.hover_copies; ++c) {
    for (long i = 0; i < demo.cols(); ++i) {
      auto s = all.col(noisy.cols() + demo.cols() * c + i);
      s = demo.col(i);
      const double gap = Draw(rng, options.hover_gap);
      s[kEePos] = static_cast<float>(s[kBlockPos] - kTouchingDistance - gap);
      s[kEePos + 1] += static_cast<float>(rng.Uniform(-0.05, 0.05));
      s[kEePos + 2] = static_cast<float>(Draw(rng, options.hover_z));
      for (int k = 0; k < 3; ++k)
        s[kEeVel + k] = static_cast<float>(rng.Uniform(-options.hover_speed, options.hover_speed));
    }
  }
  return Subset("panda-push safe states (demonstrations, " + std::to_string(options.noisy_copies) +
                    " noisy " +
                    (options.hover_copies > 0
                         ? "and " + std::to_string(options.hover_copies) + " hovering copies each)"
                         : std::string("copies each)")),
                all, DrawIndices(all.cols(), options.count, rng, "panda-push safe states (count)"));
}

data::StateSet PandaNearDangerousStates(const PandaPushOptions& task,
                                        const PandaDemonstrations& demos,
                                        const PandaNearDangerousOptions& options,
                                        const LabelCheckOptions& continuation, Rng& rng,
                                        std::vector<NearDangerousScenario>* scenarios) {
  options.Validate();
  const data::TrajectorySet& t = demos.trajectories;
  SECURE_CHECK(static_cast<long>(demos.push_begin.size()) == t.num_episodes(),
               "panda-push near-dangerous states: " << demos.push_begin.size()
                                                    << " push starts for " << t.num_episodes()
                                                    << " demonstrations");
  // One copy's scenario (u ~ U(0, 1) drawn per copy), then its values drawn per state into s.
  auto apply_scenario = [&](double u, Eigen::VectorXf& s) {
    const bool upper = u < options.p_upper;
    const bool fast = !upper && u < options.p_upper + options.p_fast;
    s[kEePos] -= static_cast<float>(options.back_off);
    if (upper) {
      s[kEePos + 2] = static_cast<float>(Draw(rng, options.upper_z));
      return NearDangerousScenario::kUpper;
    }
    if (fast) {
      s[kEePos + 2] = static_cast<float>(options.low_z_max * rng.Uniform());
      if (rng.Uniform() < options.fast_x_share) {
        s[kEeVel] = static_cast<float>(Draw(rng, options.fast_vx));
        return NearDangerousScenario::kFastX;
      }
      s[kEeVel + 2] = static_cast<float>(-Draw(rng, options.fast_vz));
      return NearDangerousScenario::kFastZ;
    }
    s[kEePos + 2] = static_cast<float>(Draw(rng, options.upper_z));
    s[kEeVel] = static_cast<float>(Draw(rng, options.fast_vx));
    return NearDangerousScenario::kBoth;
  };
  std::vector<long> push_states;
  for (long e = 0; e < t.num_episodes(); ++e)
    for (long i = demos.push_begin[e]; i < t.episode_begin[e + 1]; ++i) push_states.push_back(i);
  SECURE_CHECK(!push_states.empty(),
               "panda-push near-dangerous states: the demonstrations have no push");

  if (options.generator == PandaNearDangerousOptions::Generator::kPrecursor) {
    PandaPushSim sim(task);
    Eigen::VectorXf o(kObservationDim);
    Eigen::MatrixXf kept(kObservationDim, options.count);
    std::vector<NearDangerousScenario> kinds;
    long n = 0, tried = 0;
    for (; tried < options.max_candidates && n < options.count; ++tried) {
      const long i = push_states[rng.UniformIndex(static_cast<std::uint64_t>(push_states.size()))];
      Eigen::VectorXf s = t.states.col(i);
      const NearDangerousScenario kind = apply_scenario(rng.Uniform(), s);
      s[kEePos] -= static_cast<float>(Draw(rng, options.precursor_gap));
      if (Continue(sim, task, s, continuation, o) != Continuation::kToppled) continue;
      kept.col(n++) = s;
      kinds.push_back(kind);
    }
    SECURE_CHECK(n == options.count,
                 "panda-push near-dangerous states (generator: precursor): only "
                     << n << " of " << tried << " candidates topple when continued, "
                     << options.count << " asked for (raise max_candidates or lower count)");
    if (scenarios != nullptr) *scenarios = kinds;
    data::StateSet out;
    out.source = "panda-push near-dangerous precursor states (" + std::to_string(n) + " of " +
                 std::to_string(tried) + " candidates topple when continued)";
    out.features = ObservationFeatures();
    out.states = std::move(kept);
    return out;
  }

  std::vector<Eigen::VectorXf> rows;
  std::vector<NearDangerousScenario> kinds;
  for (long e = 0; e < t.num_episodes(); ++e) {
    for (int c = 0; c < options.copies; ++c) {
      const double u = rng.Uniform();
      for (long i = demos.push_begin[e]; i < t.episode_begin[e + 1]; ++i) {
        Eigen::VectorXf s = t.states.col(i);
        kinds.push_back(apply_scenario(u, s));
        rows.push_back(s);
      }
    }
  }
  Eigen::MatrixXf all(kObservationDim, static_cast<long>(rows.size()));
  for (long i = 0; i < all.cols(); ++i) all.col(i) = rows[i];
  const std::vector<long> idx =
      DrawIndices(all.cols(), options.count, rng, "panda-push near-dangerous states (count)");
  if (scenarios != nullptr) {
    scenarios->clear();
    for (long i : idx) scenarios->push_back(kinds[i]);
  }
  return Subset("panda-push near-dangerous states (upper part / too fast / both)", all, idx);
}

ReleasedPandaFiles ReadReleasedPandaFiles(const std::string& dir) {
  const std::filesystem::path base(dir);
  ReleasedPandaFiles f;
  f.demonstrations = data::ReadTrajectories((base / "task_demos.csv").string(),
                                            ObservationFeatures(), ActionFeatures());
  const data::StateSet nd =
      data::ReadStateSet((base / "near_dangerous_states.csv").string(), ObservationFeatures());
  std::vector<long> keep;
  for (long i = 0; i < nd.states.cols(); ++i)
    if (!nd.states.col(i).isZero(0.0f)) keep.push_back(i);
  f.near_dangerous =
      Subset("released panda-push near-dangerous states (" + nd.source + ")", nd.states, keep);
  return f;
}

ReleasedPandaData ReadReleasedPandaData(const std::string& dir, const PandaSafeOptions& safe,
                                        long near_count, Rng& rng) {
  safe.Validate();
  SECURE_CHECK(near_count >= 1,
               "released panda-push data: near_count = " << near_count << ", must be >= 1");
  ReleasedPandaFiles files = ReadReleasedPandaFiles(dir);
  ReleasedPandaData r;
  const Eigen::MatrixXf safe_all =
      WithNoisyCopies(files.demonstrations.states, safe.noisy_copies, rng);
  r.safe = Subset("released panda-push demonstrations (" + files.demonstrations.source + ", " +
                      std::to_string(safe.noisy_copies) + " noisy copies each)",
                  safe_all,
                  DrawIndices(safe_all.cols(), safe.count, rng, "released safe states (count)"));
  r.near_dangerous = Subset(files.near_dangerous.source, files.near_dangerous.states,
                            DrawIndices(files.near_dangerous.size(), near_count, rng,
                                        "released near-dangerous states (count)"));
  r.demonstrations = std::move(files.demonstrations);
  return r;
}

// ---------------------------------------------------------------------------------------------
// Labels against physics

nlohmann::json LabelCheckResult::ToJson() const {
  return {{"states", states},
          {"toppled", toppled},
          {"unreachable", unreachable},
          {"toppling_fraction", TopplingFraction()}};
}

LabelCheckResult CheckLabels(const PandaPushOptions& task, const data::StateSet& set,
                             const LabelCheckOptions& options) {
  SECURE_CHECK(
      set.dim() == kObservationDim,
      "panda-push label check: " << set.source << " has " << set.dim() << " features, expected 18");
  PandaPushSim sim(task);
  Eigen::VectorXf o(kObservationDim);
  LabelCheckResult r;
  const long n = std::min<long>(set.size(), options.max_states);
  for (long i = 0; i < n; ++i) {
    ++r.states;
    switch (Continue(sim, task, set.states.col(i), options, o)) {
      case Continuation::kUnreachable:
        ++r.unreachable;
        break;
      case Continuation::kToppled:
        ++r.toppled;
        break;
      case Continuation::kStayedUp:
        break;
    }
  }
  return r;
}

std::vector<int> LabelStates(const PandaPushOptions& task,
                             const Eigen::Ref<const Eigen::MatrixXf>& states,
                             const LabelCheckOptions& options) {
  SECURE_CHECK(states.rows() == kObservationDim, "panda-push labeller: states have "
                                                     << states.rows()
                                                     << " features, expected 18 (the observation)");
  PandaPushSim sim(task);
  Eigen::VectorXf o(kObservationDim);
  std::vector<int> labels(static_cast<std::size_t>(states.cols()));
  for (long i = 0; i < states.cols(); ++i) {
    int label = 1;
    switch (Continue(sim, task, states.col(i), options, o)) {
      case Continuation::kUnreachable:
        label = -1;
        break;
      case Continuation::kToppled:
        label = 0;
        break;
      case Continuation::kStayedUp:
        break;
    }
    labels[static_cast<std::size_t>(i)] = label;
  }
  return labels;
}

}  // namespace secure::domains::panda_push
