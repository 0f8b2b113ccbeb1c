#include "domains/panda_push/domain.h"
#include "domains/franka/arm_check.h"
#include "domains/franka/arm_preset.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fields.h"
#include "secure/common/yaml_value.h"
#include "secure/shield/shield.h"

namespace secure::domains::panda_push {
namespace {
// The held-out states of the barrier check come from this stream (data_seed ^ salt), not the
// training data's (data_seed, data_seed + 1).
constexpr std::uint64_t kCheckDataSalt = 0x9a4da7c4ecULL;
}  // namespace

const std::vector<std::string>& BarrierFeatures() {
  static const std::vector<std::string> names(ObservationFeatures().begin(),
                                              ObservationFeatures().begin() + 9);
  return names;
}

PandaPushDomainOptions PandaPushDomainOptions::For(experiments::Profile profile) {
  PandaPushDomainOptions o;
  if (profile == experiments::Profile::kQuick) {
    o.demonstrations.episodes = 3;
    o.safe.count = 400;
    o.near_dangerous.count = 400;
  }
  return o;
}

void PandaPushDomainOptions::Validate() const {
  ValidateParts();
  SECURE_CHECK_FIELD(barrier_data != BarrierData::kReleased || !released_data_dir.empty(),
                     "PandaPushDomainOptions", "released_data_dir", "''",
                     "set (the folder of task_demos.csv and near_dangerous_states.csv) with "
                     "barrier_data: released");
}

YamlFields PandaPushDomainOptions::Fields() {
  return AddParts(YamlFields())
      .Section(
          "barrier_data",
          [this](const YAML::Node& n, const std::string& w) {
            const std::string v = YamlValue<std::string>(n, "barrier_data", w);
            SECURE_CHECK(v == "generated" || v == "released",
                         w << ": barrier_data = '" << v << "', must be generated or released");
            barrier_data = v == "released" ? BarrierData::kReleased : BarrierData::kGenerated;
          },
          [this] {
            return nlohmann::json(barrier_data == BarrierData::kReleased ? "released"
                                                                         : "generated");
          })
      .Field("released_data_dir", &released_data_dir);
}

SECURE_YAML_JSON_FROM_FIELDS(PandaPushDomainOptions)

// ---------------------------------------------------------------------------------------------
PandaPushDomain::PandaPushDomain(experiments::Profile profile) : ArmDataDomain(profile) {}

std::unique_ptr<Environment> PandaPushDomain::MakeEnvironment() const {
  return std::make_unique<PandaPushEnv>(options_.task, options_.shield_model);
}

LabelCheckOptions PandaPushDomain::ContinuationOptions() const {
  LabelCheckOptions c;
  c.velocity_gain = options_.shield_model.velocity_gain;
  return c;
}

PandaPushDomain::Recipe PandaPushDomain::MakeRecipe() const {
  Recipe r;
  r.demonstrate = [this](const PandaDemonstrationOptions& o) {
    return GeneratePandaDemonstrations(options_.task, o);
  };
  r.safe = PandaSafeStates;
  r.near_dangerous = [this](const PandaDemonstrations& demos, const PandaNearDangerousOptions& o,
                            Rng& rng, std::vector<NearDangerousScenario>* scenarios) {
    return PandaNearDangerousStates(options_.task, demos, o, ContinuationOptions(), rng, scenarios);
  };
  r.discarded = [](const PandaDemonstrations& d) {
    return d.discarded_toppled + d.discarded_failed;
  };
  r.held_out_salt = kCheckDataSalt;
  return r;
}

experiments::DomainData PandaPushDomain::GenerateData(std::uint64_t data_seed) const {
  if (options_.barrier_data != BarrierData::kReleased)
    return ArmDataDomain::GenerateData(data_seed);
  options_.Validate();
  PandaDemonstrationOptions demo_options = options_.demonstrations;
  demo_options.seed = data_seed;
  const PandaDemonstrations demos = GeneratePandaDemonstrations(options_.task, demo_options);
  Rng rng(data_seed + 1);
  experiments::DomainData d;
  d.demonstrations = demos.trajectories;
  d.discarded_demonstrations = demos.discarded_toppled + demos.discarded_failed;
  ReleasedPandaData released = ReadReleasedPandaData(options_.released_data_dir, options_.safe,
                                                     options_.near_dangerous.count, rng);
  d.safe = std::move(released.safe);
  d.near_dangerous = std::move(released.near_dangerous);
  return d;
}

std::string PandaPushDomain::LabelCheckDescription() const {
  const LabelCheckOptions c;
  std::ostringstream s;
  s << "from each state the push continues at the state's own end-effector velocity for "
    << c.push_distance << " m (at most " << c.push_seconds << " s), ramps down over "
    << c.stop_seconds << " s and holds " << c.hold_seconds
    << " s; dangerous = the block tilts past " << options_.task.topple_angle << " rad";
  return s.str();
}

std::vector<int> PandaPushDomain::Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                        std::uint64_t) const {
  options_.Validate();
  return LabelStates(options_.task, states, ContinuationOptions());
}

std::vector<experiments::LabelCheckRow> PandaPushDomain::CheckLabels(std::uint64_t data_seed,
                                                                     long max_states) const {
  // The same draws as GenerateData (safe, then near-dangerous).
  const Draw draw = LabelCheckDraw(data_seed, max_states);
  const PandaDemonstrations& demos = draw.demos;
  LabelCheckOptions check = ContinuationOptions();
  check.max_states = max_states;
  std::vector<experiments::LabelCheckRow> rows;
  auto add = [&](const std::string& name, const std::string& label, const data::StateSet& set) {
    const LabelCheckResult r = panda_push::CheckLabels(options_.task, set, check);
    rows.push_back(franka::LabelRow(name, label, r.states, r.toppled, r.unreachable));
  };
  add("safe states", "safe", draw.safe);
  std::vector<long> pushing;
  for (long e = 0; e < demos.trajectories.num_episodes(); ++e)
    for (long i = demos.push_begin[e] + 1; i < demos.trajectories.episode_begin[e + 1]; ++i)
      pushing.push_back(i);
  data::StateSet demo_states;
  demo_states.features = ObservationFeatures();
  demo_states.states = demos.trajectories.states;
  add("demonstration states while pushing", "safe", franka::SelectStates(demo_states, pushing));
  franka::AddScenarioRows(draw.near_dangerous, draw.scenarios,
                          {NearDangerousScenario::kUpper, NearDangerousScenario::kFastX,
                           NearDangerousScenario::kFastZ, NearDangerousScenario::kBoth},
                          add);
  if (!options_.released_data_dir.empty()) {
    const ReleasedPandaFiles released = ReadReleasedPandaFiles(options_.released_data_dir);
    data::StateSet released_demos;
    released_demos.features = ObservationFeatures();
    released_demos.states = released.demonstrations.states;
    add("released demonstration states", "safe", released_demos);
    add("released near-dangerous states", "near-dangerous", released.near_dangerous);
  }
  return rows;
}

franka::ArmCheckSpec PandaPushDomain::CheckSpec() const {
  franka::ArmCheckSpec spec;
  spec.perturb = [](Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
    franka::AddNoise(rng, 0.005, kEePos, 3, s);
    franka::AddNoise(rng, 0.05, kEeVel, 3, s);
    franka::AddNoise(rng, 0.005, kBlockPos, 3, s);
    franka::AddNoise(rng, 0.02, kBlockEuler, 3, s);
    franka::AddNoise(rng, 0.02, kBlockVel, 3, s);
    franka::AddNoise(rng, 0.05, kBlockAngVel, 3, s);
  };
  // The end-effector target is kept above the table (panda_push.h), and the block lies on it.
  spec.project = [](Eigen::Ref<Eigen::VectorXf> s) {
    s[kEePos + 2] = std::max(s[kEePos + 2], 0.0f);
    s[kBlockPos + 2] = std::max(s[kBlockPos + 2], 0.0f);
  };
  const double topple = options_.task.topple_angle;
  spec.is_unsafe = [topple](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return ObservedBlockTilt(s) > topple;
  };
  std::ostringstream unsafe;
  unsafe << "the block's observed tilt (from its Euler angles) beyond the topple angle " << topple
         << " rad";
  spec.is_unsafe_description = unsafe.str();
  spec.region_description =
      "held-out safe and near-dangerous observations, perturbed (ee position sd 0.005 m, ee "
      "velocity sd 0.05 m/s, block position sd 0.005 m, Euler angles sd 0.02 rad, velocity sd "
      "0.02 m/s, angular velocity sd 0.05 rad/s)";
  return spec;
}

experiments::ExperimentOptions PandaPushDomain::Preset() const {
  experiments::ExperimentOptions o =
      franka::ArmExperimentPreset(profile_, options_.task.tracking.control_period);
  o.data_seed = 3000;
  // The paper's Table 2 barrier: 32-128-128-256-256-256-256-128-128-32, tanh, on the first 9
  // observation features.
  o.flat_barrier.hidden = {32, 128, 128, 256, 256, 256, 256, 128, 128, 32};
  o.flat_barrier.input_features = BarrierFeatures();
  // The shield returns the policy's mean where it is safe (docs/SHIELD.md, `policy-mean`), and
  // Algorithm 1's mean of the safe samples elsewhere: over 30 seeds +0.7 points of success against
  // Algorithm 1 on the same models, no more topples (docs/RESULTS.md, Panda, "The policy's mean").
  o.shield.aggregation = shield::Aggregation::kPolicyMean;
  // The gradient-first shield and the CBF-QP filter (methods secure-qp, cbf-qp; inert for the
  // sampling shield, whose options JSON does not change): g is nearly a step in the action where
  // the pusher meets the block, so a projection can overshoot to the box's corner. One line-search
  // step, five bisection steps back along an overshooting projection, and sampling where the
  // bisected correction is still longer than 0.5: secure-qp is then within 0.3 points of SECURE's
  // danger and success on both seed sets at 300 episodes per seed, with this model and the
  // learned one (docs/RESULTS.md, Panda, "Bisection back along an overshooting projection").
  // Where the projection still fails, one more round on g's slope over mu +- 2 sigma before
  // sampling (secure-qp only): 0.5-1.1 % of decisions go to sampling instead of 3.0-4.3 % with
  // this model, which keeps p99 under a forward (docs/RESULTS.md, Panda, "A last round on g's
  // slope").
  o.shield.qp_line_search = 1;
  o.shield.qp_bisection = 5;
  o.shield.qp_max_step = 0.5;
  o.shield.qp_smoothing = 2.0;
  // The closed-loop check before deployment (experiments::ClosedLoopCheckOptions: 50 held-out
  // shielded episodes per seed, another initialisation for a seed under 85 % success or over 2 %
  // topples, up to 4). Without it a training seed now and then stalls the arm: with these
  // defaults 1 of 50 seeds measured (30 on a Xeon, 20 on a Zen 5), seed 5 at 39 % on the Zen 5,
  // where the check replaced it (100 %); with the check no seed of 50 fell below 88 % (20 with
  // these defaults, 30 with earlier ones). A passing seed costs 50 episodes (docs/RESULTS.md,
  // Panda, "A stalled seed on a Zen 5"). Off: closed_loop: {enabled: false} or --closed-loop 0.
  // The quick profile (tests, smoke runs) leaves it off.
  if (profile_ == experiments::Profile::kFull) o.closed_loop.enabled = true;
  return o;
}

double ObservedBlockTilt(const Eigen::Ref<const Eigen::VectorXf>& o) {
  SECURE_CHECK(o.size() == kObservationDim, "ObservedBlockTilt: an observation of "
                                                << kObservationDim << " values, got " << o.size());
  const double c = std::cos(double(o[kBlockEuler])) * std::cos(double(o[kBlockEuler + 1]));
  return std::acos(std::clamp(c, -1.0, 1.0));
}

}  // namespace secure::domains::panda_push

namespace secure::plugins {
void Register_panda_push(experiments::DomainRegistry& registry) {
  registry.Add<domains::panda_push::PandaPushDomain>(
      "panda-push",
      "Panda Arm Push: a Franka arm pushes a tall block to a target without toppling it "
      "(MuJoCo; paper Section 6)");
}
}  // namespace secure::plugins
