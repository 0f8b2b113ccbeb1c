#include "domains/coffee_placing/domain.h"
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

namespace secure::domains::coffee_placing {
namespace {
// The held-out states of the barrier check come from this stream (data_seed ^ salt), not the
// training data's (data_seed, data_seed + 1).
constexpr std::uint64_t kCheckDataSalt = 0xc0ffc4ec4aULL;
}  // namespace

const std::vector<std::string>& BarrierFeatures() {
  static const std::vector<std::string> names{
      "ee_x",   "ee_y",     "ee_z",     "ee_vx",    "ee_vy",    "ee_vz",
      "tilt",   "wrist_x",  "wrist_y",  "wrist_z",  "hand_x",   "hand_y",
      "hand_z", "wrist_vx", "wrist_vy", "wrist_vz", "clearance"};
  return names;
}

CoffeePlacingDomainOptions CoffeePlacingDomainOptions::For(experiments::Profile profile) {
  CoffeePlacingDomainOptions o;
  if (profile == experiments::Profile::kQuick) {
    o.demonstrations.states = 300;
    o.labels.safe = 200;
    o.labels.unsafe = 200;
  }
  return o;
}

void CoffeePlacingDomainOptions::Validate() const {
  task.Validate();
  shield_model.Validate();
  population.Validate();
  demonstrations.Validate();
  labels.Validate();
  const char* o = "CoffeePlacingDomainOptions";
  shield_model.CheckControlPeriod(o, task.tracking.control_period);
  SECURE_CHECK_FIELD(
      std::isfinite(margin_distance) && margin_distance >= 0 && margin_distance <= 0.5, o,
      "margin_distance", margin_distance, "in [0, 0.5] m");
  SECURE_CHECK_FIELD(std::isfinite(margin_tilt) && margin_tilt >= 0 && margin_tilt <= 0.5, o,
                     "margin_tilt", margin_tilt, "in [0, 0.5] rad");
}

YamlFields CoffeePlacingDomainOptions::Fields() {
  return YamlFields()
      .Part("task", &task)
      .Part("shield_model", &shield_model)
      .Part("population", &population)
      .Part("demonstrations", &demonstrations)
      .Part("labels", &labels)
      .Field("margin_distance", &margin_distance)
      .Field("margin_tilt", &margin_tilt);
}

SECURE_YAML_JSON_FROM_FIELDS(CoffeePlacingDomainOptions)

experiments::DomainData ParticipantData(const CoffeePlacingDomainOptions& options,
                                        const coffee_placing::Participant& participant,
                                        std::uint64_t data_seed) {
  options.Validate();
  const CoffeeDemonstrations demos =
      GenerateCoffeeDemonstrations(options.task, options.demonstrations, participant, data_seed);
  Rng rng(data_seed + 1);
  experiments::DomainData d;
  d.demonstrations = demos.trajectories;
  d.discarded_demonstrations = demos.discarded_violating + demos.discarded_failed;
  CoffeeLabelledStates(options.task, options.labels, participant, demos.trajectories, rng, &d.safe,
                       &d.near_dangerous);
  return d;
}

// ---------------------------------------------------------------------------------------------
// The population

CoffeePopulation::CoffeePopulation(const CoffeePlacingDomainOptions& options,
                                   const experiments::PopulationOptions& population)
    : options_(options) {
  options_.Validate();
  SECURE_CHECK_FIELD(population.participants >= 1 && population.participants <= 1000,
                     "PopulationOptions", "participants", population.participants, "in [1, 1000]");
  SECURE_CHECK_FIELD(std::isfinite(population.threshold_spread) &&
                         population.threshold_spread >= 0 && population.threshold_spread <= 1,
                     "PopulationOptions", "threshold_spread", population.threshold_spread,
                     "in [0, 1]");
  for (int p = 0; p < population.participants; ++p)
    participants_.push_back(
        DrawParticipant(options_.population, population.seed, p, population.threshold_spread));
}

const coffee_placing::Participant& CoffeePopulation::participant(int p) const {
  SECURE_CHECK(p >= 0 && p < size(), "participant " << p << " of " << size());
  return participants_[static_cast<std::size_t>(p)];
}

nlohmann::json CoffeePopulation::Participant(int p) const { return participant(p).ToJson(); }

experiments::DomainData CoffeePopulation::GenerateData(int p, std::uint64_t data_seed) const {
  return ParticipantData(options_, participant(p), data_seed);
}

std::unique_ptr<domains::Environment> CoffeePopulation::MakeEnvironment(int p) const {
  return std::make_unique<CoffeePlacingEnv>(options_.task, options_.shield_model,
                                            participant(p).thresholds);
}

bool CoffeePopulation::HeldWithMargin(int p, const Eigen::Ref<const Eigen::VectorXf>& o) const {
  const Thresholds& t = participant(p).thresholds;
  return o[kClearance] >= t.comfort_distance + options_.margin_distance &&
         std::abs(o[kTilt]) <= t.max_tilt - options_.margin_tilt;
}

std::string CoffeePopulation::Describe() const {
  std::ostringstream s;
  s << "a violation: the robot's hand-and-cup closer to the participant's arm than their comfort "
       "distance, or the cup tilted beyond their maximum tilt; with margin: clearance >= comfort + "
    << options_.margin_distance << " m and |tilt| <= max tilt - " << options_.margin_tilt << " rad";
  return s.str();
}

std::optional<experiments::PaperUserStudy> CoffeePopulation::PaperReference() const {
  experiments::PaperUserStudy t;
  t.source =
      "Table 4, 12 people on the real robot: Likert-scale RATINGS summed over items (higher is "
      "better), not rates; no standard errors";
  t.rows = {{"Task", {73.3, 77.1, 81.6, 73.6}},
            {"Safety", {31.3, 33.3, 35.4, 35.3}},
            {"Perceived safety", {33.2, 35.4, 36.4, 35.8}}};
  return t;
}

// ---------------------------------------------------------------------------------------------
CoffeePlacingDomain::CoffeePlacingDomain(experiments::Profile profile) : ArmDomain(profile) {}

std::unique_ptr<Environment> CoffeePlacingDomain::MakeEnvironment() const {
  return std::make_unique<CoffeePlacingEnv>(options_.task, options_.shield_model,
                                            MeanParticipant(options_.population).thresholds);
}

experiments::DomainData CoffeePlacingDomain::GenerateData(std::uint64_t data_seed) const {
  return ParticipantData(options_, MeanParticipant(options_.population), data_seed);
}

void CoffeePlacingDomain::CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                                       data::StateSet* near_dangerous) const {
  CoffeePlacingDomainOptions o = options_;
  o.labels.safe = count;
  o.labels.unsafe = count;
  experiments::DomainData d =
      ParticipantData(o, MeanParticipant(o.population), data_seed ^ kCheckDataSalt);
  *safe = std::move(d.safe);
  *near_dangerous = std::move(d.near_dangerous);
  franka::MarkHeldOut(data_seed, safe, near_dangerous);
}

franka::ArmCheckSpec CoffeePlacingDomain::CheckSpec() const {
  franka::ArmCheckSpec spec;
  spec.perturb = [](Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
    franka::AddNoise(rng, 0.01, kEePos, 3, s);
    franka::AddNoise(rng, 0.05, kEeVel, 3, s);
    franka::AddNoise(rng, 0.03, kTilt, 1, s);
    for (int k = 0; k < 3; ++k) {
      const float arm = static_cast<float>(0.02 * rng.Normal());
      s[kWrist + k] += arm;
      s[kElbow + k] += arm;
      s[kHandTip + k] += arm;
    }
    franka::AddNoise(rng, 0.05, kWristVel, 3, s);
    franka::AddNoise(rng, 0.05, kElbowVel, 3, s);
  };
  // The tilt's physical bound, and the clearance feature as the observation's positions give it
  // (the shield's model recomputes it so too).
  const PersonOptions person = options_.task.person;
  spec.project = [person](Eigen::Ref<Eigen::VectorXf> s) {
    s[kTilt] = std::clamp(s[kTilt], -static_cast<float>(kMaxTilt), static_cast<float>(kMaxTilt));
    s[kClearance] = static_cast<float>(ObservedClearance(person, s));
  };
  const Thresholds mean = MeanParticipant(options_.population).thresholds;
  spec.is_unsafe = [person, mean](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return mean.Violated(ObservedClearance(person, s), s[kTilt]);
  };
  std::ostringstream unsafe;
  unsafe << "a violation of the mean participant's thresholds: the hand-and-cup within "
         << mean.comfort_distance << " m of the person's arm, or |tilt| > " << mean.max_tilt
         << " rad";
  spec.is_unsafe_description = unsafe.str();
  spec.region_description =
      "held-out safe and unsafe observations, perturbed (ee position sd 0.01 m, ee velocity sd "
      "0.05 m/s, tilt sd 0.03 rad, the person's arm sd 0.02 m, its velocities sd 0.05 m/s; the "
      "clearance recomputed)";
  return spec;
}

std::unique_ptr<experiments::Population> CoffeePlacingDomain::MakePopulation(
    const experiments::PopulationOptions& options) const {
  return std::make_unique<CoffeePopulation>(options_, options);
}

experiments::ExperimentOptions CoffeePlacingDomain::Preset() const {
  experiments::ExperimentOptions o =
      franka::ArmExperimentPreset(profile_, options_.task.tracking.control_period);
  o.data_seed = 5000;
  // Table 2's coffee-placing barrier: FC(64, 64), tanh, on BarrierFeatures().
  o.flat_barrier.hidden = {64, 64};
  o.flat_barrier.input_features = BarrierFeatures();
  // The user study was measured with alpha dt = 0.2 (docs/RESULTS.md); the arm preset's 0.8 has
  // not been tried on this domain.
  o.shield.class_k_gain = 5.0;
  return o;
}

}  // namespace secure::domains::coffee_placing

namespace secure::plugins {
void Register_coffee_placing(experiments::DomainRegistry& registry) {
  registry.Add<domains::coffee_placing::CoffeePlacingDomain>(
      "coffee-placing",
      "Coffee placing: a Franka arm carries a cup to a target square while a simulated "
      "person reaches for a book beside it; twelve simulated participants with their own "
      "comfort distance and cup tilt for the user study (MuJoCo; paper Section 7.2 in "
      "simulation)");
}
}  // namespace secure::plugins
