#include "domains/coffee_placing/participants.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"
#include "secure/domains/demonstrations.h"

namespace secure::domains::coffee_placing {
namespace {

bool Finite(double x) { return std::isfinite(x); }
double Mid(const Interval& r) { return 0.5 * (r[0] + r[1]); }

// The arm as the observation shows it, `ahead` seconds later at its velocity.
ArmPose ObservedArm(const PersonOptions& p, const Eigen::Ref<const Eigen::VectorXf>& o,
                    double ahead) {
  return franka::ReadHumanArm(o, kWrist, p.Shoulder(), ahead);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Participants

nlohmann::json Participant::ToJson() const {
  return {{"index", index},
          {"comfort_distance", thresholds.comfort_distance},
          {"max_tilt", thresholds.max_tilt},
          {"caution", caution},
          {"travel_speed", travel_speed},
          {"ramp", ramp},
          {"action_noise", action_noise},
          {"label_noise", label_noise}};
}

void PopulationRanges::Validate() const {
  const char* o = "PopulationRanges";
  SECURE_CHECK_FIELD(Finite(comfort_mean) && comfort_mean > 0 && comfort_mean <= 0.5, o,
                     "comfort_mean", comfort_mean, "in (0, 0.5] m");
  SECURE_CHECK_FIELD(
      Finite(comfort_half_range) && comfort_half_range >= 0 && comfort_half_range < comfort_mean, o,
      "comfort_half_range", comfort_half_range, "in [0, comfort_mean)");
  SECURE_CHECK_FIELD(Finite(tilt_mean) && tilt_mean > 0 && tilt_mean < kMaxTilt, o, "tilt_mean",
                     tilt_mean, "in (0, " << kMaxTilt << ") rad");
  SECURE_CHECK_FIELD(Finite(tilt_half_range) && tilt_half_range >= 0 && tilt_half_range < tilt_mean,
                     o, "tilt_half_range", tilt_half_range, "in [0, tilt_mean)");
  CheckIntervalField(caution, o, "caution", 0, 0.3);
  CheckIntervalField(travel_speed, o, "travel_speed", 0.05, 1);
  CheckIntervalField(ramp, o, "ramp", 0.01, 10);
  CheckIntervalField(action_noise, o, "action_noise", 0, 1);
  CheckIntervalField(label_noise, o, "label_noise", 0, 0.5);
}

YamlFields PopulationRanges::Fields() {
  return YamlFields()
      .Field("comfort_mean", &comfort_mean)
      .Field("comfort_half_range", &comfort_half_range)
      .Field("tilt_mean", &tilt_mean)
      .Field("tilt_half_range", &tilt_half_range)
      .Field("caution", &caution)
      .Field("travel_speed", &travel_speed)
      .Field("ramp", &ramp)
      .Field("action_noise", &action_noise)
      .Field("label_noise", &label_noise);
}

SECURE_YAML_JSON_FROM_FIELDS(PopulationRanges)

Participant DrawParticipant(const PopulationRanges& r, std::uint64_t seed, int index,
                            double spread) {
  SECURE_CHECK(index >= 0, "participant index " << index << " must be >= 0");
  SECURE_CHECK(Finite(spread) && spread >= 0 && spread <= 1,
               "threshold spread " << spread << " must be in [0, 1]");
  Rng rng(seed ^ (0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(index + 1)));
  Participant p;
  p.index = index;
  const double u_comfort = rng.Uniform(-1.0, 1.0), u_tilt = rng.Uniform(-1.0, 1.0);
  p.thresholds.comfort_distance = r.comfort_mean + spread * r.comfort_half_range * u_comfort;
  p.thresholds.max_tilt = r.tilt_mean + spread * r.tilt_half_range * u_tilt;
  p.caution = franka::DrawUniform(rng, r.caution);
  p.travel_speed = franka::DrawUniform(rng, r.travel_speed);
  p.ramp = franka::DrawUniform(rng, r.ramp) * p.thresholds.max_tilt;
  p.action_noise = franka::DrawUniform(rng, r.action_noise);
  p.label_noise = franka::DrawUniform(rng, r.label_noise);
  return p;
}

Participant MeanParticipant(const PopulationRanges& r) {
  Participant p;
  p.thresholds.comfort_distance = r.comfort_mean;
  p.thresholds.max_tilt = r.tilt_mean;
  p.caution = Mid(r.caution);
  p.travel_speed = Mid(r.travel_speed);
  p.ramp = Mid(r.ramp) * p.thresholds.max_tilt;
  p.action_noise = Mid(r.action_noise);
  p.label_noise = Mid(r.label_noise);
  return p;
}

// ---------------------------------------------------------------------------------------------
// Options

void CoffeeDemonstrationOptions::Validate() const {
  const char* o = "CoffeeDemonstrationOptions";
  SECURE_CHECK_FIELD(states >= 1 && states <= 10000000, o, "states", states, "in [1, 1e7]");
  SECURE_CHECK_FIELD(max_attempts >= 1, o, "max_attempts", max_attempts, ">= 1");
  SECURE_CHECK_FIELD(Finite(look_ahead) && look_ahead >= 0 && look_ahead <= 5, o, "look_ahead",
                     look_ahead, "in [0, 5] s");
  SECURE_CHECK_FIELD(Finite(hover_height) && hover_height > kCupDrop && hover_height <= 0.6, o,
                     "hover_height", hover_height, "in (" << kCupDrop << ", 0.6] m");
  SECURE_CHECK_FIELD(Finite(descend_speed) && descend_speed > 0 && descend_speed <= 1, o,
                     "descend_speed", descend_speed, "in (0, 1]");
  SECURE_CHECK_FIELD(Finite(velocity_gain) && velocity_gain > 0, o, "velocity_gain", velocity_gain,
                     "> 0");
}

YamlFields CoffeeDemonstrationOptions::Fields() {
  return YamlFields()
      .Field("states", &states)
      .Field("max_attempts", &max_attempts)
      .Field("look_ahead", &look_ahead)
      .Field("hover_height", &hover_height)
      .Field("descend_speed", &descend_speed)
      .Field("velocity_gain", &velocity_gain);
}

SECURE_YAML_JSON_FROM_FIELDS(CoffeeDemonstrationOptions)

void CoffeeLabelOptions::Validate() const {
  const char* o = "CoffeeLabelOptions";
  SECURE_CHECK_FIELD(safe >= 1 && safe <= 100000000, o, "safe", safe, "in [1, 1e8]");
  SECURE_CHECK_FIELD(unsafe >= 1 && unsafe <= 100000000, o, "unsafe", unsafe, "in [1, 1e8]");
  SECURE_CHECK_FIELD(Finite(arm_probability) && arm_probability >= 0 && arm_probability <= 1, o,
                     "arm_probability", arm_probability, "in [0, 1]");
  SECURE_CHECK_FIELD(Finite(arm_radius) && arm_radius > 0 && arm_radius <= 1, o, "arm_radius",
                     arm_radius, "in (0, 1] m");
  SECURE_CHECK_FIELD(Finite(arm_speed) && arm_speed >= 0 && arm_speed <= 5, o, "arm_speed",
                     arm_speed, "in [0, 5] m/s");
  SECURE_CHECK_FIELD(Finite(tilt_probability) && tilt_probability >= 0 && tilt_probability <= 1, o,
                     "tilt_probability", tilt_probability, "in [0, 1]");
  SECURE_CHECK_FIELD(Finite(tilt_range) && tilt_range >= 0 && tilt_range <= kMaxTilt, o,
                     "tilt_range", tilt_range, "in [0, " << kMaxTilt << "] rad");
}

YamlFields CoffeeLabelOptions::Fields() {
  return YamlFields()
      .Field("safe", &safe)
      .Field("unsafe", &unsafe)
      .Field("arm_probability", &arm_probability)
      .Field("arm_radius", &arm_radius)
      .Field("arm_speed", &arm_speed)
      .Field("tilt_probability", &tilt_probability)
      .Field("tilt_range", &tilt_range);
}

SECURE_YAML_JSON_FROM_FIELDS(CoffeeLabelOptions)

// ---------------------------------------------------------------------------------------------
// Demonstrations

Eigen::Vector4f DemonstratorAction(const CoffeePlacingOptions& task,
                                   const CoffeeDemonstrationOptions& options,
                                   const Participant& participant,
                                   const Eigen::Ref<const Eigen::VectorXf>& o) {
  const PersonOptions& person = task.person;
  const Eigen::Vector3d ee = franka::ObservedPoint(o, kEePos);
  const double tilt = o[kTilt];
  const ArmPose now = ObservedArm(person, o, 0.0);
  const ArmPose ahead = ObservedArm(person, o, options.look_ahead);
  const double keep = participant.thresholds.comfort_distance + participant.caution;
  const double clearance =
      std::min(Clearance(person, ee, tilt, now), Clearance(person, ee, tilt, ahead));
  const Eigen::Vector3d hover(task.target[0], task.target[1], options.hover_height);
  const double v = participant.travel_speed;
  Eigen::Vector3d want = Eigen::Vector3d::Zero();
  if (clearance < keep) {
    want = Eigen::Vector3d(0.0, -v, 0.5 * v);  // back away from the person, and up
  } else {
    const Eigen::Vector3d flat(ee.x() - hover.x(), ee.y() - hover.y(), 0.0);
    if (flat.norm() > 0.01) {
      // The straight path to the hover point (sampled) must keep the distance.
      double path = 1e9;
      for (double s : {0.25, 0.5, 0.75, 1.0}) {
        const Eigen::Vector3d q = ee + s * (hover - ee);
        path = std::min({path, Clearance(person, q, 0.0, now), Clearance(person, q, 0.0, ahead)});
      }
      if (path >= keep) {
        for (int k = 0; k < 3; ++k) want[k] = std::clamp((hover[k] - ee[k]) / 0.05, -v, v);
      }
    } else {
      want.x() = std::clamp((hover.x() - ee.x()) / 0.05, -v, v);
      want.y() = std::clamp((hover.y() - ee.y()) / 0.05, -v, v);
      want.z() = -options.descend_speed;
    }
  }
  // At most `ramp` from the action the current velocity shows.
  Eigen::Vector4f a;
  for (int k = 0; k < 3; ++k) {
    const double current = o[kEeVel + k] / options.velocity_gain;
    a[k] = static_cast<float>(std::clamp(
        std::clamp(want[k], current - participant.ramp, current + participant.ramp), -1.0, 1.0));
  }
  const double induced = task.tilt_coupling * (options.velocity_gain * a[0] - o[kEeVel]);
  a[3] = static_cast<float>(std::clamp(-(tilt + induced) / task.tilt_scale, -1.0, 1.0));
  return a;
}

CoffeeDemonstrations GenerateCoffeeDemonstrations(const CoffeePlacingOptions& task,
                                                  const CoffeeDemonstrationOptions& options,
                                                  const Participant& participant,
                                                  std::uint64_t seed) {
  options.Validate();
  CoffeePlacingEnv env(task, CoffeeShieldModelOptions{}, participant.thresholds);
  Rng rng(seed);
  CoffeeDemonstrations out;
  DemonstrationCollector collector(
      "coffee-placing demonstrations of participant " + std::to_string(participant.index),
      ObservationFeatures(), ActionFeatures());
  Eigen::VectorXf o(kObservationDim), a(kActionDim);
  int attempt = 0;
  while (collector.kept_steps() < options.states && attempt < options.max_attempts) {
    ++attempt;
    env.Reset(rng, o);
    RecordedEpisode episode;
    if (participant.thresholds.Violated(o[kClearance], o[kTilt])) {
      episode.collided = true;  // violated from the start: no step
    } else {
      episode = RecordEpisode(
          env, collector, task.max_steps, /*stop_at_goal=*/true, o, a, a,
          [&](const Eigen::VectorXf& obs, Eigen::VectorXf& act, Eigen::VectorXf&) {
            const Eigen::Vector4f clean = DemonstratorAction(task, options, participant, obs);
            for (int k = 0; k < kActionDim; ++k)
              act[k] =
                  std::clamp(clean[k] + static_cast<float>(participant.action_noise * rng.Normal()),
                             -1.0f, 1.0f);
          },
          [](const StepOutcome&) {});
    }
    if (!KeepOrCountDiscarded(episode, &out.discarded_violating, &out.discarded_failed)) continue;
    collector.KeepEpisode();
  }
  SECURE_CHECK(collector.kept_steps() >= options.states,
               "coffee-placing demonstrations of participant "
                   << participant.index << ": only " << collector.kept_steps() << " of "
                   << options.states << " states in " << attempt << " attempts ("
                   << out.discarded_violating << " violated the participant's thresholds, "
                   << out.discarded_failed << " did not put the cup down)");
  out.trajectories = collector.Finish();
  return out;
}

// ---------------------------------------------------------------------------------------------
// Labelled states

bool ParticipantJudgesUnsafe(const PersonOptions& person, const Thresholds& thresholds,
                             const Eigen::Ref<const Eigen::VectorXf>& o) {
  SECURE_CHECK(o.size() == kObservationDim, "ParticipantJudgesUnsafe: an observation of "
                                                << kObservationDim << " values, got " << o.size());
  const float clearance = static_cast<float>(ObservedClearance(person, o));
  return thresholds.Violated(clearance, o[kTilt]);
}

bool ParticipantAnswersUnsafe(const PersonOptions& person, const Participant& participant,
                              const Eigen::Ref<const Eigen::VectorXf>& o, Rng& rng) {
  const bool unsafe = ParticipantJudgesUnsafe(person, participant.thresholds, o);
  return rng.Uniform() < participant.label_noise ? !unsafe : unsafe;
}

void CoffeeLabelledStates(const CoffeePlacingOptions& task, const CoffeeLabelOptions& options,
                          const Participant& participant, const data::TrajectorySet& demos,
                          Rng& rng, data::StateSet* safe, data::StateSet* unsafe) {
  options.Validate();
  const Eigen::MatrixXf& demo = demos.states;
  SECURE_CHECK(demo.cols() > 0, "coffee-placing labelled states: no demonstration states");
  const PersonOptions& person = task.person;
  for (data::StateSet* s : {safe, unsafe}) {
    s->features = ObservationFeatures();
    s->states.resize(kObservationDim, s == safe ? options.safe : options.unsafe);
  }
  safe->source =
      "coffee-placing states participant " + std::to_string(participant.index) + " labelled safe";
  unsafe->source =
      "coffee-placing states participant " + std::to_string(participant.index) + " labelled unsafe";
  long n_safe = 0, n_unsafe = 0, drawn = 0;
  const long max_draws = 50 * (options.safe + options.unsafe);
  while ((n_safe < options.safe || n_unsafe < options.unsafe) && drawn < max_draws) {
    ++drawn;
    Eigen::VectorXf o = demo.col(
        static_cast<Eigen::Index>(rng.UniformIndex(static_cast<std::uint64_t>(demo.cols()))));
    if (rng.Uniform() < options.arm_probability) {
      Eigen::Vector3d dir(rng.Normal(), rng.Normal(), rng.Normal());
      if (dir.norm() < 1e-6) continue;
      dir.normalize();
      Eigen::Vector3d wrist =
          franka::ObservedPoint(o, kEePos) + rng.Uniform(0.0, options.arm_radius) * dir;
      wrist.z() = std::max(wrist.z(), 0.03);
      const ArmPose arm = ArmPoseForWrist(person, wrist);
      Eigen::Vector3d vel(rng.Normal(), rng.Normal(), rng.Normal());
      if (vel.norm() > 1e-9) vel = vel.normalized() * rng.Uniform(0.0, options.arm_speed);
      for (int k = 0; k < 3; ++k) {
        o[kWrist + k] = static_cast<float>(arm.wrist[k]);
        o[kElbow + k] = static_cast<float>(arm.elbow[k]);
        o[kHandTip + k] = static_cast<float>(arm.tip[k]);
        o[kWristVel + k] = static_cast<float>(vel[k]);
        o[kElbowVel + k] = static_cast<float>(0.5 * vel[k]);
      }
    }
    if (rng.Uniform() < options.tilt_probability)
      o[kTilt] = static_cast<float>(rng.Uniform(-options.tilt_range, options.tilt_range));
    o[kClearance] = static_cast<float>(ObservedClearance(person, o));
    const bool is_unsafe = ParticipantAnswersUnsafe(person, participant, o, rng);
    if (is_unsafe && n_unsafe < options.unsafe) unsafe->states.col(n_unsafe++) = o;
    if (!is_unsafe && n_safe < options.safe) safe->states.col(n_safe++) = o;
  }
  SECURE_CHECK(n_safe == options.safe && n_unsafe == options.unsafe,
               "coffee-placing labelled states of participant "
                   << participant.index << ": only " << n_safe << " safe and " << n_unsafe
                   << " unsafe states in " << drawn << " draws");
}

}  // namespace secure::domains::coffee_placing
