#include "domains/kitchen_cutting/data.h"

#include "domains/kitchen_cutting/precursor.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>

#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"
#include "secure/domains/demonstrations.h"

namespace secure::domains::kitchen_cutting {
namespace {

bool Finite(double x) { return std::isfinite(x); }

// The person's arm as the observation shows it, `ahead` seconds later at its velocity.
ArmPose ObservedArm(const HumanArmOptions& h, const Eigen::Ref<const Eigen::VectorXf>& o,
                    double ahead) {
  return franka::ReadHumanArm(o, kWrist, h.Shoulder(), ahead);
}

// The clearance of the stroke's path: the edge lowered from where it is to the board (checked
// at the board and halfway).
double PathClearance(const KitchenCuttingOptions& task, const Eigen::Vector3d& edge,
                     const ArmPose& arm) {
  Eigen::Vector3d low = edge, mid = edge;
  low.z() = task.board_top;
  mid.z() = 0.5 * (edge.z() + task.board_top);
  return std::min(EdgeToArmDistance(task.human, low, arm), EdgeToArmDistance(task.human, mid, arm));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options

void KitchenDemonstrationOptions::Validate() const {
  const char* o = "KitchenDemonstrationOptions";
  SECURE_CHECK_FIELD(states >= 1 && states <= 10000000, o, "states", states, "in [1, 1e7]");
  SECURE_CHECK_FIELD(max_attempts >= 1, o, "max_attempts", max_attempts, ">= 1");
  CheckIntervalField(stroke_speed, o, "stroke_speed", 0.05, 1.0);
  CheckIntervalField(travel_speed, o, "travel_speed", 0.05, 1.0);
  SECURE_CHECK_FIELD(Finite(caution_distance) && caution_distance > 0 && caution_distance <= 0.5, o,
                     "caution_distance", caution_distance, "in (0, 0.5] m");
  SECURE_CHECK_FIELD(Finite(look_ahead) && look_ahead >= 0 && look_ahead <= 5, o, "look_ahead",
                     look_ahead, "in [0, 5] s");
  SECURE_CHECK_FIELD(Finite(hover_height) && hover_height > 0 && hover_height <= 0.4, o,
                     "hover_height", hover_height, "in (0, 0.4] m");
  SECURE_CHECK_FIELD(Finite(action_noise) && action_noise >= 0 && action_noise <= 1, o,
                     "action_noise", action_noise, "in [0, 1]");
}

YamlFields KitchenDemonstrationOptions::Fields() {
  return YamlFields()
      .Field("states", &states)
      .Field("max_attempts", &max_attempts)
      .Field("stroke_speed", &stroke_speed)
      .Field("travel_speed", &travel_speed)
      .Field("caution_distance", &caution_distance)
      .Field("look_ahead", &look_ahead)
      .Field("hover_height", &hover_height)
      .Field("action_noise", &action_noise);
}

SECURE_YAML_JSON_FROM_FIELDS(KitchenDemonstrationOptions)

void KitchenSafeOptions::Validate() const {
  SECURE_CHECK_FIELD(count >= 1 && count <= 100000000, "KitchenSafeOptions", "count", count,
                     "in [1, 1e8]");
}
YamlFields KitchenSafeOptions::Fields() { return YamlFields().Field("count", &count); }

SECURE_YAML_JSON_FROM_FIELDS(KitchenSafeOptions)

void KitchenNearDangerousOptions::Validate() const {
  const char* o = "KitchenNearDangerousOptions";
  SECURE_CHECK_FIELD(count >= 1 && count <= 100000000, o, "count", count, "in [1, 1e8]");
  SECURE_CHECK_FIELD(Finite(p_stroke) && p_stroke >= 0 && p_stroke <= 1, o, "p_stroke", p_stroke,
                     "in [0, 1]");
  SECURE_CHECK_FIELD(Finite(near_distance) && near_distance > 0 && near_distance <= 0.3, o,
                     "near_distance", near_distance, "in (0, 0.3] m");
  CheckIntervalField(stroke_vz, o, "stroke_vz", 0.0, 5.0);
  CheckIntervalField(arm_speed, o, "arm_speed", 0.0, 5.0);
  SECURE_CHECK_FIELD(Finite(look_ahead) && look_ahead > 0 && look_ahead <= 5, o, "look_ahead",
                     look_ahead, "in (0, 5] s");
  SECURE_CHECK_FIELD(Finite(p_blade) && p_blade >= 0 && p_blade <= 1 - p_stroke, o, "p_blade",
                     p_blade, "in [0, 1 - p_stroke] (p_stroke = " << p_stroke << ")");
  CheckIntervalField(blade_speed, o, "blade_speed", 0.0, 5.0);
  SECURE_CHECK_FIELD(Finite(p_reach) && p_reach >= 0 && p_reach <= 1 - p_stroke - p_blade + 1e-12,
                     o, "p_reach", p_reach,
                     "in [0, 1 - p_stroke - p_blade] (p_stroke = " << p_stroke << ", p_blade = "
                                                                   << p_blade << ")");
  CheckIntervalField(reach_gap, o, "reach_gap", 0.0, 1.0);
  SECURE_CHECK_FIELD(Finite(label_noise) && label_noise >= 0 && label_noise <= 0.5, o,
                     "label_noise", label_noise, "in [0, 0.5]");
}

nlohmann::json KitchenNearDangerousOptions::ToJson() const {
  nlohmann::json j = TableJson(*this);
  if (p_reach <= 0) {  // only when on: the default's files keep their bytes
    j.erase("p_reach");
    j.erase("reach_gap");
  }
  if (label_noise <= 0) j.erase("label_noise");
  return j;
}

YamlFields KitchenNearDangerousOptions::Fields() {
  return YamlFields()
      .Field("count", &count)
      .Field("p_stroke", &p_stroke)
      .Field("near_distance", &near_distance)
      .Field("stroke_vz", &stroke_vz)
      .Field("arm_speed", &arm_speed)
      .Field("look_ahead", &look_ahead)
      .Field("p_blade", &p_blade)
      .Field("blade_speed", &blade_speed)
      .Field("p_reach", &p_reach)
      .Field("reach_gap", &reach_gap)
      .Field("label_noise", &label_noise);
}

void KitchenNearDangerousOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  Fields().Apply(node, source);
}

namespace {
constexpr EnumTable<NearDangerousScenario, 4> kScenarioNames{{
    {NearDangerousScenario::kStroke, "stroke into the arm"},
    {NearDangerousScenario::kArm, "arm into the blade"},
    {NearDangerousScenario::kBlade, "blade into the resting arm"},
    {NearDangerousScenario::kReach, "the person's reach, before contact"},
}};
}  // namespace

const char* ScenarioName(NearDangerousScenario s) { return NameOf(kScenarioNames, s); }

// ---------------------------------------------------------------------------------------------
// The person's rule (data.h)

bool StrokeReaches(const KitchenCuttingOptions& task, const KitchenNearDangerousOptions& rule,
                   const Eigen::Vector3d& edge, double ee_vz, const ArmPose& arm) {
  return ee_vz < 0 && -ee_vz >= rule.stroke_vz[0] &&
         PathClearance(task, edge, arm) < task.contact_distance;
}

bool ArmReaches(const KitchenCuttingOptions& task, const Eigen::Vector3d& edge, const ArmPose& arm,
                const Eigen::Vector3d& wrist_velocity, const Eigen::Vector3d& elbow_velocity,
                double look_ahead) {
  ArmPose later = arm;
  later.wrist += look_ahead * wrist_velocity;
  later.tip += look_ahead * wrist_velocity;
  later.elbow += look_ahead * elbow_velocity;
  return EdgeToArmDistance(task.human, edge, later) < task.contact_distance;
}

bool BladeReaches(const KitchenCuttingOptions& task, const Eigen::Vector3d& edge,
                  const Eigen::Vector3d& ee_velocity, const ArmPose& arm, double look_ahead) {
  constexpr int kPathPoints = 10;
  for (int i = 1; i <= kPathPoints; ++i) {
    const Eigen::Vector3d at = edge + (look_ahead * i / kPathPoints) * ee_velocity;
    if (at.z() >= task.board_top && EdgeToArmDistance(task.human, at, arm) < task.contact_distance)
      return true;
  }
  return false;
}

KitchenJudgement JudgeKitchenState(const KitchenCuttingOptions& task,
                                   const KitchenNearDangerousOptions& rule,
                                   const Eigen::Ref<const Eigen::VectorXf>& o) {
  SECURE_CHECK(o.size() == kObservationDim, "JudgeKitchenState: an observation of "
                                                << kObservationDim << " values, got " << o.size());
  const Eigen::Vector3d edge = franka::ObservedPoint(o, kBlade),
                        ee_velocity = franka::ObservedPoint(o, kEeVel);
  const ArmPose arm = ObservedArm(task.human, o, 0.0);
  if (EdgeToArmDistance(task.human, edge, arm) < task.contact_distance)
    return KitchenJudgement::kDangerous;
  const bool near = StrokeReaches(task, rule, edge, ee_velocity.z(), arm) ||
                    ArmReaches(task, edge, arm, franka::ObservedPoint(o, kWristVel),
                               franka::ObservedPoint(o, kElbowVel), rule.look_ahead) ||
                    BladeReaches(task, edge, ee_velocity, arm, rule.look_ahead);
  return near ? KitchenJudgement::kNearDangerous : KitchenJudgement::kSafe;
}

// ---------------------------------------------------------------------------------------------
// Demonstrations

Eigen::Vector3f DemonstratorAction(const KitchenCuttingOptions& task,
                                   const KitchenDemonstrationOptions& options,
                                   const Eigen::Ref<const Eigen::VectorXf>& o, double stroke_speed,
                                   double travel_speed) {
  const Eigen::Vector3d edge = franka::ObservedPoint(o, kBlade);
  const ArmPose now = ObservedArm(task.human, o, 0.0);
  const ArmPose ahead = ObservedArm(task.human, o, options.look_ahead);
  const double clearance = std::min(EdgeToArmDistance(task.human, edge, now),
                                    EdgeToArmDistance(task.human, edge, ahead));
  const double path = std::min(PathClearance(task, edge, now), PathClearance(task, edge, ahead));
  const double height = edge.z() - task.board_top;
  Eigen::Vector3f a = Eigen::Vector3f::Zero();
  if (clearance < options.caution_distance) {
    a[2] = 1.0f;  // lift the knife away
    return a;
  }
  const double ex = task.cut_line_x - edge.x(), ey = task.cut_line_y - edge.y();
  a[0] = static_cast<float>(std::clamp(ex / 0.05, -travel_speed, travel_speed));
  a[1] = static_cast<float>(std::clamp(ey / 0.05, -travel_speed, travel_speed));
  const float hover =
      static_cast<float>(std::clamp(0.5 * (options.hover_height - height) / 0.05, -1.0, 1.0));
  if (path < options.caution_distance) {
    a[2] = std::max(hover, 0.0f);  // wait above, never towards the arm
  } else if (std::abs(ex) > 0.01 || std::abs(ey) > 0.01) {
    a[2] = hover;
  } else if (o[kLifted] > 0.5f) {
    a[2] = static_cast<float>(-stroke_speed);
  } else {
    a[2] = static_cast<float>(stroke_speed);
  }
  return a;
}

KitchenDemonstrations GenerateKitchenDemonstrations(const KitchenCuttingOptions& task,
                                                    const KitchenDemonstrationOptions& options) {
  task.Validate();
  options.Validate();
  KitchenCuttingEnv env(task, KitchenShieldModelOptions{});
  Rng rng(options.seed);
  KitchenDemonstrations out;
  DemonstrationCollector collector(
      "scripted kitchen-cutting demonstrations (seed " + std::to_string(options.seed) + ")",
      ObservationFeatures(), ActionFeatures());
  Eigen::VectorXf o(kObservationDim), a(kActionDim);
  int attempt = 0;
  for (; attempt < options.max_attempts && collector.kept_steps() < options.states; ++attempt) {
    Rng episode_rng(rng.NextU64());
    const double stroke = franka::DrawUniform(episode_rng, options.stroke_speed);
    const double travel = franka::DrawUniform(episode_rng, options.travel_speed);
    env.Reset(episode_rng, o);
    const RecordedEpisode episode = RecordEpisode(
        env, collector, task.max_steps, /*stop_at_goal=*/true, o, a, a,
        [&](const Eigen::VectorXf& obs, Eigen::VectorXf& act, Eigen::VectorXf&) {
          const Eigen::Vector3f clean = DemonstratorAction(task, options, obs, stroke, travel);
          for (int k = 0; k < kActionDim; ++k)
            act[k] = std::clamp(
                clean[k] + static_cast<float>(options.action_noise * episode_rng.Normal()), -1.0f,
                1.0f);
        },
        [](const StepOutcome&) {});
    if (!KeepOrCountDiscarded(episode, &out.discarded_dangerous, &out.discarded_failed)) continue;
    if (env.sim().path().into) ++out.into_episodes;
    collector.KeepEpisode();
  }
  SECURE_CHECK(collector.kept_steps() >= options.states,
               "kitchen-cutting demonstrations: only "
                   << collector.kept_steps() << " of " << options.states << " states in " << attempt
                   << " attempts (" << out.discarded_dangerous << " came dangerous, "
                   << out.discarded_failed << " did not finish the cut)");
  out.trajectories = collector.Finish();
  return out;
}

// ---------------------------------------------------------------------------------------------
// Safe and near-dangerous states

data::StateSet KitchenSafeStates(const KitchenDemonstrations& demos,
                                 const KitchenSafeOptions& options, Rng& rng) {
  options.Validate();
  const Eigen::MatrixXf& demo = demos.trajectories.states;
  SECURE_CHECK(options.count <= demo.cols(),
               "kitchen-cutting safe states: count = " << options.count << " but only "
                                                       << demo.cols() << " demonstration states");
  std::vector<long> order(static_cast<size_t>(demo.cols()));
  std::iota(order.begin(), order.end(), 0L);
  Shuffle(order.begin(), order.end(), rng);
  data::StateSet s;
  s.source = "kitchen-cutting demonstration states";
  s.features = ObservationFeatures();
  s.states.resize(kObservationDim, options.count);
  for (long i = 0; i < options.count; ++i) s.states.col(i) = demo.col(order[i]);
  return s;
}

data::StateSet KitchenNearDangerousStates(const KitchenCuttingOptions& task,
                                          const KitchenDemonstrations& demos,
                                          const KitchenNearDangerousOptions& options, Rng& rng,
                                          std::vector<NearDangerousScenario>* scenarios) {
  options.Validate();
  const HumanArmOptions& h = task.human;
  const Eigen::MatrixXf& demo = demos.trajectories.states;
  SECURE_CHECK(demo.cols() > 0, "kitchen-cutting near-dangerous states: no demonstration states");
  data::StateSet s;
  s.source = "kitchen-cutting near-dangerous states (the arm put near the blade)";
  s.features = ObservationFeatures();
  s.states.resize(kObservationDim, options.count);
  if (scenarios != nullptr) scenarios->clear();
  long made = 0, visited = 0;
  std::vector<long> order(static_cast<size_t>(demo.cols()));
  std::iota(order.begin(), order.end(), 0L);
  Shuffle(order.begin(), order.end(), rng);
  const long max_visits = 20 * options.count + demo.cols();
  // An arm pose with its wrist in a random direction from the edge and the arm's surface
  // contact_distance..near_distance from it (scenarios b and c), or none for this draw.
  auto arm_near_edge = [&](const Eigen::Vector3d& edge) -> std::optional<ArmPose> {
    Eigen::Vector3d dir(rng.Normal(), rng.Normal(), rng.Normal());
    if (dir.norm() < 1e-6) return std::nullopt;
    dir.normalize();
    const Eigen::Vector3d wrist =
        edge + dir * rng.Uniform(0.0, options.near_distance + h.forearm_radius + 0.08);
    if (wrist.z() < task.board_top + 0.02) return std::nullopt;
    const ArmPose p = ArmPoseForWrist(h, wrist);
    const double d = EdgeToArmDistance(h, edge, p);
    if (d < task.contact_distance || d > options.near_distance) return std::nullopt;
    return p;
  };
  while (made < options.count && visited < max_visits) {
    Eigen::VectorXf o = demo.col(order[static_cast<size_t>(visited % demo.cols())]);
    ++visited;
    const Eigen::Vector3d edge = franka::ObservedPoint(o, kBlade);
    const double u = rng.Uniform();
    const bool stroke = u < options.p_stroke;
    // Drawn from the same uniform, so that p_blade = 0 keeps the draws of releases without (c).
    const bool blade = !stroke && u < options.p_stroke + options.p_blade;
    const bool reach = !stroke && !blade && u < options.p_stroke + options.p_blade + options.p_reach;
    bool accepted = false;
    for (int attempt = 0; attempt < 200 && !accepted; ++attempt) {
      if (stroke) {
        // The wrist under the edge, from the person's side (+y) to the blade's plane.
        const double top = edge.z() - task.contact_distance - 0.01;
        if (top <= task.board_top + 0.03) break;  // no room under the blade
        const Eigen::Vector3d wrist(edge.x() + rng.Uniform(-0.07, 0.07),
                                    edge.y() + rng.Uniform(-0.08, 0.0),
                                    rng.Uniform(task.board_top + 0.03, top));
        const ArmPose p = ArmPoseForWrist(h, wrist);
        const double d = EdgeToArmDistance(h, edge, p);
        if (d < task.contact_distance || d > options.near_distance) continue;
        // The rule's clause (a) at the fastest stroke speed (the draw of it follows: any drawn
        // speed satisfies the clause as well).
        if (!StrokeReaches(task, options, edge, -options.stroke_vz[1], p)) continue;
        franka::WriteHumanArm(p, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), kWrist, o);
        o[kEeVel] = o[kEeVel + 1] = 0.0f;
        o[kEeVel + 2] = static_cast<float>(-franka::DrawUniform(rng, options.stroke_vz));
        accepted = true;
      } else if (reach) {
        accepted = ReachPrecursorState(task, options, rng, o);
      } else if (blade) {
        // The arm at rest near the edge; the end-effector moving towards it (the direction to
        // the wrist, perturbed) so that the edge comes within contact_distance of the arm
        // within look_ahead if the motion continues.
        const std::optional<ArmPose> near = arm_near_edge(edge);
        if (!near) continue;
        const ArmPose& p = *near;
        Eigen::Vector3d towards = (p.wrist - edge).normalized() +
                                  0.3 * Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal());
        if (towards.norm() < 1e-6) continue;
        const Eigen::Vector3d v =
            franka::DrawUniform(rng, options.blade_speed) * towards.normalized();
        if (!BladeReaches(task, edge, v, p, options.look_ahead)) continue;  // the rule's (c)
        franka::WriteHumanArm(p, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), kWrist, o);
        for (int k = 0; k < 3; ++k) o[kEeVel + k] = static_cast<float>(v[k]);
        accepted = true;
      } else {
        const std::optional<ArmPose> near = arm_near_edge(edge);
        if (!near) continue;
        const ArmPose& p = *near;
        const Eigen::Vector3d towards = (edge - p.wrist).normalized();
        const double speed = franka::DrawUniform(rng, options.arm_speed);
        const Eigen::Vector3d wv = speed * towards, ev = 0.5 * speed * towards;
        if (!ArmReaches(task, edge, p, wv, ev, options.look_ahead)) continue;  // the rule's (b)
        franka::WriteHumanArm(p, wv, ev, kWrist, o);
        accepted = true;
      }
    }
    if (!accepted) continue;
    s.states.col(made++) = o;
    if (scenarios != nullptr)
      scenarios->push_back(stroke  ? NearDangerousScenario::kStroke
                           : blade ? NearDangerousScenario::kBlade
                           : reach ? NearDangerousScenario::kReach
                                   : NearDangerousScenario::kArm);
  }
  SECURE_CHECK(made == options.count, "kitchen-cutting near-dangerous states: only "
                                          << made << " of " << options.count << " made");
  return s;
}

// ---------------------------------------------------------------------------------------------
// The label check

KitchenLabelCheckResult CheckKitchenLabels(const KitchenCuttingOptions& task,
                                           const data::StateSet& set,
                                           const KitchenLabelCheckOptions& options) {
  KitchenCuttingSim sim(task);
  KitchenLabelCheckResult r;
  const long n = std::min(set.size(), options.max_states);
  const int continue_steps =
      static_cast<int>(std::lround(options.continue_seconds / task.tracking.control_period));
  const int hold_steps =
      static_cast<int>(std::lround(options.hold_seconds / task.tracking.control_period));
  for (long i = 0; i < n; ++i) {
    ++r.states;
    const Eigen::VectorXf o = set.states.col(i);
    if (sim.SetObservation(o) > 0.01) {
      ++r.unreachable;
      continue;
    }
    bool dangerous = sim.Dangerous();
    Eigen::Vector3f a;
    for (int k = 0; k < 3; ++k)
      a[k] = std::clamp(static_cast<float>(o[kEeVel + k] / options.velocity_gain), -1.0f, 1.0f);
    for (int t = 0; t < continue_steps + hold_steps && !dangerous; ++t) {
      sim.Step(t < continue_steps ? a : Eigen::Vector3f::Zero());
      dangerous = sim.Dangerous();
    }
    if (dangerous) ++r.dangerous;
  }
  return r;
}

}  // namespace secure::domains::kitchen_cutting
