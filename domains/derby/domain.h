#pragma once
// Demolition Derby as an experiments::Domain (the plug-in's face to the generic driver and the
// CLI): 16 random cars, the privileged CBF-QP expert, the per-car barrier (the released
// architecture), the barrier check's region and collision test.
#include <cstdint>
#include <memory>
#include <string>

#include "domains/derby/derby.h"
#include "domains/derby/expert.h"
#include "secure/cbf/car_barrier.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/options_domain.h"

namespace secure::domains::derby {

/// The domain's own options: the task, the expert and the data generators.
struct DerbyDomainOptions {
  DerbyOptions task;
  DerbyExpertOptions expert;
  DerbyDemonstrationOptions demonstrations;
  DerbyNearDangerousOptions near_dangerous;
  long safe_states = 1024;  // demonstration observations used as the safe class (Table 2)

  /// The paper's protocol, or the small profile.
  static DerbyDomainOptions For(experiments::Profile profile);
  void Validate() const;
  /// Keys: task (DerbyOptions), safe_states, demonstrations {episodes, max_attempts},
  /// near_dangerous {count, nearest, max_redraws}.
  /// ToJson writes exactly these keys, so that ApplyYaml reads it back.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
  YamlFields Fields();
};

class DerbyDomain final : public experiments::OptionsDomain<DerbyDomainOptions> {
 public:
  explicit DerbyDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "derby"; }
  std::string Describe() const override;
  std::string Title() const override { return "Demolition Derby"; }
  std::string ConfigSection() const override { return "derby"; }

  std::unique_ptr<Environment> MakeEnvironment() const override;
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  experiments::ExperimentOptions Preset() const override;
  /// The paper's experiments on this domain (Section 6), for `secure reproduce`.
  std::vector<std::string> PaperExperiments() const override {
    return {"method-comparison", "ablation", "sensitivity", "joint"};
  }

  bool HasCheck() const override { return true; }
  void CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                    data::StateSet* near_dangerous) const override;
  cbf::BarrierCheckProblem MakeCheckProblem(
      const shield::ShieldOptions& shield, const data::StateSet& safe,
      const data::StateSet& near_dangerous,
      std::unique_ptr<DynamicsModel>* dynamics) const override;

  /// The labeller (labeller.cc): near-dangerous iff the nearest observed car is within
  /// LabelDistance() (max of near_dangerous.rho, 0.14) of the ego. Query pool: the default.
  bool HasLabeller() const override { return true; }
  std::vector<int> Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                         std::uint64_t seed) const override;
  std::string LabellerDescription() const override;
  double LabelDistance() const;

  /// The report's pictures (report_hints.cc): the per-car barrier over one car's relative
  /// position, the ego's episodes (ego-relative) with the observed cars; Table 3's Derby row.
  std::optional<experiments::ReportHints> MakeReportHints() const override;
  std::optional<experiments::PaperTable3> PaperReference() const override;
};

/// The barrier check's inputs on Demolition Derby:
///  - dynamics: the shield's model, DerbyShieldModel(task.dt, task.accel_bound,
///    task.lookahead_steps); action box [-accel_bound, accel_bound]^2; dt, class-K and gain from
///    `shield`;
///  - region: a state of `safe` or of `near_dangerous` (each with probability 1/2), perturbed:
///    ego velocity + N(0, 0.1^2) per axis, every observed car's relative position + N(0, 0.03^2)
///    and relative velocity + N(0, 0.05^2) per axis (the goal offset unchanged);
///  - unsafe test (c): some observed car within task.collision_radius of the ego;
///  - (b) and the held-out accuracy: `near_dangerous` and `safe`.
/// `safe` and `near_dangerous` must be observations (kObservationDim rows); the returned problem
/// keeps copies.
cbf::BarrierCheckProblem MakeDerbyCheckProblem(const DerbyOptions& task,
                                               const shield::ShieldOptions& shield,
                                               const data::StateSet& safe,
                                               const data::StateSet& near_dangerous,
                                               std::unique_ptr<DynamicsModel>* dynamics);

/// The check's Derby defaults: cbf::BarrierCheckOptions with 2000 region and 2000 near-dangerous
/// samples (about 1 s per per-car barrier).
cbf::BarrierCheckOptions DerbyCheckDefaults();

/// Where the observed cars sit in the observation (kObservationDim = 52 values): goal - p_ego
/// (2), v_ego (2), then the kObservedCars = 12 nearest cars as blocks of kCarStride = 4 from
/// kFirstCarOffset = 4, each (p_car - p_ego (2), v_car - v_ego (2)). The per-car barrier's input
/// (DerbyDomain::Preset().per_obstacle_barrier.input.layout).
cbf::ObstacleLayout ObstacleLayoutOfObservation();

}  // namespace secure::domains::derby
