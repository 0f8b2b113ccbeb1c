#include "domains/derby/domain.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fields.h"
#include "secure/experiments/check_problem.h"

namespace secure::domains::derby {
namespace {
// The held-out states of the barrier check come from this stream (data_seed ^ salt), not the
// training data's (data_seed + 1).
constexpr std::uint64_t kCheckDataSalt = 0xc4ec4da7aULL;
}  // namespace

DerbyDomainOptions DerbyDomainOptions::For(experiments::Profile profile) {
  DerbyDomainOptions o;
  o.near_dangerous.count = 1024;
  // The shield's model holds the action for 3 steps (measured on one seed's AIRL policy and
  // barrier, 100 episodes, dangerous rate: 2 steps 11 %, 3 steps 3 %, 4 steps 38 % -- with 2 the
  // action moves the predicted position by only a dt^2 = 0.03 at the bound; with 4 the
  // prediction jumps past the car). See docs/RESULTS.md.
  o.task.lookahead_steps = 3;
  if (profile == experiments::Profile::kQuick) {
    o.demonstrations.episodes = 60;
    o.safe_states = 512;
    o.near_dangerous.count = 512;
  }
  return o;
}

void DerbyDomainOptions::Validate() const {
  task.Validate();
  expert.Validate();
  demonstrations.Validate();
  near_dangerous.Validate();
  SECURE_CHECK_FIELD(safe_states > 0 && safe_states <= kMaxStates, "DerbyDomainOptions",
                     "safe_states", safe_states, "in [1, " << kMaxStates << "]");
}

// The keys a config file sets, read and written by one table: the options JSON (OptionsJson, a
// run's record, Python's read_config_section) is read back by ApplyYaml. The expert's and the
// near-dangerous generator's other fields are code constants, recorded by the build's git_sha.
YamlFields DerbyDomainOptions::Fields() {
  return YamlFields()
      .Part("task", &task)
      .Field("safe_states", &safe_states)
      .Section("demonstrations", YamlFields()
                                     .Field("episodes", &demonstrations.episodes)
                                     .Field("max_attempts", &demonstrations.max_attempts))
      .Section("near_dangerous", YamlFields()
                                     .Field("count", &near_dangerous.count)
                                     .Field("nearest", &near_dangerous.nearest)
                                     .Field("max_redraws", &near_dangerous.max_redraws));
}

SECURE_YAML_JSON_FROM_FIELDS(DerbyDomainOptions)

// ---------------------------------------------------------------------------------------------
DerbyDomain::DerbyDomain(experiments::Profile profile) : OptionsDomain(profile) {}

std::string DerbyDomain::Describe() const { return DerbyEnv(options_.task).Describe(); }

std::unique_ptr<Environment> DerbyDomain::MakeEnvironment() const {
  return std::make_unique<DerbyEnv>(options_.task);
}

experiments::DomainData DerbyDomain::GenerateData(std::uint64_t data_seed) const {
  DerbyDemonstrationOptions demo_options = options_.demonstrations;
  demo_options.seed = data_seed;
  const DerbyDemonstrations demos =
      GenerateDerbyDemonstrations(options_.task, options_.expert, demo_options);
  Rng rng(data_seed + 1);
  experiments::DomainData d;
  d.demonstrations = demos.trajectories;
  d.safe = SafeStatesFromDemonstrations(demos.trajectories, options_.safe_states, rng);
  d.near_dangerous = GenerateDerbyNearDangerous(options_.task, demos, options_.near_dangerous, rng);
  d.discarded_demonstrations = demos.discarded_collisions + demos.discarded_no_goal;
  return d;
}

void DerbyDomain::CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                               data::StateSet* near_dangerous) const {
  DerbyDemonstrationOptions demo_options = options_.demonstrations;
  demo_options.seed = data_seed;
  const DerbyDemonstrations demos =
      GenerateDerbyDemonstrations(options_.task, options_.expert, demo_options);
  Rng check_rng(data_seed ^ kCheckDataSalt);
  DerbyNearDangerousOptions nd_options = options_.near_dangerous;
  nd_options.count = count;
  *safe = SafeStatesFromDemonstrations(demos.trajectories, count, check_rng);
  *near_dangerous = GenerateDerbyNearDangerous(options_.task, demos, nd_options, check_rng);
  safe->source = "held-out safe states (data_seed " + std::to_string(data_seed) + ")";
  near_dangerous->source =
      "held-out near-dangerous states (data_seed " + std::to_string(data_seed) + ")";
}

cbf::BarrierCheckProblem DerbyDomain::MakeCheckProblem(
    const shield::ShieldOptions& shield, const data::StateSet& safe,
    const data::StateSet& near_dangerous, std::unique_ptr<DynamicsModel>* dynamics) const {
  return MakeDerbyCheckProblem(options_.task, shield, safe, near_dangerous, dynamics);
}

experiments::ExperimentOptions DerbyDomain::Preset() const {
  experiments::ExperimentOptions o;
  o.data_seed = 2000;
  o.barrier_kind = experiments::BarrierKind::kPerObstacle;
  o.per_obstacle_barrier.input.layout = ObstacleLayoutOfObservation();
  // AIRL on 100-step episodes: 40 episodes per iteration.
  o.airl.iterations = 60;
  // AIRL + BC regulariser (AirlOptions::bc_weight). Pure AIRL's PPO leaves the policy's MEAN
  // imprecise where the learned reward is flat: it brakes 0.1-0.2 short of the goal and stalls
  // there, which costs little when actions are sampled but much under the shield, whose average
  // of safe samples is the mean. Measured on 10 seeds, on episodes other than the reported ones
  // (docs/RESULTS.md): SECURE 81.3 -> 88.3 % success, AIRL 91.1 -> 91.5 %.
  o.airl.bc_weight = 1.0;
  // The shield: rho0 = 0.1 (the released code's); alpha dt = 0.2 < 1 (requirement R3; the
  // ablation's secure-myopic shows alpha dt = 1). Cheaper rounds than the released code's
  // M = 64 i.i.d. with N = 64 probes and a sigma step of 0.5 (issue 16, docs/RESULTS.md "The
  // shield's work per decision"): 32 QMC samples, 8 probes and a step of 4 reach the safe
  // actions in fewer and cheaper rounds; on the same models and 10 seeds x 1000 episodes the
  // dangerous rate is equivalent (paired TOST, 2 points; 0.1 against 0.4 %), success higher
  // (89.3 against 86.7 %), and the decision's p99 about a sixth.
  o.shield.num_samples = 32;
  o.shield.sampler = shield::Sampler::kQmc;
  o.shield.num_probes = 8;
  o.shield.sigma_step = 4.0;
  o.shield.safe_ratio = 0.1;
  o.shield.dt = options_.task.dt;
  o.shield.class_k_gain = 2.0;
  o.shield.probe_extent = 1.0;
  o.check = DerbyCheckDefaults();
  if (profile_ == experiments::Profile::kQuick) {
    o.seeds = 2;
    o.episodes = 10;
    o.bc.epochs = std::max(1, o.bc.epochs / 8);
    o.airl.iterations = 2;
    o.airl.steps_per_iteration = 1000;
    o.per_obstacle_barrier.max_epochs = std::max(1, o.per_obstacle_barrier.max_epochs / 4);
    o.flat_barrier.max_epochs = 40;
    o.data_fractions = {1.0, 0.1};
    o.imbalance_ratios = {1, 4};
    o.label_noise = {0.0, 0.3};
  }
  return o;
}

cbf::ObstacleLayout ObstacleLayoutOfObservation() {
  cbf::ObstacleLayout l;
  l.obs_dim = kObservationDim;
  l.first_obstacle_offset = kFirstCarOffset;
  l.obstacle_stride = kCarStride;
  l.num_obstacles = kObservedCars;
  l.position_offset = 0;  // car_dx, car_dy
  l.velocity_offset = 2;  // car_dvx, car_dvy
  return l;
}

cbf::BarrierCheckOptions DerbyCheckDefaults() {
  // The generic defaults with more samples: on the per-car barrier the whole check takes
  // about 1 s per barrier on one core.
  cbf::BarrierCheckOptions c;
  c.region_samples = 2000;
  c.near_samples = 2000;
  return c;
}

cbf::BarrierCheckProblem MakeDerbyCheckProblem(const DerbyOptions& task,
                                               const shield::ShieldOptions& shield_options,
                                               const data::StateSet& safe,
                                               const data::StateSet& near_dangerous,
                                               std::unique_ptr<DynamicsModel>* dynamics) {
  task.Validate();
  cbf::BarrierCheckProblem p = experiments::CheckProblemBase(
      "Derby", kObservationDim, kActionDim, task.accel_bound, shield_options, safe, near_dangerous);
  *dynamics =
      std::make_unique<DerbyShieldModel>(task.dt, task.accel_bound, task.lookahead_steps);
  // The region's noise on a held-out observation: ego velocity, every observed car.
  const auto perturb = [](Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
    s[2] += static_cast<float>(0.1 * rng.Normal());
    s[3] += static_cast<float>(0.1 * rng.Normal());
    for (int c = 0; c < kObservedCars; ++c) {
      const int b = kFirstCarOffset + kCarStride * c;
      s[b] += static_cast<float>(0.03 * rng.Normal());
      s[b + 1] += static_cast<float>(0.03 * rng.Normal());
      s[b + 2] += static_cast<float>(0.05 * rng.Normal());
      s[b + 3] += static_cast<float>(0.05 * rng.Normal());
    }
  };
  p.sample_region = experiments::PerturbedHeldOutRegion(safe, near_dangerous, perturb);
  const double r2 = task.collision_radius * task.collision_radius;
  p.is_unsafe = [r2](const Eigen::Ref<const Eigen::VectorXf>& s) {
    for (int c = 0; c < kObservedCars; ++c) {
      const int b = kFirstCarOffset + kCarStride * c;
      const double dx = s[b], dy = s[b + 1];
      if (dx * dx + dy * dy <= r2) return true;
    }
    return false;
  };
  p.is_unsafe_description =
      "an observed car within the collision radius " + std::to_string(task.collision_radius);
  p.region_description =
      "safe and near-dangerous observations, perturbed (ego velocity sd 0.1, car positions sd "
      "0.03, car velocities sd 0.05)";
  return p;
}

}  // namespace secure::domains::derby

namespace secure::plugins {
void Register_derby(experiments::DomainRegistry& registry) {
  registry.Add<domains::derby::DerbyDomain>(
      "derby", "Demolition Derby: reach a goal among 16 randomly moving cars (paper Section 6)");
}
}  // namespace secure::plugins
