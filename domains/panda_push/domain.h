#pragma once
// Panda Arm Push as an experiments::Domain: the plug-in's face to the generic driver and the CLI.
#include <cstdint>
#include <memory>
#include <string>

#include "domains/franka/arm_data.h"
#include "domains/panda_push/data.h"
#include "domains/panda_push/panda_push.h"
#include "secure/common/yaml_fwd.h"
#include "secure/experiments/experiment.h"

namespace secure::domains::panda_push {

/// Where the barrier's training states come from.
enum class BarrierData { kGenerated, kReleased };

/// The domain's own options (config section "panda_push"): task, shield_model, demonstrations,
/// safe, near_dangerous (franka::ArmDataOptions), and where the barrier's data come from.
struct PandaPushDomainOptions
    : franka::ArmDataOptions<PandaPushOptions, PandaPushShieldModelOptions,
                             PandaDemonstrationOptions, PandaSafeOptions,
                             PandaNearDangerousOptions> {
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
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
};

class PandaPushDomain final
    : public franka::ArmDataDomain<PandaPushDomainOptions, PandaDemonstrations,
                                   NearDangerousScenario> {
 public:
  explicit PandaPushDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "panda-push"; }
  std::string Title() const override { return "Panda Arm Push"; }
  std::string ConfigSection() const override { return "panda_push"; }

  std::unique_ptr<Environment> MakeEnvironment() const override;
  /// barrier_data generated: franka::ArmDataDomain's (the demonstrations from data_seed, the safe
  /// and near-dangerous states from data_seed + 1); released: the same demonstrations, the safe
  /// and near-dangerous states from the released files (with the stream data_seed + 1).
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  experiments::ExperimentOptions Preset() const override;
  /// The paper's experiments on this domain (Section 6), for `secure reproduce`.
  std::vector<std::string> PaperExperiments() const override {
    return {"method-comparison", "ablation", "sensitivity"};
  }

  /// Rows: the safe states; the pushing part of the demonstrations; the near-dangerous states
  /// by scenario (upper part, fast along x, fast along z, both); with released_data_dir set,
  /// the released demonstration and near-dangerous states. See CheckLabels in data.h.
  bool HasLabelCheck() const override { return true; }
  std::vector<experiments::LabelCheckRow> CheckLabels(std::uint64_t data_seed,
                                                      long max_states) const override;
  std::string LabelCheckDescription() const override;

  /// The labeller: the label check's physics per state (LabelStates in data.h): near-dangerous
  /// if continuing the state's motion topples the block, -1 where the arm cannot reach. Query
  /// pool: the default (the generated safe and near-dangerous states).
  bool HasLabeller() const override { return true; }
  std::vector<int> Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                         std::uint64_t seed) const override;
  std::string LabellerDescription() const override {
    return "the label check's physics (secure demos check-labels): " + LabelCheckDescription();
  }

  /// The barrier check (cbf/barrier_check.h):
  ///  - held-out states (franka::ArmDataDomain::CheckHeldOut): our generators (data.h) on new
  ///    demonstrations, drawn from the stream data_seed ^ a salt (the training data's are
  ///    data_seed and data_seed + 1): `count` safe states (PandaSafeStates with the domain's
  ///    copies) and `count` near-dangerous ones (PandaNearDangerousStates, the domain's
  ///    generator); also with barrier_data: released, since the barrier is deployed in this
  ///    simulator;
  ///  - region: a held-out safe or near-dangerous observation (probability 1/2 each) perturbed:
  ///    ee position + N(0, 0.005^2) m and ee velocity + N(0, 0.05^2) m/s per axis, block position
  ///    + N(0, 0.005^2) m, block Euler angles + N(0, 0.02^2) rad, block velocity + N(0, 0.02^2)
  ///    m/s, angular velocity + N(0, 0.05^2) rad/s; ee_z and block_z kept >= 0;
  ///  - unsafe test (c): the block's tilt from upright computed from the observed Euler angles
  ///    beyond task.topple_angle (ObservedBlockTilt; the environment's own dangerous test). The
  ///    region's blocks stand upright (the demonstrations topple nothing, and the noise tilts by
  ///    0.02 rad), so (c) rarely has a state to test: (a) and (b) carry this check;
  ///  - dynamics: the environment's shield model (shield_model: approximate, or the privileged
  ///    rollout, which costs one simulated control period per action the check tries), action box
  ///    [-1, 1]^3, dt and class-K from the shield's options.
  /// The report's pictures (report_hints.cc): the barrier over the end effector's height and
  /// pushing speed; Table 3's Panda Arm Push row.
  std::optional<experiments::ReportHints> MakeReportHints() const override;
  std::optional<experiments::PaperTable3> PaperReference() const override;

 protected:
  franka::ArmCheckSpec CheckSpec() const override;
  /// GeneratePandaDemonstrations, PandaSafeStates, PandaNearDangerousStates (with
  /// ContinuationOptions()) on the options' task.
  Recipe MakeRecipe() const override;

 private:
  // The label check's continuation with this domain's shield-model velocity gain (also the
  // physics of the near-dangerous precursor generator).
  LabelCheckOptions ContinuationOptions() const;
};

/// The barrier's input: the first 9 observation features (ee position, ee velocity, block
/// position), as the paper's Table 2 barrier.
const std::vector<std::string>& BarrierFeatures();

/// The block's tilt from upright (rad) as an observation shows it: the angle between the block's
/// z axis and the world's, acos(cos(roll) cos(pitch)) for R = Rz(yaw) Ry(pitch) Rx(roll)
/// (PandaPushSim::BlockTilt of the observed state).
double ObservedBlockTilt(const Eigen::Ref<const Eigen::VectorXf>& observation);

}  // namespace secure::domains::panda_push
