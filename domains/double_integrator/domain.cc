#include "domains/double_integrator/domain.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>

#include "domains/double_integrator/ground_truth_barrier.h"
#include "domains/double_integrator/table1.h"
#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fields.h"
#include "secure/experiments/check_problem.h"

namespace secure::domains::double_integrator {
namespace {
// The held-out states of the barrier check come from this stream (data_seed ^ salt), not the
// training data's (data_seed, data_seed + 1).
constexpr std::uint64_t kCheckDataSalt = 0xd1c4ec4a7ULL;
}  // namespace

DomainOptions DomainOptions::For(experiments::Profile profile) {
  DomainOptions o;
  if (profile == experiments::Profile::kQuick) {
    o.demonstrations.episodes = 30;
    o.safe_states = 2000;
    o.near_dangerous.count = 1000;
  }
  return o;
}

void DomainOptions::Validate() const {
  task.Validate();
  expert.Validate();
  demonstrations.Validate();
  near_dangerous.Validate();
  grid.Validate();
  SECURE_CHECK_FIELD(safe_states > 0 && safe_states <= kMaxStates, "DomainOptions",
                     "safe_states", safe_states, "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(slowed_copies >= 0 && slowed_copies <= 100, "DomainOptions",
                     "slowed_copies", slowed_copies, "in [0, 100]");
  SECURE_CHECK_FIELD(safe_states * (1L + slowed_copies) <= kMaxStates, "DomainOptions",
                     "safe_states x (1 + slowed_copies)", safe_states * (1L + slowed_copies),
                     "<= " << kMaxStates);
}

// The keys a config file sets, read and written by one table: the options JSON (OptionsJson, a
// run's record, Python's read_config_section) is read back by ApplyYaml. The expert's fields are
// code constants, recorded by the build's git_sha.
YamlFields DomainOptions::Fields() {
  return YamlFields()
      .Part("task", &task)
      .Field("safe_states", &safe_states)
      .Field("slowed_copies", &slowed_copies)
      .Section("demonstrations", YamlFields()
                                     .Field("episodes", &demonstrations.episodes)
                                     .Field("stop_at_goal", &demonstrations.stop_at_goal)
                                     .Field("max_attempts", &demonstrations.max_attempts))
      .Section("near_dangerous", YamlFields()
                                     .Field("count", &near_dangerous.count)
                                     .Field("rho_min", &near_dangerous.rho_min)
                                     .Field("rho_max", &near_dangerous.rho_max)
                                     .Field("velocity_lo", &near_dangerous.velocity_lo)
                                     .Field("velocity_hi", &near_dangerous.velocity_hi));
}

SECURE_YAML_JSON_FROM_FIELDS(DomainOptions)

// ---------------------------------------------------------------------------------------------
DoubleIntegratorDomain::DoubleIntegratorDomain(experiments::Profile profile)
    : OptionsDomain(profile) {}

std::string DoubleIntegratorDomain::Describe() const {
  return ReachAvoidEnv(options_.task).Describe();
}

std::unique_ptr<Environment> DoubleIntegratorDomain::MakeEnvironment() const {
  return std::make_unique<ReachAvoidEnv>(options_.task);
}

experiments::DomainData DoubleIntegratorDomain::GenerateData(std::uint64_t data_seed) const {
  DemonstrationOptions demo_options = options_.demonstrations;
  demo_options.seed = data_seed;
  const Demonstrations demos = GenerateDemonstrations(options_.task, options_.expert, demo_options);
  Rng rng(data_seed + 1);
  experiments::DomainData d;
  d.demonstrations = demos.trajectories;
  // The safe states: the demonstrations' states on the way to the goal (not the holding at it).
  d.safe = WithSlowedCopies(
      SafeStatesFromDemonstrations(UntilGoal(demos), options_.safe_states, rng),
      options_.slowed_copies, rng);
  d.near_dangerous = GenerateNearDangerous(options_.task, options_.near_dangerous, rng);
  d.discarded_demonstrations = demos.discarded_collisions + demos.discarded_no_goal;
  return d;
}

experiments::ExperimentOptions DoubleIntegratorDomain::Preset() const {
  experiments::ExperimentOptions o;
  o.data_seed = 1000;
  o.barrier_kind = experiments::BarrierKind::kFlat;
  // The barrier settings tuned on the double integrator (table1.h), with larger minibatches for
  // the ~28,000 states here (the preset's 128 is for Table 1's 1,600).
  o.flat_barrier = cbf::DoubleIntegratorTrainerPreset();
  o.flat_barrier.batch_size = 512;
  // Twice the preset's near-dangerous margin (0.05, tuned for Table 1's uniform samples, where
  // it trades conservativeness for accuracy): here the shield needs the barrier's zero level
  // inside the data gap, not at its unsafe edge. Measured: with 0.05 the learned barrier of
  // seed 11 stayed positive on the obstacle's edge for tangential grazing (2 of 100 SECURE
  // episodes touched it); with 0.1, 0.
  o.flat_barrier.unsafe_margin = 0.1;
  o.shield.dt = options_.task.dt;
  if (profile_ == experiments::Profile::kQuick) {
    o.seeds = 2;
    o.episodes = 20;
    o.flat_barrier.max_epochs = 60;
    o.bc.epochs = std::max(1, o.bc.epochs / 4);
    o.airl.iterations = 5;
  }
  return o;
}

std::unique_ptr<cbf::Barrier> DoubleIntegratorDomain::MakeGroundTruth() const {
  return std::make_unique<GroundTruthBarrier>(options_.task.truth);
}

std::optional<cbf::StateSource> DoubleIntegratorDomain::ValidationGrid() const {
  return GridStates(options_.grid);
}

void DoubleIntegratorDomain::CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                                          data::StateSet* near_dangerous) const {
  SECURE_CHECK(count > 0 && count <= kMaxStates,
               "double-integrator barrier check: held-out count = " << count << ", must be in [1, "
                                                                    << kMaxStates << "]");
  options_.task.truth.Validate();
  Rng rng(data_seed ^ kCheckDataSalt);
  LabelledStates l = SampleLabelled(options_.task.truth, StateBox{}, count, count, rng);
  const std::string seed = " (data_seed " + std::to_string(data_seed) + ")";
  *safe = {"held-out safe states: uniform in the validation box, h* >= 0" + seed, StateFeatures(),
           std::move(l.safe)};
  *near_dangerous = {"held-out unsafe states: uniform in the validation box, h* < 0" + seed,
                     StateFeatures(), std::move(l.unsafe)};
}

cbf::BarrierCheckProblem DoubleIntegratorDomain::MakeCheckProblem(
    const shield::ShieldOptions& shield, const data::StateSet& safe,
    const data::StateSet& near_dangerous, std::unique_ptr<DynamicsModel>* dynamics) const {
  return MakeDoubleIntegratorCheckProblem(options_.task, shield, safe, near_dangerous, dynamics);
}

cbf::BarrierCheckProblem MakeDoubleIntegratorCheckProblem(
    const ReachAvoidOptions& task, const shield::ShieldOptions& shield, const data::StateSet& safe,
    const data::StateSet& near_dangerous, std::unique_ptr<DynamicsModel>* dynamics) {
  task.Validate();
  cbf::BarrierCheckProblem p = experiments::CheckProblemBase(
      "double-integrator", kStateDim, kActionDim, task.accel_bound, shield, safe, near_dangerous);
  *dynamics = std::make_unique<ClippedDoubleIntegrator>(shield.dt, task.accel_bound);
  const StateBox box;
  p.sample_region = [box](Rng& rng, Eigen::Ref<Eigen::VectorXf> state) {
    for (int i = 0; i < kStateDim; ++i)
      state[i] = static_cast<float>(rng.Uniform(box.lo[i], box.hi[i]));
  };
  p.project = [box](Eigen::Ref<Eigen::VectorXf> state) {
    for (int i = 0; i < kStateDim; ++i)
      state[i] = std::clamp(state[i], static_cast<float>(box.lo[i]), static_cast<float>(box.hi[i]));
  };
  const GroundTruth truth = task.truth;
  p.is_unsafe = [truth](const Eigen::Ref<const Eigen::VectorXf>& x) {
    return truth.H(x[0], x[1], x[2], x[3]) < 0;
  };
  p.is_unsafe_description = "ground truth h*(s) < 0";
  p.region_description = "the validation box x, y in [0, 10), vx, vy in [-1.5, 1.5)";
  return p;
}

}  // namespace secure::domains::double_integrator

namespace secure::plugins {
void Register_double_integrator(experiments::DomainRegistry& registry) {
  registry.Add<domains::double_integrator::DoubleIntegratorDomain>(
      "double-integrator",
      "a point mass with bounded acceleration reaches a goal past a round obstacle "
      "(paper Section 6, Table 1)");
}
}  // namespace secure::plugins
