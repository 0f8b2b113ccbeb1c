#pragma once
// Panda Arm Push as an experiments::Domain: the plug-in's face to the generic driver and the CLI.
#include <cstdint>
#include <memory>
#include <string>

#include "domains/panda_push/data.h"
#include "domains/panda_push/panda_push.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::domains::panda_push {

/// Where the barrier's training states come from.
enum class BarrierData { kGenerated, kReleased };

/// The domain's own options (config section "panda_push").
struct PandaPushDomainOptions {
  PandaPushOptions task;
  PandaPushShieldModelOptions shield_model;
  PandaDemonstrationOptions demonstrations;
  PandaSafeOptions safe;
  PandaNearDangerousOptions near_dangerous;
  /// generated: safe and near-dangerous states from our demonstrations (data.h); released: from
  /// the authors' released files in released_data_dir (the transfer variant: a barrier learned
  /// from panda-gym's PyBullet data, used in this simulator). The policies always learn from our
  /// demonstrations.
  BarrierData barrier_data = BarrierData::kGenerated;
  std::string released_data_dir;

  /// The paper's protocol, or the small profile.
  static PandaPushDomainOptions For(experiments::Profile profile);
  void Validate() const;
  /// Keys: task, shield_model, demonstrations, safe, near_dangerous (their fields),
  /// barrier_data (generated | released), released_data_dir.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

class PandaPushDomain final : public experiments::Domain {
 public:
  explicit PandaPushDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "panda-push"; }
  std::string Describe() const override;
  std::string Title() const override { return "Panda Arm Push"; }
  std::string ConfigSection() const override { return "panda_push"; }
  void ApplyYaml(const YAML::Node& node, const std::string& source) override;
  void Validate() const override { options_.Validate(); }
  nlohmann::json OptionsJson() const override { return options_.ToJson(); }

  std::unique_ptr<Environment> MakeEnvironment() const override;
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  void CheckExperiment(const experiments::ExperimentOptions& options) const override;
  experiments::ExperimentOptions Preset() const override;

  /// Rows: the safe states; the pushing part of the demonstrations; the near-dangerous states
  /// by scenario (upper part, fast along x, fast along z, both); with released_data_dir set,
  /// the released demonstration and near-dangerous states. See CheckLabels in data.h.
  bool HasLabelCheck() const override { return true; }
  std::vector<experiments::LabelCheckRow> CheckLabels(std::uint64_t data_seed,
                                                      long max_states) const override;
  std::string LabelCheckDescription() const override;

  const PandaPushDomainOptions& options() const { return options_; }
  PandaPushDomainOptions& mutable_options() { return options_; }

 private:
  // The label check's continuation with this domain's shield-model velocity gain (also the
  // physics of the near-dangerous precursor generator).
  LabelCheckOptions ContinuationOptions() const;

  experiments::Profile profile_;
  PandaPushDomainOptions options_;
};

/// The barrier's input: the first 9 observation features (ee position, ee velocity, block
/// position), as the paper's Table 2 barrier.
const std::vector<std::string>& BarrierFeatures();

}  // namespace secure::domains::panda_push
