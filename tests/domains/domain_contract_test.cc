// The domain contract (experiments/domain.h, domains/environment.h, domains/dynamics.h), checked
// on every registered domain: the plug-ins of the build (secure::plugins: the built-ins under
// domains/ and the example plug-in examples/toy_domain). A new plug-in runs through this suite
// without any change here (docs/ADDING_A_DOMAIN.md). Quick profiles throughout.
//
// Per domain: the registry lists and makes it; its options and preset validate, and its options
// JSON is read back by its ApplyYaml; an episode is
// replayed exactly from the same Rng; a clone is independent; bad actions are rejected; the
// backup action (where claimed) is finite; collisions count entries into danger; the action box
// is the clip of Step(); the shield model has the environment's dimensions and,
// where the environment claims it is exact (ShieldModelIsExact), predicts every step exactly;
// GenerateData is deterministic and gives non-empty finite sets of the environment's dimension;
// the ground truth (where given) has the right dimension, is finite and agrees with the data's
// labels, and its validation grid is well formed.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "tests/domains/domain_contract_util.h"
#include "tests/test_util.h"

namespace secure::test {
namespace {

using experiments::DomainRegistry;
using experiments::Profile;

// One episode's record: observations (including the first), outcomes.
struct Episode {
  std::vector<Eigen::VectorXf> observations;
  std::vector<bool> goal, collided;
  std::vector<int> collisions;

  // One step of `env` with `action` (the observation `o` updated in place), recorded.
  void Step(domains::Environment& env, const Eigen::VectorXf& action, Eigen::VectorXf& o) {
    const domains::StepOutcome out = env.Step(action, o);
    observations.push_back(o);
    goal.push_back(out.reached_goal);
    collided.push_back(out.collided);
    collisions.push_back(out.collisions);
  }
};

// An episode of `env` from Rng(seed) with actions drawn from Rng(action_seed), `steps` steps.
Episode RunEpisode(domains::Environment& env, std::uint64_t seed, std::uint64_t action_seed,
                   int steps) {
  Rng rng(seed), action_rng(action_seed);
  Eigen::VectorXf o(env.observation_dim()), a(env.action_dim());
  Episode e;
  env.Reset(rng, o);
  e.observations.push_back(o);
  for (int t = 0; t < steps; ++t) {
    DrawAction(action_rng, a);
    e.Step(env, a, o);
  }
  return e;
}

void ExpectSameEpisode(const Episode& a, const Episode& b) {
  ASSERT_EQ(a.observations.size(), b.observations.size());
  for (std::size_t t = 0; t < a.observations.size(); ++t)
    ASSERT_EQ(a.observations[t], b.observations[t]) << "step " << t;
  EXPECT_EQ(a.goal, b.goal);
  EXPECT_EQ(a.collided, b.collided);
  EXPECT_EQ(a.collisions, b.collisions);
}

bool SameStates(const data::StateSet& a, const data::StateSet& b) {
  return a.features == b.features && a.states.rows() == b.states.rows() &&
         a.states.cols() == b.states.cols() && a.states == b.states;
}

class DomainContract : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    domain_ = DomainRegistry::Global().Make(GetParam(), Profile::kQuick);
    env_ = domain_->MakeEnvironment();
    ASSERT_NE(env_, nullptr);
    // A short horizon keeps the suite fast; every domain allows max_steps steps after Reset.
    steps_ = std::min(env_->max_steps(), 40);
  }
  std::unique_ptr<experiments::Domain> domain_;
  std::unique_ptr<domains::Environment> env_;
  int steps_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Registry, options, preset

TEST_P(DomainContract, RegistryListsAndMakesIt) {
  const DomainRegistry& registry = DomainRegistry::Global();
  EXPECT_TRUE(registry.Has(GetParam()));
  const std::vector<std::string> names = registry.Names();
  EXPECT_NE(std::find(names.begin(), names.end(), GetParam()), names.end());
  EXPECT_NE(registry.NameList().find(GetParam()), std::string::npos);
  EXPECT_NE(registry.Summaries().find(GetParam()), std::string::npos);
  EXPECT_EQ(domain_->name(), GetParam());
  EXPECT_EQ(registry.Make(GetParam(), Profile::kFull)->name(), GetParam());
  EXPECT_FALSE(domain_->Describe().empty());
  EXPECT_FALSE(domain_->Title().empty());
  EXPECT_FALSE(domain_->ConfigSection().empty());
}

TEST_P(DomainContract, OptionsAndPresetValidateInBothProfiles) {
  for (Profile p : {Profile::kQuick, Profile::kFull}) {
    std::unique_ptr<experiments::Domain> d = DomainRegistry::Global().Make(GetParam(), p);
    EXPECT_NO_THROW(d->Validate());
    EXPECT_TRUE(d->OptionsJson().is_object());
    const experiments::ExperimentOptions o = d->Preset();
    EXPECT_NO_THROW(o.Validate());
    EXPECT_NO_THROW(experiments::CheckExperimentOptions(*d, o));
    EXPECT_TRUE(o.ToJson().is_object());
  }
}

// A domain's options JSON (a run's record, Python's read_config_section, which make_env takes
// back) holds only keys its ApplyYaml reads, and reading it back changes nothing: in both
// profiles, and after a change, so that a value the writer left out would show.
TEST_P(DomainContract, OptionsJsonIsReadBackByApplyYaml) {
  for (Profile p : {Profile::kQuick, Profile::kFull}) {
    const std::unique_ptr<experiments::Domain> d = DomainRegistry::Global().Make(GetParam(), p);
    const nlohmann::json written = d->OptionsJson();
    const std::unique_ptr<experiments::Domain> other =
        DomainRegistry::Global().Make(GetParam(), p == Profile::kQuick ? Profile::kFull
                                                                      : Profile::kQuick);
    ASSERT_NO_THROW(other->ApplyYaml(YAML::Load(written.dump()), "round trip"))
        << GetParam() << ": " << written.dump();
    EXPECT_EQ(other->OptionsJson(), written) << GetParam();
  }
}

// The experiments train their barriers for every epoch (patience 0, the library default, as
// docs/RESULTS.md measured them): early stopping is only `secure cbf train`'s default when it
// trains from files (apps/secure/cbf_commands.cc), and must not reach a preset.
TEST_P(DomainContract, PresetBarrierTrainersDoNotStopEarly) {
  EXPECT_EQ(cbf::BarrierTrainerOptions{}.patience, 0);
  EXPECT_EQ(cbf::CarBarrierTrainerOptions{}.patience, 0);
  for (Profile p : {Profile::kQuick, Profile::kFull}) {
    const experiments::ExperimentOptions o = DomainRegistry::Global().Make(GetParam(), p)->Preset();
    EXPECT_EQ(o.flat_barrier.patience, 0);
    EXPECT_EQ(o.per_obstacle_barrier.patience, 0);
  }
}

// ---------------------------------------------------------------------------------------------
// Environment

TEST_P(DomainContract, EnvironmentDescribesItself) {
  EXPECT_GT(env_->observation_dim(), 0);
  EXPECT_GT(env_->action_dim(), 0);
  EXPECT_EQ(static_cast<int>(env_->ObservationFeatures().size()), env_->observation_dim());
  EXPECT_EQ(static_cast<int>(env_->ActionFeatures().size()), env_->action_dim());
  EXPECT_GT(env_->max_steps(), 0);
  EXPECT_FALSE(env_->Describe().empty());
}

TEST_P(DomainContract, SameRngReplaysTheSameEpisode) {
  const Episode a = RunEpisode(*env_, 11, 12, steps_);
  const Episode b = RunEpisode(*env_, 11, 12, steps_);  // the same environment, reset
  ExpectSameEpisode(a, b);
  std::unique_ptr<domains::Environment> fresh = domain_->MakeEnvironment();
  ExpectSameEpisode(a, RunEpisode(*fresh, 11, 12, steps_));
  for (const Eigen::VectorXf& o : a.observations) ASSERT_TRUE(o.allFinite());
  // Another Rng gives another start.
  const Episode c = RunEpisode(*env_, 13, 12, steps_);
  EXPECT_NE(a.observations.front(), c.observations.front());
}

TEST_P(DomainContract, CloneIsIndependent) {
  const Episode reference = RunEpisode(*env_, 21, 22, steps_);
  std::unique_ptr<domains::Environment> clone = env_->Clone();
  ASSERT_NE(clone, nullptr);
  EXPECT_EQ(clone->observation_dim(), env_->observation_dim());
  EXPECT_EQ(clone->action_dim(), env_->action_dim());
  EXPECT_EQ(clone->max_steps(), env_->max_steps());
  // Interleave the original (same streams as the reference) with the clone (other streams).
  Rng rng(21), action_rng(22), clone_rng(99), clone_actions(98);
  Eigen::VectorXf o(env_->observation_dim()), a(env_->action_dim());
  Eigen::VectorXf co(clone->observation_dim()), ca(clone->action_dim());
  Episode interleaved;
  env_->Reset(rng, o);
  clone->Reset(clone_rng, co);
  interleaved.observations.push_back(o);
  for (int t = 0; t < steps_; ++t) {
    DrawAction(clone_actions, ca);
    clone->Step(ca, co);
    DrawAction(action_rng, a);
    interleaved.Step(*env_, a, o);
  }
  ExpectSameEpisode(reference, interleaved);
  // The clone, run alone, is an environment of its own with the same options.
  ExpectSameEpisode(reference, RunEpisode(*clone, 21, 22, steps_));
}

TEST_P(DomainContract, BadActionsAreRejected) {
  Rng rng(31);
  Eigen::VectorXf o(env_->observation_dim());
  env_->Reset(rng, o);
  Eigen::VectorXf too_long = Eigen::VectorXf::Zero(env_->action_dim() + 1);
  EXPECT_THROW(env_->Step(too_long, o), Error);
  if (env_->action_dim() > 1) {
    Eigen::VectorXf too_short = Eigen::VectorXf::Zero(env_->action_dim() - 1);
    EXPECT_THROW(env_->Step(too_short, o), Error);
  }
  for (float bad :
       {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    for (int i = 0; i < env_->action_dim(); ++i) {
      Eigen::VectorXf a = Eigen::VectorXf::Zero(env_->action_dim());
      a[i] = bad;
      EXPECT_THROW(env_->Step(a, o), Error) << "component " << i << " = " << bad;
    }
  }
  // The shield model rejects mismatched dimensions too.
  const domains::DynamicsModel& model = env_->ShieldModel();
  Eigen::MatrixXf actions = Eigen::MatrixXf::Zero(model.action_dim() + 1, 3);
  Eigen::MatrixXf next(model.state_dim(), 3);
  EXPECT_THROW(model.Step(o, actions, next), Error);
  Eigen::MatrixXf good = Eigen::MatrixXf::Zero(model.action_dim(), 3);
  Eigen::MatrixXf wrong_next(model.state_dim(), 2);
  EXPECT_THROW(model.Step(o, good, wrong_next), Error);
}

TEST_P(DomainContract, BackupActionIsFiniteWhereClaimed) {
  Rng rng(41), action_rng(42);
  Eigen::VectorXf o(env_->observation_dim()), a(env_->action_dim());
  Eigen::VectorXf backup(env_->action_dim());
  env_->Reset(rng, o);
  int claimed = 0;
  for (int t = 0; t < steps_; ++t) {
    backup.setConstant(std::numeric_limits<float>::quiet_NaN());
    if (env_->BackupAction(o, backup)) {
      ++claimed;
      ASSERT_TRUE(backup.allFinite()) << "step " << t << ": " << backup.transpose();
      // Inside the actuator box (a shield with the box rejects a backup outside it).
      Eigen::VectorXf low(env_->action_dim()), high(env_->action_dim());
      env_->ActionBounds(low, high);
      ASSERT_TRUE(((backup.array() >= low.array()) && (backup.array() <= high.array())).all())
          << "step " << t << ": backup " << backup.transpose() << " outside the actuator box";
      ASSERT_NO_THROW(env_->Step(backup, o));  // applicable as an action
    } else {
      DrawAction(action_rng, a);
      env_->Step(a, o);
    }
  }
  // A domain either has a backup action everywhere on this episode or nowhere here.
  EXPECT_TRUE(claimed == 0 || claimed == steps_) << claimed << " of " << steps_;
}

// StepOutcome (environment.h): collided on every step of a contact, collisions = 1 only on the
// step that enters danger, so collisions > 0 implies collided. Random actions, several episodes.
TEST_P(DomainContract, CollisionsCountEntriesIntoDanger) {
  int contact_steps = 0;
  for (std::uint64_t seed = 0; seed < 6; ++seed) {
    const Episode e = RunEpisode(*env_, 61 + seed, 71 + seed, steps_);
    bool before = false;  // no domain starts an episode in danger
    for (std::size_t t = 0; t < e.collided.size(); ++t) {
      contact_steps += e.collided[t];
      const int entered = e.collided[t] && !before ? 1 : 0;
      ASSERT_EQ(e.collisions[t], entered)
          << "seed " << seed << " step " << t << ": collided " << e.collided[t]
          << ", collided before " << before;
      before = e.collided[t];
    }
  }
  RecordProperty("contact_steps", contact_steps);
}

// The driver checks once, for every domain, that the shield looks ahead one control period
// (experiments::CheckExperimentOptions): the preset does; another shield.dt is an error naming
// the field and both values.
TEST_P(DomainContract, ShieldDtMustBeTheControlPeriod) {
  experiments::ExperimentOptions o = domain_->Preset();
  const double period = env_->control_period();
  EXPECT_NEAR(o.shield.dt, period, 1e-12);
  o.shield.dt = 1.5 * period;
  std::ostringstream expected;
  expected << "ExperimentOptions::shield.dt = " << o.shield.dt
           << ", must be the control period of the " << GetParam() << " environment (" << period
           << " s)";
  EXPECT_HAS(ErrorOf([&] { experiments::CheckExperimentOptions(*domain_, o); }), expected.str());
}

// The actuator box (Environment::ActionBounds) is what Step() clips to: an action outside it
// steps exactly as the action clipped to it, in a second environment on the same episode.
TEST_P(DomainContract, ActionBoundsAreTheClipOfStep) {
  const int n = env_->action_dim();
  Eigen::VectorXf low(n), high(n);
  env_->ActionBounds(low, high);
  EXPECT_GT(env_->control_period(), 0.0) << "every registered domain has a control period";
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(std::isfinite(low[i]) && std::isfinite(high[i]))
        << "component " << i << ": [" << low[i] << ", " << high[i] << "]";
    ASSERT_LT(low[i], high[i]) << "component " << i;
  }
  std::unique_ptr<domains::Environment> clipped = domain_->MakeEnvironment();
  Rng rng_a(81), rng_b(81), action_rng(82);
  Eigen::VectorXf oa(env_->observation_dim()), ob(env_->observation_dim());
  Eigen::VectorXf a(n), b(n);
  env_->Reset(rng_a, oa);
  clipped->Reset(rng_b, ob);
  ASSERT_EQ(oa, ob);
  int outside = 0;
  for (int t = 0; t < std::min(steps_, 20); ++t) {
    for (int i = 0; i < n; ++i) {
      const double width = high[i] - low[i];
      a[i] = static_cast<float>(action_rng.Uniform(low[i] - 2 * width, high[i] + 2 * width));
      b[i] = std::clamp(a[i], low[i], high[i]);
      outside += a[i] != b[i];
    }
    const domains::StepOutcome x = env_->Step(a, oa);
    const domains::StepOutcome y = clipped->Step(b, ob);
    ASSERT_EQ(oa, ob) << "step " << t << ": action " << a.transpose() << " vs clipped "
                      << b.transpose();
    ASSERT_EQ(x.collided, y.collided);
    ASSERT_EQ(x.reached_goal, y.reached_goal);
  }
  EXPECT_GT(outside, 0);
}

TEST_P(DomainContract, ShieldModelMatchesTheEnvironmentWhereExact) {
  const domains::DynamicsModel& model = env_->ShieldModel();
  // The shield looks ahead from observations with the policy's actions.
  EXPECT_EQ(model.state_dim(), env_->observation_dim());
  EXPECT_EQ(model.action_dim(), env_->action_dim());
  EXPECT_FALSE(model.Describe().empty());
  Rng rng(51), action_rng(52);
  Eigen::VectorXf o(env_->observation_dim()), a(env_->action_dim());
  Eigen::MatrixXf predicted(model.state_dim(), 1);
  env_->Reset(rng, o);
  for (int t = 0; t < steps_; ++t) {
    DrawAction(action_rng, a);
    model.Step(o, a, predicted);
    ASSERT_TRUE(predicted.allFinite()) << "step " << t;
    env_->Step(a, o);
    if (env_->ShieldModelIsExact()) {
      ASSERT_TRUE((predicted.col(0) - o).norm() <= 1e-6f * (1.0f + o.norm()))
          << "step " << t << ": predicted " << predicted.col(0).transpose() << ", stepped "
          << o.transpose();
    }
  }
  if (!env_->ShieldModelIsExact()) GTEST_SKIP() << GetParam() << " claims no exact shield model";
}

// ---------------------------------------------------------------------------------------------
// Data

// Rendering (secure render): a domain that claims an offscreen renderer draws frames of the size
// asked for without changing the episode; one that does not refuses with "cannot render".
TEST_P(DomainContract, RenderingWhereClaimed) {
  domains::Frame frame;
  if (!env_->CanRender()) {
    Eigen::VectorXf o(env_->observation_dim());
    Rng rng(1);
    env_->Reset(rng, o);
    try {
      env_->Render(64, 48, &frame);
      ADD_FAILURE() << "Render() of a domain that cannot render did not throw";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("cannot render"), std::string::npos) << e.what();
    }
    return;
  }
  const int steps = std::min(steps_, 10);
  const Episode plain = RunEpisode(*env_, 31, 32, steps);
  // The same episode with a frame after the reset and after every step.
  Rng rng(31), action_rng(32);
  Eigen::VectorXf o(env_->observation_dim()), a(env_->action_dim());
  Episode rendered;
  env_->Reset(rng, o);
  rendered.observations.push_back(o);
  for (int t = 0; t <= steps; ++t) {
    const int width = t % 2 == 0 ? 64 : 32, height = t % 2 == 0 ? 48 : 24;
    env_->Render(width, height, &frame);
    ASSERT_EQ(frame.width, width) << "step " << t;
    ASSERT_EQ(frame.height, height) << "step " << t;
    ASSERT_EQ(frame.rgb.size(), 3u * width * height) << "step " << t;
    if (t == steps) break;
    DrawAction(action_rng, a);
    rendered.Step(*env_, a, o);
  }
  ExpectSameEpisode(plain, rendered);
}

TEST_P(DomainContract, GenerateDataIsDeterministicFiniteAndOfTheEnvironmentsDimension) {
  const experiments::DomainData a = domain_->GenerateData(7);
  const experiments::DomainData b = domain_->GenerateData(7);
  const int obs = env_->observation_dim(), act = env_->action_dim();

  const data::TrajectorySet& d = a.demonstrations;
  EXPECT_GT(d.num_episodes(), 0);
  EXPECT_GT(d.num_steps(), 0);
  EXPECT_EQ(d.states.rows(), obs);
  EXPECT_EQ(d.actions.rows(), act);
  EXPECT_EQ(d.actions.cols(), d.states.cols());
  EXPECT_EQ(d.state_features, env_->ObservationFeatures());
  EXPECT_EQ(d.action_features, env_->ActionFeatures());
  ASSERT_FALSE(d.episode_begin.empty());
  EXPECT_EQ(d.episode_begin.front(), 0);
  EXPECT_EQ(d.episode_begin.back(), d.num_steps());
  EXPECT_TRUE(std::is_sorted(d.episode_begin.begin(), d.episode_begin.end()));
  EXPECT_TRUE(d.states.allFinite());
  EXPECT_TRUE(d.actions.allFinite());
  EXPECT_GE(a.discarded_demonstrations, 0);

  for (const data::StateSet* s : {&a.safe, &a.near_dangerous}) {
    EXPECT_EQ(s->dim(), obs) << s->source;
    EXPECT_EQ(s->states.rows(), obs) << s->source;
    EXPECT_NO_THROW(data::CheckNonEmptyFinite(*s, s->source));
  }

  EXPECT_EQ(a.demonstrations.states, b.demonstrations.states);
  EXPECT_EQ(a.demonstrations.actions, b.demonstrations.actions);
  EXPECT_EQ(a.demonstrations.episode_begin, b.demonstrations.episode_begin);
  EXPECT_TRUE(SameStates(a.safe, b.safe));
  EXPECT_TRUE(SameStates(a.near_dangerous, b.near_dangerous));
  EXPECT_EQ(a.discarded_demonstrations, b.discarded_demonstrations);

  const experiments::DomainData c = domain_->GenerateData(8);
  EXPECT_FALSE(SameStates(a.near_dangerous, c.near_dangerous)) << "the seed is ignored";
}

TEST_P(DomainContract, CheckHeldOutWhereGiven) {
  if (!domain_->HasCheck()) GTEST_SKIP() << GetParam() << " has no barrier check";
  data::StateSet safe, nd, safe2, nd2;
  domain_->CheckHeldOut(7, 16, &safe, &nd);
  domain_->CheckHeldOut(7, 16, &safe2, &nd2);
  for (const data::StateSet* s : {&safe, &nd}) {
    EXPECT_EQ(s->states.rows(), env_->observation_dim());
    EXPECT_NO_THROW(data::CheckNonEmptyFinite(*s, s->source));
  }
  EXPECT_TRUE(SameStates(safe, safe2));
  EXPECT_TRUE(SameStates(nd, nd2));
  std::unique_ptr<domains::DynamicsModel> dynamics;
  const cbf::BarrierCheckProblem p =
      domain_->MakeCheckProblem(domain_->Preset().shield, safe, nd, &dynamics);
  ASSERT_NE(dynamics, nullptr);
  EXPECT_EQ(dynamics->state_dim(), env_->observation_dim());
  EXPECT_EQ(p.action_lo.size(), env_->action_dim());
  EXPECT_EQ(p.action_hi.size(), env_->action_dim());
}

TEST_P(DomainContract, GroundTruthWhereGiven) {
  std::unique_ptr<cbf::Barrier> truth = domain_->MakeGroundTruth();
  if (!truth) {
    EXPECT_FALSE(domain_->ValidationGrid().has_value()) << "a grid without a ground truth";
    GTEST_SKIP() << GetParam() << " has no ground truth";
  }
  EXPECT_EQ(truth->state_dim(), env_->observation_dim());
  EXPECT_FALSE(truth->Describe().empty());
  const experiments::DomainData d = domain_->GenerateData(7);
  // The data's labels agree with the ground truth (most states: generators may sample near the
  // boundary).
  Eigen::VectorXf h_safe(d.safe.size()), h_nd(d.near_dangerous.size());
  truth->Evaluate(d.safe.states, h_safe);
  truth->Evaluate(d.near_dangerous.states, h_nd);
  ASSERT_TRUE(h_safe.allFinite());
  ASSERT_TRUE(h_nd.allFinite());
  const double safe_ok = (h_safe.array() >= 0.0f).cast<double>().mean();
  const double nd_ok = (h_nd.array() < 0.0f).cast<double>().mean();
  EXPECT_GE(safe_ok, 0.9) << "safe states with h >= 0";
  EXPECT_GE(nd_ok, 0.9) << "near-dangerous states with h < 0";
  // Deterministic.
  Eigen::VectorXf again(d.safe.size());
  truth->Evaluate(d.safe.states, again);
  EXPECT_EQ(h_safe, again);
  // Wrong dimension rejected.
  Eigen::MatrixXf wrong = Eigen::MatrixXf::Zero(env_->observation_dim() + 1, 2);
  Eigen::VectorXf h2(2);
  EXPECT_THROW(truth->Evaluate(wrong, h2), Error);

  const std::optional<cbf::StateSource> grid = domain_->ValidationGrid();
  if (grid) {
    EXPECT_EQ(grid->state_dim, env_->observation_dim());
    ASSERT_GT(grid->size, 0);
    const long n = std::min<long>(grid->size, 64);
    Eigen::MatrixXf states(grid->state_dim, n);
    grid->fill(grid->size - n, n, states);
    EXPECT_TRUE(states.allFinite());
  }
}

// The ground truth's sampler (cbf train --domain, the ground-truth study): the requested counts,
// labelled by the ground truth, the environment's features, the same states for the same seed.
TEST_P(DomainContract, GroundTruthSamplerWhereGiven) {
  if (!domain_->HasGroundTruth()) {
    EXPECT_THROW(domain_->SampleGroundTruth(10, 10, 0), Error);
    GTEST_SKIP() << GetParam() << " has no ground truth";
  }
  const experiments::GroundTruthSample a = domain_->SampleGroundTruth(50, 30, 4);
  ASSERT_EQ(a.safe.size(), 50);
  ASSERT_EQ(a.unsafe.size(), 30);
  EXPECT_EQ(a.safe.features, env_->ObservationFeatures());
  EXPECT_EQ(a.unsafe.features, env_->ObservationFeatures());
  std::unique_ptr<cbf::Barrier> truth = domain_->MakeGroundTruth();
  Eigen::VectorXf h_safe(50), h_unsafe(30);
  truth->Evaluate(a.safe.states, h_safe);
  truth->Evaluate(a.unsafe.states, h_unsafe);
  EXPECT_TRUE((h_safe.array() >= 0.0f).all());
  EXPECT_TRUE((h_unsafe.array() < 0.0f).all());
  const experiments::GroundTruthSample b = domain_->SampleGroundTruth(50, 30, 4);
  EXPECT_EQ(a.safe.states, b.safe.states);
  EXPECT_NE(a.safe.states, domain_->SampleGroundTruth(50, 30, 5).safe.states);
  EXPECT_NO_THROW(domain_->GroundTruthTrainerPreset().Validate());
}

INSTANTIATE_TEST_SUITE_P(AllRegistered, DomainContract, ::testing::ValuesIn(ContractDomainNames()),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           return ParamName(info.param);
                         });

// ---------------------------------------------------------------------------------------------
// The registry as a whole

TEST(DomainRegistryContract, HoldsTheBuiltInAndTheExamplePlugIns) {
  const std::vector<std::string> names = ContractDomainNames();
  for (const char* n : {"double-integrator", "derby", "toy-cart"})
    EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
  EXPECT_TRUE(std::is_sorted(names.begin(), names.end()));
}

TEST(DomainRegistryContract, UnknownNameIsRejectedListingTheDomains) {
  ContractDomainNames();
  const std::string message =
      ErrorOf([] { DomainRegistry::Global().Make("no-such-domain", Profile::kQuick); });
  EXPECT_NE(message.find("no-such-domain"), std::string::npos) << message;
  for (const std::string& n : DomainRegistry::Global().Names())
    EXPECT_NE(message.find(n), std::string::npos) << message;
}

TEST(DomainRegistryContract, NamesAreUniqueAndWellFormed) {
  ContractDomainNames();
  DomainRegistry& registry = DomainRegistry::Global();
  const auto factory = [](Profile p) {
    return DomainRegistry::Global().Make("double-integrator", p);
  };
  EXPECT_NE(ErrorOf([&] { registry.Add("double-integrator", "again", factory); }).find("twice"),
            std::string::npos);
  EXPECT_THROW(registry.Add("Toy Cart", "bad name", factory), Error);
  // A factory that makes another domain than its name says is caught on Make.
  DomainRegistry local;
  local.Add("mislabelled", "", factory);
  EXPECT_NE(ErrorOf([&] { local.Make("mislabelled"); }).find("made another domain"),
            std::string::npos);
  // RegisterBuiltinDomains is idempotent per registry.
  const std::size_t n = registry.Names().size();
  plugins::RegisterBuiltinDomains(registry);
  EXPECT_EQ(registry.Names().size(), n);
}

}  // namespace
}  // namespace secure::test
