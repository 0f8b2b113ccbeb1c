#pragma once
// The double-integrator reach-avoid task as an experiments::Domain (the plug-in's face to the
// generic driver and the CLI): exact dynamics, the CBF-QP expert, a flat barrier MLP, the
// analytic ground truth with its validation grid (Table 1), and the barrier check's problem
// (the validation box, the ground truth as the unsafe test, the clipped exact step).
#include <cstdint>
#include <memory>
#include <string>

#include "domains/double_integrator/double_integrator.h"
#include "domains/double_integrator/expert.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/options_domain.h"

namespace secure::domains::double_integrator {

/// The domain's own options: the task, the expert and the data generators.
struct DomainOptions {
  ReachAvoidOptions task;
  ExpertOptions expert;
  DemonstrationOptions demonstrations;
  NearDangerousOptions near_dangerous;
  long safe_states = 20000;  // demonstration states (up to the goal) used as the safe class;
                             // at random if there are more (100 demonstrations hold ~11,000)
  int slowed_copies = 1;     // safe-state augmentation (WithSlowedCopies)
  Grid grid;                 // the validation grid (Table 1)

  /// The paper's protocol, or the small profile.
  static DomainOptions For(experiments::Profile profile);
  void Validate() const;
  /// Keys: task (ReachAvoidOptions), safe_states, slowed_copies, demonstrations {episodes,
  /// stop_at_goal, max_attempts}, near_dangerous {count, rho_min, rho_max, velocity_lo,
  /// velocity_hi}.
  /// ToJson writes exactly these keys, so that ApplyYaml reads it back.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
  YamlFields Fields();
};

class DoubleIntegratorDomain final : public experiments::OptionsDomain<DomainOptions> {
 public:
  explicit DoubleIntegratorDomain(experiments::Profile profile = experiments::Profile::kFull);

  std::string name() const override { return "double-integrator"; }
  std::string Describe() const override;
  std::string Title() const override { return "the double-integrator reach-avoid task"; }
  std::string ConfigSection() const override { return "pipeline"; }

  std::unique_ptr<Environment> MakeEnvironment() const override;
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  experiments::ExperimentOptions Preset() const override;

  std::unique_ptr<cbf::Barrier> MakeGroundTruth() const override;
  std::optional<cbf::StateSource> ValidationGrid() const override;
  // The rest of the ground truth and the shield run: capabilities.cc.
  /// Table 1's sampler: uniform in the state box (StateBox), labelled by task.truth, from the
  /// stream seed ^ a salt (cbf::SampleDoubleIntegratorData).
  experiments::GroundTruthSample SampleGroundTruth(long n_safe, long n_unsafe,
                                                   std::uint64_t seed) const override;
  /// cbf::DoubleIntegratorTrainerPreset() (table1.h).
  cbf::BarrierTrainerOptions GroundTruthTrainerPreset() const override;
  /// {"obstacle": [x, y], "radius": r, "gamma": g} of task.truth.
  nlohmann::json GroundTruthJson() const override;
  std::string GroundTruthSection() const override { return "double_integrator"; }
  /// Table 1 of the paper: 1.9 % (1.0 %) over-, 4.1 % (2.2 %) under-conservative.
  std::optional<experiments::PaperGroundTruthStudy> PaperGroundTruthReference() const override;
  /// The shield run of shield_run.h: a noisy PD policy at the goal past the obstacle, in the
  /// reach-avoid task of the domain's options; the shield's dt is the task's.
  bool HasShieldRun() const override { return true; }
  experiments::ShieldRunRequest ShieldRunPreset() const override;
  experiments::ShieldRunReport RunShield(const experiments::ShieldRunRequest& request,
                                         cbf::Barrier& barrier) const override;

  /// The labeller (labeller.cc): the ground truth, h*(s) >= 0 safe, no noise. The query pool:
  /// uniform in the validation box (StateBox), from the stream seed ^ a salt.
  bool HasLabeller() const override { return true; }
  std::vector<int> Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                         std::uint64_t seed) const override;
  std::string LabellerDescription() const override;
  data::StateSet SampleQueryPool(long count, std::uint64_t seed) const override;

  /// The barrier check (MakeDoubleIntegratorCheckProblem below). Held-out states: `count` safe
  /// (h* >= 0) and `count` unsafe (h* < 0) states drawn uniformly from the validation box
  /// (StateBox) by the ground truth of task.truth, from the stream data_seed ^ a salt (the
  /// training data use data_seed and data_seed + 1).
  bool HasCheck() const override { return true; }
  void CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                    data::StateSet* near_dangerous) const override;
  cbf::BarrierCheckProblem MakeCheckProblem(
      const shield::ShieldOptions& shield, const data::StateSet& safe,
      const data::StateSet& near_dangerous,
      std::unique_ptr<DynamicsModel>* dynamics) const override;

  /// The report's pictures (report_hints.cc): the barrier over (x, y) at three velocities,
  /// the episodes in the box with the obstacle and the goal.
  std::optional<experiments::ReportHints> MakeReportHints() const override;
};

/// The barrier check's inputs on the double integrator:
///  - dynamics: the clipped exact step, ClippedDoubleIntegrator(shield.dt, task.accel_bound)
///    (the environment's own transition when shield.dt = task.dt); action box
///    [-accel_bound, accel_bound]^2; dt, class-K and gain from `shield`;
///  - region: uniform in the validation box (StateBox: x, y in [0, 10), vx, vy in [-1.5, 1.5)),
///    states moved by the local search clamped back into it;
///  - unsafe test (c): the ground truth h*(s) < 0 (task.truth);
///  - (b) and the held-out accuracy: `near_dangerous` and `safe`.
/// `safe` and `near_dangerous` must be states (kStateDim rows); the problem keeps copies.
cbf::BarrierCheckProblem MakeDoubleIntegratorCheckProblem(const ReachAvoidOptions& task,
                                                          const shield::ShieldOptions& shield,
                                                          const data::StateSet& safe,
                                                          const data::StateSet& near_dangerous,
                                                          std::unique_ptr<DynamicsModel>* dynamics);

}  // namespace secure::domains::double_integrator
