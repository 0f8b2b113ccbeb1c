#include "domains/kitchen_cutting/domain.h"
#include "domains/franka/arm_preset.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::kitchen_cutting {

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
  task.Validate();
  shield_model.Validate();
  demonstrations.Validate();
  safe.Validate();
  near_dangerous.Validate();
  SECURE_CHECK_FIELD(std::abs(shield_model.dt - task.control_period) < 1e-12,
                     "KitchenCuttingDomainOptions", "shield_model.dt", shield_model.dt,
                     "the control period (" << task.control_period << " s)");
}

void KitchenCuttingDomainOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  YamlFields()
      .Section("task", [this](const YAML::Node& n, const std::string& w) { task.ApplyYaml(n, w); })
      .Section("shield_model",
               [this](const YAML::Node& n, const std::string& w) { shield_model.ApplyYaml(n, w); })
      .Section("demonstrations", [this](const YAML::Node& n,
                                        const std::string& w) { demonstrations.ApplyYaml(n, w); })
      .Section("safe", [this](const YAML::Node& n, const std::string& w) { safe.ApplyYaml(n, w); })
      .Section("near_dangerous", [this](const YAML::Node& n,
                                        const std::string& w) { near_dangerous.ApplyYaml(n, w); })
      .Apply(node, source);
}

nlohmann::json KitchenCuttingDomainOptions::ToJson() const {
  return {{"task", task.ToJson()},
          {"shield_model", shield_model.ToJson()},
          {"demonstrations", demonstrations.ToJson()},
          {"safe", safe.ToJson()},
          {"near_dangerous", near_dangerous.ToJson()}};
}

// ---------------------------------------------------------------------------------------------
KitchenCuttingDomain::KitchenCuttingDomain(experiments::Profile profile)
    : profile_(profile), options_(KitchenCuttingDomainOptions::For(profile)) {}

std::string KitchenCuttingDomain::Describe() const {
  return KitchenCuttingEnv(options_.task, options_.shield_model).Describe();
}

void KitchenCuttingDomain::ApplyYaml(const YAML::Node& node, const std::string& source) {
  options_.ApplyYaml(node, source);
}

std::unique_ptr<Environment> KitchenCuttingDomain::MakeEnvironment() const {
  return std::make_unique<KitchenCuttingEnv>(options_.task, options_.shield_model);
}

experiments::DomainData KitchenCuttingDomain::GenerateData(std::uint64_t data_seed) const {
  options_.Validate();
  KitchenDemonstrationOptions demo_options = options_.demonstrations;
  demo_options.seed = data_seed;
  const KitchenDemonstrations demos = GenerateKitchenDemonstrations(options_.task, demo_options);
  Rng rng(data_seed + 1);
  experiments::DomainData d;
  d.demonstrations = demos.trajectories;
  d.discarded_demonstrations = demos.discarded_dangerous + demos.discarded_failed;
  d.safe = KitchenSafeStates(demos, options_.safe, rng);
  d.near_dangerous = KitchenNearDangerousStates(options_.task, demos, options_.near_dangerous, rng);
  return d;
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
  options_.Validate();
  SECURE_CHECK(max_states >= 1, "label check: max_states = " << max_states << ", must be >= 1");
  KitchenDemonstrationOptions demo_options = options_.demonstrations;
  demo_options.seed = data_seed;
  const KitchenDemonstrations demos = GenerateKitchenDemonstrations(options_.task, demo_options);
  Rng rng(data_seed + 1);
  // The same draws as GenerateData (safe, then near-dangerous).
  const data::StateSet safe = KitchenSafeStates(demos, options_.safe, rng);
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet near =
      KitchenNearDangerousStates(options_.task, demos, options_.near_dangerous, rng, &kinds);
  KitchenLabelCheckOptions check;
  check.max_states = max_states;
  check.velocity_gain = options_.shield_model.velocity_gain;
  std::vector<experiments::LabelCheckRow> rows;
  auto add = [&](const std::string& name, const std::string& label, const data::StateSet& set) {
    const KitchenLabelCheckResult r = CheckKitchenLabels(options_.task, set, check);
    experiments::LabelCheckRow row;
    row.set = name;
    row.label = label;
    row.states = r.states;
    row.dangerous = r.dangerous;
    row.skipped = r.unreachable;
    rows.push_back(row);
  };
  add("safe states", "safe", safe);
  for (NearDangerousScenario k : {NearDangerousScenario::kStroke, NearDangerousScenario::kArm}) {
    std::vector<long> cols;
    for (long i = 0; i < static_cast<long>(kinds.size()); ++i)
      if (kinds[i] == k) cols.push_back(i);
    if (cols.empty()) continue;
    data::StateSet s;
    s.features = near.features;
    s.source = near.source;
    s.states = data::SelectColumns(near.states, cols);
    add(std::string("near-dangerous (") + ScenarioName(k) + ")", "near-dangerous", s);
  }
  return rows;
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

void KitchenCuttingDomain::CheckExperiment(const experiments::ExperimentOptions& options) const {
  SECURE_CHECK_FIELD(std::abs(options.shield.dt - options_.task.control_period) < 1e-12,
                     "ExperimentOptions", "shield.dt", options.shield.dt,
                     "the control period (" << options_.task.control_period
                                            << " s): the shield's model looks one step ahead");
}

experiments::ExperimentOptions KitchenCuttingDomain::Preset() const {
  // 10 seeds x 100 episodes (the paper's own protocol, 10 episodes, is --seeds 1 --episodes 10).
  experiments::ExperimentOptions o =
      franka::ArmExperimentPreset(profile_, options_.task.control_period);
  o.data_seed = 4000;
  // Table 2's knife-cutting barrier: 32-128-128-256-256-256-256-128-128-32, tanh.
  o.flat_barrier.hidden = {32, 128, 128, 256, 256, 256, 256, 128, 128, 32};
  o.flat_barrier.input_features = BarrierFeatures();
  return o;
}

}  // namespace secure::domains::kitchen_cutting

namespace secure::plugins {
void Register_kitchen_cutting(experiments::DomainRegistry& registry) {
  registry.Add("kitchen-cutting",
               "Kitchen cutting: a Franka arm cuts through a line on a board while a simulated "
               "person's arm reaches nearby (MuJoCo; paper Section 7.1 in simulation)",
               [](experiments::Profile p) {
                 return std::make_unique<domains::kitchen_cutting::KitchenCuttingDomain>(p);
               });
}
}  // namespace secure::plugins
