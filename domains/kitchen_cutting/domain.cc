#include "domains/kitchen_cutting/domain.h"
#include "domains/franka/arm_check.h"
#include "domains/franka/arm_preset.h"
#include "domains/franka/human_arm.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::kitchen_cutting {
namespace {
// The held-out states of the barrier check come from this stream (data_seed ^ salt), not the
// training data's (data_seed, data_seed + 1).
constexpr std::uint64_t kCheckDataSalt = 0x6b17c4ec4aULL;
}  // namespace

const std::vector<std::string>& BarrierFeatures() {
  static const std::vector<std::string> names{
      "blade_x", "blade_y",  "blade_z",  "ee_vx",    "ee_vy",    "ee_vz",    "wrist_x",
      "wrist_y", "wrist_z",  "elbow_x",  "elbow_y",  "elbow_z",  "hand_x",   "hand_y",
      "hand_z",  "wrist_vx", "wrist_vy", "wrist_vz", "elbow_vx", "elbow_vy", "elbow_vz"};
  return names;
}

KitchenCuttingDomainOptions KitchenCuttingDomainOptions::For(experiments::Profile profile) {
  KitchenCuttingDomainOptions o;
  if (profile == experiments::Profile::kQuick) {
    o.demonstrations.states = 300;
    o.safe.count = 200;
    o.near_dangerous.count = 200;
  }
  return o;
}

void KitchenCuttingDomainOptions::Validate() const {
  ValidateParts();
  shield_model.CheckControlPeriod("KitchenCuttingDomainOptions", task.tracking.control_period);
}

YamlFields KitchenCuttingDomainOptions::Fields() { return AddParts(YamlFields()); }

SECURE_YAML_JSON_FROM_FIELDS(KitchenCuttingDomainOptions)

// ---------------------------------------------------------------------------------------------
KitchenCuttingDomain::KitchenCuttingDomain(experiments::Profile profile) : ArmDataDomain(profile) {}

std::unique_ptr<Environment> KitchenCuttingDomain::MakeEnvironment() const {
  return std::make_unique<KitchenCuttingEnv>(options_.task, options_.shield_model);
}

KitchenCuttingDomain::Recipe KitchenCuttingDomain::MakeRecipe() const {
  Recipe r;
  r.demonstrate = [this](const KitchenDemonstrationOptions& o) {
    return GenerateKitchenDemonstrations(options_.task, o);
  };
  r.fit_held_out = [](long count, KitchenDemonstrationOptions* o) {
    o->states = std::max(o->states, count);  // KitchenSafeStates draws without replacement
  };
  r.safe = KitchenSafeStates;
  r.near_dangerous = [this](const KitchenDemonstrations& demos,
                            const KitchenNearDangerousOptions& o, Rng& rng,
                            std::vector<NearDangerousScenario>* scenarios) {
    return KitchenNearDangerousStates(options_.task, demos, o, rng, scenarios);
  };
  r.discarded = [](const KitchenDemonstrations& d) {
    return d.discarded_dangerous + d.discarded_failed;
  };
  r.held_out_salt = kCheckDataSalt;
  return r;
}

std::string KitchenCuttingDomain::LabelCheckDescription() const {
  const KitchenLabelCheckOptions c;
  std::ostringstream s;
  s << "from each state the end-effector continues at its own velocity for " << c.continue_seconds
    << " s, then holds " << c.hold_seconds
    << " s; the person's arm moves on at its observed velocity; dangerous = the blade's edge "
       "within "
    << options_.task.contact_distance << " m of the arm";
  return s.str();
}

std::vector<experiments::LabelCheckRow> KitchenCuttingDomain::CheckLabels(std::uint64_t data_seed,
                                                                          long max_states) const {
  // The same draws as GenerateData (safe, then near-dangerous).
  const Draw draw = LabelCheckDraw(data_seed, max_states);
  KitchenLabelCheckOptions check;
  check.max_states = max_states;
  check.velocity_gain = options_.shield_model.velocity_gain;
  std::vector<experiments::LabelCheckRow> rows;
  auto add = [&](const std::string& name, const std::string& label, const data::StateSet& set) {
    const KitchenLabelCheckResult r = CheckKitchenLabels(options_.task, set, check);
    rows.push_back(franka::LabelRow(name, label, r.states, r.dangerous, r.unreachable));
  };
  add("safe states", "safe", draw.safe);
  franka::AddScenarioRows(draw.near_dangerous, draw.scenarios,
                          {NearDangerousScenario::kStroke, NearDangerousScenario::kArm,
                           NearDangerousScenario::kBlade, NearDangerousScenario::kReach},
                          add);
  return rows;
}

franka::ArmCheckSpec KitchenCuttingDomain::CheckSpec() const {
  franka::ArmCheckSpec spec;
  spec.perturb = [](Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
    for (int k = 0; k < 3; ++k) {
      const float hand = static_cast<float>(0.005 * rng.Normal());
      s[kEePos + k] += hand;
      s[kBlade + k] += hand;
    }
    franka::AddNoise(rng, 0.05, kEeVel, 3, s);
    for (int k = 0; k < 3; ++k) {
      const float arm = static_cast<float>(0.01 * rng.Normal());
      s[kWrist + k] += arm;
      s[kElbow + k] += arm;
      s[kHandTip + k] += arm;
    }
    franka::AddNoise(rng, 0.05, kWristVel, 3, s);
    franka::AddNoise(rng, 0.05, kElbowVel, 3, s);
  };
  // The blade stops at the board (kitchen_cutting.h): the hand and the edge move up together.
  const float board = static_cast<float>(options_.task.board_top);
  spec.project = [board](Eigen::Ref<Eigen::VectorXf> s) {
    const float below = board - s[kBlade + 2];
    if (below > 0) {
      s[kBlade + 2] += below;
      s[kEePos + 2] += below;
    }
  };
  const KitchenCuttingOptions task = options_.task;
  spec.is_unsafe = [task](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return ObservedEdgeClearance(task, s) < task.contact_distance;
  };
  std::ostringstream unsafe;
  unsafe << "the blade's edge within the contact distance " << task.contact_distance
         << " m of the person's arm (capsules from the observed wrist, elbow and hand tip)";
  spec.is_unsafe_description = unsafe.str();
  spec.region_description =
      "held-out safe and near-dangerous observations, perturbed (hand and blade sd 0.005 m, ee "
      "velocity sd 0.05 m/s, the person's arm sd 0.01 m, its velocities sd 0.05 m/s)";
  return spec;
}

double ObservedEdgeClearance(const KitchenCuttingOptions& task,
                             const Eigen::Ref<const Eigen::VectorXf>& o) {
  SECURE_CHECK(o.size() == kObservationDim, "ObservedEdgeClearance: an observation of "
                                                << kObservationDim << " values, got " << o.size());
  const Vec3& sh = task.human.shoulder;
  const ArmPose arm = franka::ReadHumanArm(o, kWrist, Eigen::Vector3d(sh[0], sh[1], sh[2]));
  const Eigen::Vector3d edge(o[kBlade], o[kBlade + 1], o[kBlade + 2]);
  return EdgeToArmDistance(task.human, edge, arm);
}

std::optional<experiments::PaperTable3> KitchenCuttingDomain::PaperReference() const {
  const double none = std::nan("");
  experiments::PaperTable3 t;
  t.source = "Table 3, the real robot with people, 10 episodes, no standard deviations";
  t.rows = {
      {"bc", 70, none, 100, none}, {"airl", 80, none, 100, none}, {"secure", 90, none, 0, none}};
  t.comparison = "success +10%, dangerous -100% (no test on 10 episodes)";
  return t;
}

experiments::ExperimentOptions KitchenCuttingDomain::Preset() const {
  // 10 seeds x 100 episodes (the paper's own protocol, 10 episodes, is --seeds 1 --episodes 10).
  experiments::ExperimentOptions o =
      franka::ArmExperimentPreset(profile_, options_.task.tracking.control_period);
  o.data_seed = 4000;
  // Table 2's knife-cutting barrier: 32-128-128-256-256-256-256-128-128-32, tanh.
  o.flat_barrier.hidden = {32, 128, 128, 256, 256, 256, 256, 128, 128, 32};
  o.flat_barrier.input_features = BarrierFeatures();
  return o;
}

}  // namespace secure::domains::kitchen_cutting

namespace secure::plugins {
void Register_kitchen_cutting(experiments::DomainRegistry& registry) {
  registry.Add<domains::kitchen_cutting::KitchenCuttingDomain>(
      "kitchen-cutting",
      "Kitchen cutting: a Franka arm cuts through a line on a board while a simulated "
      "person's arm reaches nearby (MuJoCo; paper Section 7.1 in simulation)");
}
}  // namespace secure::plugins
