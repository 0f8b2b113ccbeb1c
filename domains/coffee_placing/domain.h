#pragma once
// Coffee placing as an experiments::Domain (the plug-in's face to the generic driver and the
// CLI), with the participants of the user study (experiments::Population).
#include <cstdint>
#include <memory>
#include <string>

#include "domains/coffee_placing/coffee_placing.h"
#include "domains/coffee_placing/participants.h"
#include "domains/franka/arm_domain.h"
#include "secure/common/yaml_fwd.h"
#include "secure/experiments/experiment.h"

namespace secure::domains::coffee_placing {

/// The domain's own options (config section "coffee_placing").
struct CoffeePlacingDomainOptions {
  CoffeePlacingOptions task;
  CoffeeShieldModelOptions shield_model;
  PopulationRanges population;
  CoffeeDemonstrationOptions demonstrations;
  CoffeeLabelOptions labels;
  // Over-conservativeness: a participant's thresholds hold "with margin" when the clearance is
  // at least comfort_distance + margin_distance and |tilt| at most max_tilt - margin_tilt.
  double margin_distance = 0.05;  // m
  double margin_tilt = 0.05;      // rad

  /// The paper's data sizes (Table 2), or the small profile.
  static CoffeePlacingDomainOptions For(experiments::Profile profile);
  void Validate() const;
  /// Keys: task, shield_model, population, demonstrations, labels (their fields),
  /// margin_distance, margin_tilt.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
};

/// The participants drawn from the domain's ranges (participants.h).
class CoffeePopulation final : public experiments::Population {
 public:
  CoffeePopulation(const CoffeePlacingDomainOptions& options,
                   const experiments::PopulationOptions& population);
  int size() const override { return static_cast<int>(participants_.size()); }
  nlohmann::json Participant(int p) const override;
  experiments::DomainData GenerateData(int p, std::uint64_t data_seed) const override;
  std::unique_ptr<domains::Environment> MakeEnvironment(int p) const override;
  bool HeldWithMargin(int p, const Eigen::Ref<const Eigen::VectorXf>& observation) const override;
  std::string Describe() const override;
  double StepSeconds() const override { return options_.task.tracking.control_period; }
  /// Table 4 (Likert ratings, not rates).
  std::optional<experiments::PaperUserStudy> PaperReference() const override;

  const coffee_placing::Participant& participant(int p) const;

 private:
  CoffeePlacingDomainOptions options_;
  std::vector<coffee_placing::Participant> participants_;
};

class CoffeePlacingDomain final : public franka::ArmDomain<CoffeePlacingDomainOptions> {
 public:
  explicit CoffeePlacingDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "coffee-placing"; }
  std::string Title() const override { return "Coffee Placing"; }
  std::string ConfigSection() const override { return "coffee_placing"; }

  /// The environment judged by the mean participant (MeanParticipant: every constant at the
  /// middle of its range).
  std::unique_ptr<Environment> MakeEnvironment() const override;
  /// The mean participant's data.
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  experiments::ExperimentOptions Preset() const override;

  /// The barrier check (cbf/barrier_check.h), judged by the mean participant (as
  /// MakeEnvironment and GenerateData):
  ///  - held-out states: the mean participant's data (ParticipantData) from the stream
  ///    data_seed ^ a salt (the training data's are data_seed and data_seed + 1), `count` safe
  ///    and `count` unsafe (their violations, with their label noise);
  ///  - region: a held-out safe or unsafe observation (probability 1/2 each) perturbed: ee
  ///    position + N(0, 0.01^2) m and ee velocity + N(0, 0.05^2) m/s per axis, tilt +
  ///    N(0, 0.03^2) rad (kept within +-kMaxTilt), the person's wrist, elbow and hand tip moved
  ///    together by N(0, 0.02^2) m per axis, their velocities + N(0, 0.05^2) m/s; the clearance
  ///    feature recomputed from the perturbed positions (ObservedClearance), also after every
  ///    local-search move;
  ///  - unsafe test (c): a violation of the mean participant's thresholds (Thresholds::Violated
  ///    on ObservedClearance and the tilt: the environment's dangerous test);
  ///  - dynamics: the environment's shield model (CoffeeShieldModel), action box [-1, 1]^4, dt
  ///    and class-K from the shield's options.
  void CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                    data::StateSet* near_dangerous) const override;

  /// The labeller (labeller.cc): the mean participant, the person of GenerateData
  /// (ParticipantAnswersUnsafe in participants.h): unsafe (a violation of their comfort
  /// distance or maximum tilt, the clearance recomputed from the positions) -> 0, else 1, each
  /// answer flipped with their label noise (population.label_noise's middle, 0.03) from `seed`.
  /// Query pool: the default (the generated safe and unsafe states).
  bool HasLabeller() const override { return true; }
  std::vector<int> Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                         std::uint64_t seed) const override;
  std::string LabellerDescription() const override;

  bool HasPopulation() const override { return true; }
  std::unique_ptr<experiments::Population> MakePopulation(
      const experiments::PopulationOptions& options) const override;

 protected:
  franka::ArmCheckSpec CheckSpec() const override;
};

/// The barrier's input: the end-effector position and velocity, the cup's tilt, the person's
/// wrist and hand tip, the wrist velocity and the clearance (17 features).
const std::vector<std::string>& BarrierFeatures();

/// A participant's data (GenerateData of the population and of the domain): demonstrations from
/// `data_seed`, labelled states from data_seed + 1.
experiments::DomainData ParticipantData(const CoffeePlacingDomainOptions& options,
                                        const coffee_placing::Participant& participant,
                                        std::uint64_t data_seed);

}  // namespace secure::domains::coffee_placing
