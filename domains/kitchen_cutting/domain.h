#pragma once
// Kitchen cutting as an experiments::Domain: the plug-in's face to the generic driver and the CLI.
#include <cstdint>
#include <memory>
#include <string>

#include "domains/franka/arm_data.h"
#include "domains/kitchen_cutting/data.h"
#include "domains/kitchen_cutting/kitchen_cutting.h"
#include "secure/common/yaml_fwd.h"
#include "secure/experiments/experiment.h"

namespace secure::domains::kitchen_cutting {

/// The domain's own options (config section "kitchen_cutting"): task, shield_model,
/// demonstrations, safe, near_dangerous (franka::ArmDataOptions).
struct KitchenCuttingDomainOptions
    : franka::ArmDataOptions<KitchenCuttingOptions, KitchenShieldModelOptions,
                             KitchenDemonstrationOptions, KitchenSafeOptions,
                             KitchenNearDangerousOptions> {
  /// The paper's data sizes (Table 2), or the small profile.
  static KitchenCuttingDomainOptions For(experiments::Profile profile);
  void Validate() const;
  /// Keys: task, shield_model, demonstrations, safe, near_dangerous (their fields).
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
};

class KitchenCuttingDomain final
    : public franka::ArmDataDomain<KitchenCuttingDomainOptions, KitchenDemonstrations,
                                   NearDangerousScenario> {
 public:
  explicit KitchenCuttingDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "kitchen-cutting"; }
  std::string Title() const override { return "Kitchen Cutting"; }
  std::string ConfigSection() const override { return "kitchen_cutting"; }

  std::unique_ptr<Environment> MakeEnvironment() const override;
  // GenerateData: franka::ArmDataDomain's (the demonstrations from data_seed, the safe and
  // near-dangerous states from data_seed + 1, by MakeRecipe()'s generators).
  experiments::ExperimentOptions Preset() const override;

  /// Rows: the safe states, the demonstration states, the near-dangerous states by scenario
  /// (CheckKitchenLabels in data.h).
  bool HasLabelCheck() const override { return true; }
  std::vector<experiments::LabelCheckRow> CheckLabels(std::uint64_t data_seed,
                                                      long max_states) const override;
  std::string LabelCheckDescription() const override;

  /// The labeller (labeller.cc): the person's rule that made the near-dangerous states
  /// (JudgeKitchenState in data.h, with near_dangerous.look_ahead): near-dangerous or dangerous
  /// -> 0, safe -> 1, each answer flipped with probability near_dangerous.label_noise (default 0)
  /// from `seed`. Query pool: the default (the generated safe and near-dangerous states).
  bool HasLabeller() const override { return true; }
  std::vector<int> Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                         std::uint64_t seed) const override;
  std::string LabellerDescription() const override;

  /// The barrier check (cbf/barrier_check.h):
  ///  - held-out states (franka::ArmDataDomain::CheckHeldOut): our generators (data.h) on new
  ///    demonstrations (at least `count` states), drawn from the stream data_seed ^ a salt (the
  ///    training data's are data_seed and data_seed + 1): `count` safe states (KitchenSafeStates)
  ///    and `count` near-dangerous ones (KitchenNearDangerousStates);
  ///  - region: a held-out safe or near-dangerous observation (probability 1/2 each) perturbed:
  ///    the end-effector and the blade's edge moved together by N(0, 0.005^2) m per axis (the
  ///    knife is fixed to the hand), ee velocity + N(0, 0.05^2) m/s, the person's wrist, elbow
  ///    and hand tip moved together by N(0, 0.01^2) m per axis, their velocities + N(0, 0.05^2)
  ///    m/s; the cut's progress unchanged; the edge kept at or above the board;
  ///  - unsafe test (c): the environment's dangerous test from the observation
  ///    (ObservedEdgeClearance < task.contact_distance: the blade's edge within contact distance
  ///    of the arm's capsules, the arm from the observed wrist, elbow and hand tip and the fixed
  ///    shoulder);
  ///  - dynamics: the environment's shield model (KitchenShieldModel), action box [-1, 1]^3, dt
  ///    and class-K from the shield's options.
  /// Table 3's kitchen row: the real robot, 10 episodes (BC 70 / AIRL 80 / SECURE 90 % success,
  /// 100 / 100 / 0 % dangerous; no standard deviations).
  std::optional<experiments::PaperTable3> PaperReference() const override;

 protected:
  franka::ArmCheckSpec CheckSpec() const override;
  /// GenerateKitchenDemonstrations (held out: at least `count` states, as KitchenSafeStates
  /// draws them without replacement), KitchenSafeStates, KitchenNearDangerousStates on the
  /// options' task.
  Recipe MakeRecipe() const override;
};

/// The barrier's input: the blade's edge, the end-effector velocity, the person's wrist, elbow
/// and hand tip and the wrist and elbow velocities (21 features; not the cut's progress).
const std::vector<std::string>& BarrierFeatures();

/// The distance (m) from the blade's cutting edge to the person's arm's surface as an observation
/// shows them: the edge (its centre at blade_x/y/z, kBladeHalfLength either side along world x:
/// the hand points down, tool x = world x) to the upper arm (task.human.shoulder to the observed
/// elbow), forearm (elbow to wrist) and hand (wrist to the observed hand tip) capsules
/// (EdgeToArmDistance; < 0 inside). The environment's dangerous test is this < contact_distance
/// (KitchenCuttingSim::Dangerous measures the same with the knife's simulated orientation).
double ObservedEdgeClearance(const KitchenCuttingOptions& task,
                             const Eigen::Ref<const Eigen::VectorXf>& observation);

}  // namespace secure::domains::kitchen_cutting
