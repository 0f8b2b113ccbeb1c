// The top-level AIRL loop and the public API; the parts of an iteration are in internal/.
#include "secure/policy/airl_trainer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "secure/cbf/differentiable_barrier.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/progress.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/common/timer.h"
#include "secure/nn/model_file.h"
#include "secure/policy/bc_trainer.h"
#include "secure/policy/internal/airl_checkpoint.h"
#include "secure/policy/internal/airl_discriminator.h"
#include "secure/policy/internal/airl_ppo.h"
#include "secure/policy/internal/airl_rollout.h"
#include "secure/policy/internal/joint_cbf_term.h"
#include "secure/policy/internal/torch_policy.h"

namespace secure::policy {
namespace {

// Seeds of the parts of a run (internal::DeriveSeed salts).
enum Salt : std::uint64_t {
  kPolicyInit = 1,
  kValueInit = 2,
  kRewardInit = 3,
  kShapingInit = 4,
  kExpertSubset = 5,
  kIterationBase = 1000,  // + iteration (0-based)
};

// The summary as recorded in the model file's provenance: without timing (wall-clock seconds
// and rates) and without how the run was split (resumed, start iteration, checkpoints written),
// so that identical runs write identical model files, whether or not they were interrupted and
// resumed. Both stay in AirlSummary::ToJson() (the --json output) and BriefReport().
nlohmann::json ModelFileSummary(const AirlSummary& s) {
  nlohmann::json j = nn::WithoutTiming(s.ToJson());
  for (const char* key : {"resumed", "start_iteration", "checkpoints_written"}) j.erase(key);
  return j;
}

// The options as recorded in the model file's provenance: without run control (where the
// curve and checkpoints went, how often, whether this invocation resumed, verbosity), which
// does not change the model.
nlohmann::json ModelFileOptions(const AirlOptions& o) {
  nlohmann::json j = o.ToJson();
  for (const char* key : {"curve_path", "checkpoint_path", "checkpoint_every", "resume", "verbose"})
    j.erase(key);
  return j;
}

// Columns of the learning-curve CSV.
std::string CurveCsv(const std::vector<AirlIterationStats>& rows) {
  std::string out = Join(AirlIterationStats::Columns(), ",") + "\n";
  char buf[64];
  for (const auto& row : rows) {
    const auto values = row.Values();
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (i > 0) out += ',';
      if (i < 3) {
        std::snprintf(buf, sizeof buf, "%ld", static_cast<long>(values[i]));
      } else if (std::isfinite(values[i])) {
        std::snprintf(buf, sizeof buf, "%.9g", values[i]);
      } else {
        buf[0] = '\0';
      }
      out += buf;
    }
    out += '\n';
  }
  return out;
}

nn::MlpSpec SpecOf(int input_dim, const std::vector<int>& hidden, int output_dim,
                   nn::Activation activation) {
  nn::MlpSpec spec;
  spec.input_dim = input_dim;
  spec.hidden = hidden;
  spec.output_dim = output_dim;
  spec.activation = activation;
  return spec;
}

nlohmann::json SpecJson(const nn::MlpSpec& spec) {
  return {{"input_dim", spec.input_dim},
          {"hidden", spec.hidden},
          {"output_dim", spec.output_dim},
          {"activation", ToString(nn::kActivationNames, spec.activation)}};
}

// One AIRL run: the state that a checkpoint holds, and the steps of an iteration (rollout:
// internal/airl_rollout.h, discriminator: internal/airl_discriminator.h, PPO and the reward:
// internal/airl_ppo.h, the joint term: internal/joint_cbf_term.h, the file:
// internal/airl_checkpoint.h).
class AirlRun {
 public:
  AirlRun(const AirlOptions& options, const data::TrajectorySet& demos,
          const domains::Environment& env, const GaussianPolicy* warm_start)
      : o_(options), demos_(demos), horizon_(env.max_steps()), expert_(demos) {
    obs_dim_ = env.observation_dim();
    act_dim_ = env.action_dim();
    episodes_ = (o_.steps_per_iteration + horizon_ - 1) / horizon_;
    env_description_ = env.Describe();
    observation_features_ = env.ObservationFeatures();
    action_features_ = env.ActionFeatures();
    for (int e = 0; e < episodes_; ++e) envs_.push_back(env.Clone());

    // Policy: warm start (architecture, normaliser and log sigma kept) or fresh.
    nn::MlpParams mean_params;
    Eigen::VectorXf log_std;
    if (warm_start != nullptr) {
      warm_start->Validate("AIRL warm start");
      warm_start->CheckFeatures(env.ObservationFeatures(), env.ActionFeatures(),
                                "the environment (" + env_description_ + ")");
      normalizer_ = warm_start->input;
      input_features_ = warm_start->input_features;
      input_rows_ = warm_start->InputRows();
      mean_params = warm_start->mean;
      log_std = warm_start->log_std.cwiseMax(static_cast<float>(o_.min_log_std));
      warm_started_ = true;
    } else {
      normalizer_ = nn::Normalizer::Fit(demos.states);
      mean_params = internal::InitialParams(
          SpecOf(obs_dim_, o_.policy_hidden, act_dim_, nn::Activation::kTanh),
          internal::DeriveSeed(o_.seed, kPolicyInit), /*last_layer_scale=*/0.01,
          /*zero_last_bias=*/true);
      log_std = Eigen::VectorXf::Constant(act_dim_, static_cast<float>(o_.init_log_std));
    }
    policy_spec_ = mean_params.spec;
    const int in_dim = mean_params.spec.input_dim;  // the networks read the policy's inputs
    policy_ = internal::TorchGaussian(mean_params, log_std, o_.min_log_std);
    value_ = nn::TorchMlp(SpecOf(in_dim, o_.value_hidden, 1, nn::Activation::kTanh));
    value_->LoadParams(
        internal::InitialParams(value_->spec(), internal::DeriveSeed(o_.seed, kValueInit)));
    disc_ = internal::AirlDiscriminator(
        internal::InitialParams(SpecOf(in_dim, o_.reward_hidden, 1, nn::Activation::kRelu),
                                internal::DeriveSeed(o_.seed, kRewardInit)),
        internal::InitialParams(SpecOf(in_dim, o_.shaping_hidden, 1, nn::Activation::kRelu),
                                internal::DeriveSeed(o_.seed, kShapingInit)),
        o_.discriminator_discount);
    policy_opt_ = std::make_unique<torch::optim::Adam>(policy_->parameters(),
                                                       torch::optim::AdamOptions(o_.policy_lr));
    value_opt_ = std::make_unique<torch::optim::Adam>(value_->parameters(),
                                                      torch::optim::AdamOptions(o_.value_lr));
    disc_opt_ = std::make_unique<torch::optim::Adam>(
        disc_->parameters(), torch::optim::AdamOptions(o_.discriminator_lr));

    expert_.Build(normalizer_, input_rows_, internal::DeriveSeed(o_.seed, kExpertSubset));
    rollout_.Resize(obs_dim_, act_dim_, static_cast<long>(episodes_) * horizon_);
  }

  void SetJoint(internal::JointCbfTerm* joint) { joint_ = joint; }
  double JointLoss() const { return joint_ != nullptr ? joint_->MeanLoss() : 0.0; }

  int episodes() const { return episodes_; }
  int horizon() const { return horizon_; }
  long expert_count() const { return expert_.count(); }
  bool warm_started() const { return warm_started_; }
  int completed() const { return completed_; }
  long env_steps() const { return env_steps_; }
  const std::vector<AirlIterationStats>& history() const { return history_; }
  double previous_seconds() const { return previous_seconds_; }

  GaussianPolicy Policy() {
    GaussianPolicy p = policy_->Export(normalizer_);
    p.observation_features = observation_features_;
    p.input_features = input_features_;
    p.action_features = action_features_;
    return p;
  }

  // The discriminator's reward and shaping networks, for the shield's task value.
  AirlRewardModel RewardModel() {
    AirlRewardModel m;
    m.reward = disc_->reward->ToParams();
    m.shaping = disc_->shaping->ToParams();
    m.input = normalizer_;
    m.discount = o_.gamma;
    m.observation_features = observation_features_;
    m.input_features = input_features_;
    return m;
  }

  // One iteration: rollout, discriminator, rewards, PPO.
  AirlIterationStats Iterate(AirlSummary& timing) {
    Rng iteration_rng(internal::DeriveSeed(o_.seed, kIterationBase + completed_));
    Rng rollout_rng = iteration_rng.Split();
    Rng disc_rng = iteration_rng.Split();
    Rng ppo_rng = iteration_rng.Split();
    AirlIterationStats stats;
    stats.iteration = completed_ + 1;

    Stopwatch watch;
    internal::CollectRollout(Policy(), envs_, horizon_, o_.absorbing_goal, rollout_rng, rollout_,
                             stats);
    timing.rollout_seconds += watch.Seconds();

    watch.Restart();
    const torch::Tensor x =
        nn::ToTensor(normalizer_.Apply(PolicyInputs(rollout_.obs, input_rows_)));
    const torch::Tensor x_next =
        nn::ToTensor(normalizer_.Apply(PolicyInputs(rollout_.next_obs, input_rows_)));
    const torch::Tensor a = nn::ToTensor(rollout_.actions);
    if (static_cast<long>(rollout_.live.size()) == rollout_.obs.cols()) {
      internal::UpdateDiscriminator(o_, disc_, *disc_opt_, policy_, expert_, x, x_next, a, disc_rng,
                                    stats);
    } else {  // absorbing_goal froze some steps: the discriminator sees those before the goal
      SECURE_CHECK(
          !rollout_.live.empty(),
          "AIRL with absorbing_goal: every rollout episode reached the goal in its first "
          "step, so the discriminator has no policy transition (the starts lie in the goal)");
      const torch::Tensor live =
          torch::from_blob(rollout_.live.data(), {static_cast<long>(rollout_.live.size())},
                           torch::kLong)
              .clone();
      internal::UpdateDiscriminator(o_, disc_, *disc_opt_, policy_, expert_,
                                    x.index_select(0, live), x_next.index_select(0, live),
                                    a.index_select(0, live), disc_rng, stats);
    }
    timing.discriminator_seconds += watch.Seconds();

    watch.Restart();
    if (joint_ != nullptr) joint_->Prepare(rollout_.obs, act_dim_);
    internal::PpoUpdate(o_, episodes_, horizon_, Modules(), expert_, joint_, reward_stat_, x,
                        x_next, a, ppo_rng, stats);
    timing.ppo_seconds += watch.Seconds();

    ++completed_;
    env_steps_ += static_cast<long>(episodes_) * horizon_;
    stats.env_steps = env_steps_;
    return stats;
  }

  void Record(const AirlIterationStats& stats) { history_.push_back(stats); }

  // ---- checkpoints ----

  nlohmann::json Meta() const {
    nlohmann::json rows = nlohmann::json::array();
    for (const auto& s : history_) rows.push_back(s.ToJson());
    return {{"format", internal::kCheckpointFormat},
            {"version", internal::kCheckpointVersion},
            {"completed_iterations", completed_},
            {"env_steps", env_steps_},
            {"options", internal::TrainingShapingOptions(o_)},
            {"demonstrations_fingerprint", std::to_string(internal::Fingerprint(demos_))},
            {"environment", env_description_},
            {"horizon", horizon_},
            {"episodes_per_iteration", episodes_},
            {"policy_spec", PolicySpecJson()},
            {"warm_started", warm_started_},
            {"joint", joint_ != nullptr ? joint_->options().ToJson() : nlohmann::json(nullptr)},
            {"reward_stat", {reward_stat_.count, reward_stat_.mean, reward_stat_.m2}},
            {"curve", rows}};
  }

  void SaveCheckpoint(const std::string& path, double seconds) {
    nlohmann::json meta = Meta();
    meta["seconds"] = seconds;
    internal::SaveCheckpoint(path, Modules(), meta);
  }

  // Restores everything from `path`; throws naming the file and the first mismatch.
  void LoadCheckpoint(const std::string& path) {
    const nlohmann::json meta = internal::LoadCheckpoint(path, Modules(), Meta());
    // The expert tensors depend on the normaliser (the same unless a different warm start).
    expert_.Build(normalizer_, input_rows_, internal::DeriveSeed(o_.seed, kExpertSubset));
    completed_ = meta.at("completed_iterations").get<int>();
    env_steps_ = meta.at("env_steps").get<long>();
    const auto& rs = meta.at("reward_stat");
    reward_stat_ = {rs.at(0).get<double>(), rs.at(1).get<double>(), rs.at(2).get<double>()};
    history_.clear();
    for (const auto& row : meta.at("curve")) history_.push_back(internal::StatsFromJson(row));
    previous_seconds_ = meta.value("seconds", 0.0);
  }

 private:
  // The input features only when they are a subset, so that older checkpoints still resume.
  nlohmann::json PolicySpecJson() const {
    nlohmann::json spec = SpecJson(policy_spec_);
    if (!input_features_.empty()) spec["input_features"] = input_features_;
    return spec;
  }

  internal::CheckpointModules Modules() {
    return {{policy_, value_, disc_, *policy_opt_, *value_opt_}, *disc_opt_, normalizer_};
  }

  const AirlOptions& o_;
  const data::TrajectorySet& demos_;
  int horizon_ = 0, episodes_ = 0, obs_dim_ = 0, act_dim_ = 0;
  std::string env_description_;
  std::vector<std::string> observation_features_, action_features_;
  std::vector<std::string> input_features_;  // the warm start's; empty: all
  std::vector<int> input_rows_;
  std::vector<std::unique_ptr<domains::Environment>> envs_;
  internal::ExpertTransitions expert_;
  bool warm_started_ = false;
  nn::Normalizer normalizer_;
  nn::MlpSpec policy_spec_;
  internal::TorchGaussian policy_{nullptr};
  nn::TorchMlp value_{nullptr};
  internal::AirlDiscriminator disc_{nullptr};
  std::unique_ptr<torch::optim::Adam> policy_opt_, value_opt_, disc_opt_;
  internal::RolloutBuffer rollout_;
  internal::RunningStat reward_stat_;
  int completed_ = 0;
  long env_steps_ = 0;
  std::vector<AirlIterationStats> history_;
  double previous_seconds_ = 0.0;
  internal::JointCbfTerm* joint_ = nullptr;  // TrainAirlJoint only
};

void CheckInputs(const data::TrajectorySet& demos, const domains::Environment& env) {
  CheckDemos(demos, 2);
  SECURE_CHECK(env.max_steps() > 0,
               "AIRL: the environment's max_steps() = " << env.max_steps() << ", must be > 0");
  SECURE_CHECK(env.observation_dim() == static_cast<int>(env.ObservationFeatures().size()) &&
                   env.action_dim() == static_cast<int>(env.ActionFeatures().size()),
               "AIRL: the environment (" << env.Describe()
                                         << ") has feature lists that do not match its dimensions");
  SECURE_CHECK(demos.state_features == env.ObservationFeatures(),
               "demonstrations (" << demos.source << ") have state features ("
                                  << Join(demos.state_features) << "); the environment ("
                                  << env.Describe() << ") observes ("
                                  << Join(env.ObservationFeatures()) << ")");
  SECURE_CHECK(demos.action_features == env.ActionFeatures(),
               "demonstrations (" << demos.source << ") have action features ("
                                  << Join(demos.action_features) << "); the environment ("
                                  << env.Describe() << ") takes (" << Join(env.ActionFeatures())
                                  << ")");
}

GaussianPolicy TrainAirlImpl(const AirlOptions& options, const data::TrajectorySet& demos,
                             const domains::Environment& env, const GaussianPolicy* warm_start,
                             AirlSummary* summary, const AirlCallback& callback,
                             internal::JointCbfTerm* joint, AirlRewardModel* reward_model) {
  options.Validate();
  CheckInputs(demos, env);
  const Stopwatch clock;
  AirlRun run(options, demos, env, warm_start);
  run.SetJoint(joint);

  AirlSummary s;
  s.horizon = run.horizon();
  s.episodes_per_iteration = run.episodes();
  s.steps_per_iteration = run.episodes() * run.horizon();
  s.expert_transitions = run.expert_count();
  s.warm_started = run.warm_started();
  if (options.resume && std::filesystem::exists(options.checkpoint_path)) {
    run.LoadCheckpoint(options.checkpoint_path);
    // A run cannot be shortened; with as many iterations as completed, the checkpoint's policy
    // is returned without training.
    SECURE_CHECK(run.completed() <= options.iterations,
                 options.checkpoint_path
                     << ": checkpoint has " << run.completed()
                     << " completed iterations, more than iterations = " << options.iterations
                     << " (AirlOptions::iterations, --iterations): a run cannot be shortened; "
                        "resume with iterations >= "
                     << run.completed() << ", or start afresh without resume");
    s.resumed = true;
    if (options.verbose)
      PrintStatusLineF("[airl] resumed from %s at iteration %d\n", options.checkpoint_path.c_str(),
                       run.completed());
  }
  s.start_iteration = run.completed();
  const double previous_seconds = run.previous_seconds();
  auto total_seconds = [&] { return previous_seconds + clock.Seconds(); };

  if (!options.curve_path.empty())
    CreateDirectories(std::filesystem::path(options.curve_path).parent_path().string());
  s.stop_reason = "iterations";
  double last_report = -1e9;
  const bool stop_now =
      options.stop_after_iterations > 0 && run.completed() >= options.stop_after_iterations;
  if (stop_now) s.stop_reason = "stop_after_iterations";
  while (!stop_now && run.completed() < options.iterations) {
    AirlIterationStats stats = run.Iterate(s);
    s.cbf_loss = run.JointLoss();
    stats.seconds = total_seconds();
    run.Record(stats);
    if (!options.curve_path.empty())
      WriteFileAtomically(options.curve_path, CurveCsv(run.history()));

    bool stop = false;
    if (callback && !callback(stats)) {
      s.stop_reason = "callback";
      stop = true;
    } else if (options.stop_after_iterations > 0 &&
               run.completed() >= options.stop_after_iterations &&
               run.completed() < options.iterations) {
      s.stop_reason = "stop_after_iterations";
      stop = true;
    }
    const bool last = stop || run.completed() >= options.iterations;
    if (!options.checkpoint_path.empty() &&
        (last || run.completed() % options.checkpoint_every == 0)) {
      run.SaveCheckpoint(options.checkpoint_path, total_seconds());
      ++s.checkpoints_written;
    }
    if (options.verbose && (last || clock.Seconds() - last_report >= 2.0 || stats.iteration == 1)) {
      last_report = clock.Seconds();
      PrintStatusLineF(
          "[airl] it %d/%d steps %ld success %.3f collide %.3f D exp %.3f pol %.3f "
          "r %.3f ent %.3f sigma %.3f kl %.4f %.1f s\n",
          stats.iteration, options.iterations, stats.env_steps, stats.success_rate,
          stats.collision_rate, stats.d_expert, stats.d_policy, stats.mean_reward, stats.entropy,
          stats.mean_sigma, stats.approx_kl, stats.seconds);
    }
    if (stop) break;
  }

  s.iterations = run.completed();
  s.env_steps = run.env_steps();
  if (!run.history().empty()) s.last = run.history().back();
  s.wall_seconds = clock.Seconds();
  const int ran = s.iterations - s.start_iteration;
  s.iterations_per_second = s.wall_seconds > 0 ? ran / s.wall_seconds : 0.0;
  s.env_steps_per_second =
      s.wall_seconds > 0 ? static_cast<double>(ran) * s.steps_per_iteration / s.wall_seconds : 0.0;

  GaussianPolicy policy = run.Policy();
  policy.provenance = {
      {"trainer", joint != nullptr ? "secure::policy::TrainAirlJoint (AIRL + PPO with the "
                                     "barrier's derivative condition as an extra loss)"
                                   : "secure::policy::TrainAirl (AIRL, state-only discriminator, "
                                     "PPO generator)"},
      {"options", ModelFileOptions(options)},
      {"summary", ModelFileSummary(s)},
      {"environment", env.Describe()},
      {"demonstrations",
       {{"source", demos.source},
        {"episodes", demos.num_episodes()},
        {"steps", demos.num_steps()}}}};
  if (warm_start != nullptr && warm_start->provenance.contains("trainer"))
    policy.provenance["warm_start"] = warm_start->provenance["trainer"];
  if (joint != nullptr) policy.provenance["joint"] = joint->options().ToJson();
  policy.Validate("AIRL policy");
  if (reward_model != nullptr) {
    *reward_model = run.RewardModel();
    reward_model->provenance = {{"trainer", policy.provenance["trainer"]},
                                {"policy_summary", policy.provenance["summary"]},
                                {"environment", env.Describe()}};
    reward_model->Validate("AIRL reward model");
  }
  if (summary != nullptr) *summary = s;
  return policy;
}

}  // namespace

GaussianPolicy TrainAirl(const AirlOptions& options, const data::TrajectorySet& demos,
                         const domains::Environment& env, const GaussianPolicy* warm_start,
                         AirlSummary* summary, const AirlCallback& callback,
                         AirlRewardModel* reward_model) {
  return TrainAirlImpl(options, demos, env, warm_start, summary, callback, nullptr, reward_model);
}

GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint_options,
                              const cbf::DifferentiableBarrier& barrier,
                              const domains::DynamicsModel& model, const data::TrajectorySet& demos,
                              const domains::Environment& env, const GaussianPolicy* warm_start,
                              AirlSummary* summary, const AirlCallback& callback) {
  joint_options.Validate();
  SECURE_CHECK(model.state_dim() == env.observation_dim() && model.action_dim() == env.action_dim(),
               "joint optimisation: the dynamics model ("
                   << model.Describe() << ") maps " << model.state_dim() << "-D states and "
                   << model.action_dim() << "-D actions; the environment (" << env.Describe()
                   << ") has " << env.observation_dim() << "-D observations and "
                   << env.action_dim() << "-D actions");
  SECURE_CHECK(barrier.state_dim() == env.observation_dim(),
               "joint optimisation: the barrier ("
                   << barrier.Describe() << ") reads " << barrier.state_dim()
                   << "-D states; the environment (" << env.Describe() << ") has "
                   << env.observation_dim() << "-D observations");
  internal::JointCbfTerm joint(joint_options, barrier, model);
  return TrainAirlImpl(options, demos, env, warm_start, summary, callback, &joint, nullptr);
}

GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint_options,
                              const cbf::CarBarrierNet& barrier,
                              const domains::DynamicsModel& model, const data::TrajectorySet& demos,
                              const domains::Environment& env, const GaussianPolicy* warm_start,
                              AirlSummary* summary, const AirlCallback& callback) {
  return TrainAirlJoint(options, joint_options, *cbf::MakeDifferentiableBarrier(barrier), model,
                        demos, env, warm_start, summary, callback);
}

GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint_options,
                              const cbf::BarrierNet& barrier, const domains::DynamicsModel& model,
                              const data::TrajectorySet& demos, const domains::Environment& env,
                              const GaussianPolicy* warm_start, AirlSummary* summary,
                              const AirlCallback& callback) {
  // A barrier that reads some of the observation's features (BarrierTrainerOptions::
  // input_features) picks them by name; any other barrier meets the dimension check.
  const std::vector<std::string> features = env.ObservationFeatures();
  bool subset = true;
  for (const std::string& f : barrier.features)
    subset = subset && std::find(features.begin(), features.end(), f) != features.end();
  const std::unique_ptr<cbf::DifferentiableBarrier> differentiable =
      subset ? cbf::MakeDifferentiableBarrierFor(barrier, features, env.Describe(), "the barrier")
             : cbf::MakeDifferentiableBarrier(barrier);
  return TrainAirlJoint(options, joint_options, *differentiable, model, demos, env, warm_start,
                        summary, callback);
}

}  // namespace secure::policy
