#pragma once
// Kitchen cutting as an experiments::Domain: the plug-in's face to the generic driver and the CLI.
#include <cstdint>
#include <memory>
#include <string>

#include "domains/kitchen_cutting/data.h"
#include "domains/kitchen_cutting/kitchen_cutting.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::domains::kitchen_cutting {

/// The domain's own options (config section "kitchen_cutting").
struct KitchenCuttingDomainOptions {
  KitchenCuttingOptions task;
  KitchenShieldModelOptions shield_model;
  KitchenDemonstrationOptions demonstrations;
  KitchenSafeOptions safe;
  KitchenNearDangerousOptions near_dangerous;

  /// The paper's data sizes (Table 2), or the small profile.
  static KitchenCuttingDomainOptions For(experiments::Profile profile);
  void Validate() const;
  /// Keys: task, shield_model, demonstrations, safe, near_dangerous (their fields).
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

class KitchenCuttingDomain final : public experiments::Domain {
 public:
  explicit KitchenCuttingDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "kitchen-cutting"; }
  std::string Describe() const override;
  std::string Title() const override { return "Kitchen Cutting"; }
  std::string ConfigSection() const override { return "kitchen_cutting"; }
  void ApplyYaml(const YAML::Node& node, const std::string& source) override;
  void Validate() const override { options_.Validate(); }
  nlohmann::json OptionsJson() const override { return options_.ToJson(); }

  std::unique_ptr<Environment> MakeEnvironment() const override;
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  void CheckExperiment(const experiments::ExperimentOptions& options) const override;
  experiments::ExperimentOptions Preset() const override;

  /// Rows: the safe states, the demonstration states, the near-dangerous states by scenario
  /// (CheckKitchenLabels in data.h).
  bool HasLabelCheck() const override { return true; }
  std::vector<experiments::LabelCheckRow> CheckLabels(std::uint64_t data_seed,
                                                      long max_states) const override;
  std::string LabelCheckDescription() const override;

  /// Table 3's kitchen row: the real robot, 10 episodes (BC 70 / AIRL 80 / SECURE 90 % success,
  /// 100 / 100 / 0 % dangerous; no standard deviations).
  std::optional<experiments::PaperTable3> PaperReference() const override;

  const KitchenCuttingDomainOptions& options() const { return options_; }
  KitchenCuttingDomainOptions& mutable_options() { return options_; }

 private:
  experiments::Profile profile_;
  KitchenCuttingDomainOptions options_;
};

/// The barrier's input: the blade's edge, the end-effector velocity, the person's wrist, elbow
/// and hand tip and the wrist and elbow velocities (21 features; not the cut's progress).
const std::vector<std::string>& BarrierFeatures();

}  // namespace secure::domains::kitchen_cutting
