#include "secure/policy/airl_trainer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <numeric>
#include <sstream>
#include <string_view>

#include "secure/cbf/internal/car_barrier_torch.h"
#include "secure/common/atomic_file.h"
#include "secure/common/filesystem.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/common/timer.h"
#include "secure/nn/model_file.h"
#include "secure/policy/bc_trainer.h"
#include "secure/policy/internal/torch_policy.h"

namespace secure::policy {
namespace {

// Checkpoint file, version 2 (docs/FILE_FORMATS.md):
//   "secure-airl-checkpoint 2\n"   format name and version
//   <LibTorch archive bytes>        a zip (torch::serialize::OutputArchive::save_to)
//   "\ncrc32 xxxxxxxx\n"            CRC-32 (nn::Crc32) of everything before this trailer
// Version 1 was the bare archive (a zip, "PK\x03\x04..."), without a checksum: LibTorch's
// reader does not verify the zip's own CRCs, so a flipped byte in tensor data was accepted.
constexpr int kCheckpointVersion = 2;
constexpr const char* kCheckpointFormat = "secure-airl-checkpoint";
constexpr std::string_view kCheckpointTrailerPrefix = "\ncrc32 ";
constexpr std::size_t kCheckpointTrailerSize = kCheckpointTrailerPrefix.size() + 8 + 1;
// Expert transitions in the D-on-expert statistic (a fixed random subset).
constexpr long kExpertStatTransitions = 2048;

// Seeds of the parts of a run (internal::DeriveSeed salts).
enum Salt : std::uint64_t {
  kPolicyInit = 1,
  kValueInit = 2,
  kRewardInit = 3,
  kShapingInit = 4,
  kExpertSubset = 5,
  kIterationBase = 1000,  // + iteration (0-based)
};

// FNV-1a over the demonstration matrices and episode boundaries: identifies the data a
// checkpoint was trained on.
std::uint64_t Fingerprint(const data::TrajectorySet& demos) {
  std::uint64_t h = 1469598103934665603ULL;
  auto mix = [&h](const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ULL;
  };
  mix(demos.states.data(), sizeof(float) * demos.states.size());
  mix(demos.actions.data(), sizeof(float) * demos.actions.size());
  mix(demos.episode_begin.data(), sizeof(long) * demos.episode_begin.size());
  for (const auto& f : demos.state_features) mix(f.data(), f.size() + 1);
  for (const auto& f : demos.action_features) mix(f.data(), f.size() + 1);
  return h;
}

std::string Hex8(std::uint32_t value) {
  char buffer[9];
  std::snprintf(buffer, sizeof buffer, "%08x", static_cast<unsigned>(value));
  return buffer;
}

// The checkpoint file's bytes: the format line, `archive`, the checksum trailer.
std::string FrameCheckpoint(const std::string& archive) {
  std::string out =
      std::string(kCheckpointFormat) + " " + std::to_string(kCheckpointVersion) + "\n" + archive;
  const std::uint32_t crc = nn::Crc32(out);
  out += kCheckpointTrailerPrefix;
  out += Hex8(crc);
  out += '\n';
  return out;
}

// The archive inside a checkpoint file's `bytes`, after checking the format line, the version,
// the trailer and the checksum; throws naming `path` and what is wrong.
std::string_view UnframeCheckpoint(const std::string& bytes, const std::string& path) {
  const std::string_view all(bytes);
  SECURE_CHECK(all.substr(0, 4) != std::string_view("PK\x03\x04", 4),
               path << ": AIRL checkpoint version 1 (a bare LibTorch archive without a checksum, "
                       "written by an older build); this build reads version "
                    << kCheckpointVersion
                    << " only: delete the file to start afresh, or run without resume");
  const std::string prefix = std::string(kCheckpointFormat) + " ";
  constexpr std::size_t kMaxFormatLine = 64;
  const std::size_t line_end = all.substr(0, kMaxFormatLine).find('\n');
  const bool prefix_ok =
      all.substr(0, prefix.size()) == std::string_view(prefix).substr(0, all.size());
  SECURE_CHECK(!prefix_ok || line_end != std::string_view::npos || all.size() >= kMaxFormatLine,
               path << ": truncated AIRL checkpoint (" << all.size()
                    << " bytes, the format line is incomplete)");
  SECURE_CHECK(prefix_ok && line_end != std::string_view::npos,
               path << ": not an AIRL checkpoint (it does not start with '" << kCheckpointFormat
                    << " <version>')");
  const std::string_view version = all.substr(prefix.size(), line_end - prefix.size());
  SECURE_CHECK(version == std::to_string(kCheckpointVersion),
               path << ": AIRL checkpoint version " << version << ", this build reads version "
                    << kCheckpointVersion << " only");
  const std::size_t body = line_end + 1;
  SECURE_CHECK(all.size() >= body + kCheckpointTrailerSize,
               path << ": truncated AIRL checkpoint (" << all.size()
                    << " bytes, no room for the checksum trailer)");
  const std::size_t trailer_start = all.size() - kCheckpointTrailerSize;
  const std::string_view trailer = all.substr(trailer_start);
  std::uint32_t stored = 0;
  bool hex = true;
  for (const char c : trailer.substr(kCheckpointTrailerPrefix.size(), 8)) {
    const int digit = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
    hex = hex && digit >= 0;
    stored = (stored << 4) | static_cast<std::uint32_t>(digit & 0xf);
  }
  SECURE_CHECK(hex &&
                   trailer.substr(0, kCheckpointTrailerPrefix.size()) == kCheckpointTrailerPrefix &&
                   trailer.back() == '\n',
               path << ": truncated or corrupt AIRL checkpoint (it does not end with the "
                       "checksum trailer '\\ncrc32 xxxxxxxx\\n')");
  const std::uint32_t computed = nn::Crc32(all.substr(0, trailer_start));
  SECURE_CHECK(stored == computed, path << ": checksum mismatch (stored " << Hex8(stored)
                                        << ", computed " << Hex8(computed)
                                        << "): the checkpoint is corrupt");
  return all.substr(body, trailer_start - body);
}

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

// Options that shape the training trajectory: must match when resuming.
nlohmann::json TrainingShapingOptions(const AirlOptions& o) {
  nlohmann::json j = o.ToJson();
  for (const char* key : {"iterations", "curve_path", "checkpoint_path", "checkpoint_every",
                          "resume", "stop_after_iterations"})
    j.erase(key);
  return j;
}

// Running mean and variance (Chan et al.'s parallel merge), for reward normalisation.
struct RunningStat {
  double count = 0.0, mean = 0.0, m2 = 0.0;

  void AddBatch(const std::vector<double>& xs) {
    if (xs.empty()) return;
    double bm = 0.0;
    for (double x : xs) bm += x;
    bm /= static_cast<double>(xs.size());
    double bm2 = 0.0;
    for (double x : xs) bm2 += (x - bm) * (x - bm);
    const double bn = static_cast<double>(xs.size());
    const double delta = bm - mean;
    const double total = count + bn;
    mean += delta * bn / total;
    m2 += bm2 + delta * delta * count * bn / total;
    count = total;
  }
  double Std() const { return count > 1 ? std::sqrt(m2 / count) : 1.0; }
};

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

AirlIterationStats StatsFromJson(const nlohmann::json& j) {
  AirlIterationStats s;
  auto num = [&j](const char* key) {
    return j.contains(key) && j[key].is_number() ? j[key].get<double>()
                                                 : std::numeric_limits<double>::quiet_NaN();
  };
  s.iteration = static_cast<int>(num("iteration"));
  s.env_steps = static_cast<long>(num("env_steps"));
  s.episodes = static_cast<int>(num("episodes"));
  s.success_rate = num("success_rate");
  s.collision_rate = num("collision_rate");
  s.mean_collisions = num("mean_collisions");
  s.d_expert = num("d_expert");
  s.d_policy = num("d_policy");
  s.discriminator_loss = num("discriminator_loss");
  s.mean_reward = num("mean_reward");
  s.policy_loss = num("policy_loss");
  s.value_loss = num("value_loss");
  s.entropy = num("entropy");
  s.mean_sigma = num("mean_sigma");
  s.approx_kl = num("approx_kl");
  s.clip_fraction = num("clip_fraction");
  s.bc_nll = num("bc_nll");
  s.seconds = num("seconds");
  return s;
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

torch::Tensor NormalizerTensor(const Eigen::VectorXf& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {v.size()}, torch::kFloat32).clone();
}

Eigen::VectorXf EigenVector(const torch::Tensor& t) {
  const torch::Tensor c = t.contiguous().to(torch::kFloat32);
  return Eigen::Map<const Eigen::VectorXf>(c.data_ptr<float>(), c.numel());
}

// One AIRL run: the state that a checkpoint holds, and the steps of an iteration.
// The joint-optimisation term of TrainAirlJoint: the frozen barrier in LibTorch, the shield's
// model and, per iteration, the model linearised around a = 0 at every rollout state.
struct JointTerm {
  JointCbfOptions options;
  const domains::DynamicsModel* model = nullptr;
  cbf::internal::CarBarrierTorch barrier{nullptr};
  torch::Tensor base, jacobian, h_state;  // (n x obs), (n x act x obs), (n)
  double loss_sum = 0.0;
  long batches = 0;

  // T(s, 0) and dT/da at every column of `states` (raw observations, obs x n), and h(s).
  void Prepare(const Eigen::MatrixXf& states, int action_dim) {
    const long n = states.cols();
    const long d = states.rows();
    Eigen::MatrixXf actions = Eigen::MatrixXf::Zero(action_dim, action_dim + 1);
    for (int k = 0; k < action_dim; ++k) actions(k, k + 1) = 1.0f;
    Eigen::MatrixXf next(d, action_dim + 1);
    Eigen::MatrixXf base_m(d, n);
    Eigen::MatrixXf jac_m(d, n * action_dim);  // column i * action_dim + k: dT/da_k at state i
    for (long i = 0; i < n; ++i) {
      model->Step(states.col(i), actions, next);
      base_m.col(i) = next.col(0);
      for (int k = 0; k < action_dim; ++k)
        jac_m.col(i * action_dim + k) = next.col(k + 1) - next.col(0);
    }
    base = nn::ToTensor(base_m);
    jacobian = nn::ToTensor(jac_m).reshape({n, action_dim, d});
    torch::NoGradGuard no_grad;
    h_state = barrier->forward(nn::ToTensor(states)).reshape({n});
    loss_sum = 0.0;
    batches = 0;
  }

  // L_cbf on rows `idx` for the reparameterised actions (m x act).
  torch::Tensor Loss(const torch::Tensor& idx, const torch::Tensor& actions) {
    const torch::Tensor next = base.index_select(0, idx) +
                               torch::bmm(actions.unsqueeze(1), jacobian.index_select(0, idx))
                                   .squeeze(1);
    const torch::Tensor h = h_state.index_select(0, idx);
    const torch::Tensor h_next = barrier->forward(next).reshape({-1});
    const torch::Tensor deriv = h_next - h + options.dt * options.class_k_gain * h;
    const torch::Tensor loss =
        torch::where(h >= 0, torch::relu(-deriv),
                     options.unsafe_weight * torch::relu(-deriv + options.unsafe_margin))
            .mean();
    loss_sum += loss.item<double>();
    ++batches;
    return loss;
  }
};

class AirlRun {
 public:
  AirlRun(const AirlOptions& options, const data::TrajectorySet& demos,
          const domains::Environment& env, const GaussianPolicy* warm_start)
      : o_(options), demos_(demos), horizon_(env.max_steps()) {
    obs_dim_ = env.observation_dim();
    act_dim_ = env.action_dim();
    episodes_ = (o_.steps_per_iteration + horizon_ - 1) / horizon_;
    env_description_ = env.Describe();
    observation_features_ = env.ObservationFeatures();
    action_features_ = env.ActionFeatures();
    for (int e = 0; e < episodes_; ++e) envs_.push_back(env.Clone());

    // Expert transitions (s_t, a_t, s_{t+1}) within each episode; the last row is dropped.
    std::vector<long> cols, next_cols;
    for (long ep = 0; ep < demos.num_episodes(); ++ep)
      for (long c = demos.episode_begin[ep]; c + 1 < demos.episode_begin[ep + 1]; ++c) {
        cols.push_back(c);
        next_cols.push_back(c + 1);
      }
    expert_count_ = static_cast<long>(cols.size());
    expert_cols_ = std::move(cols);
    expert_next_cols_ = std::move(next_cols);

    // Policy: warm start (architecture, normaliser and log sigma kept) or fresh.
    nn::MlpParams mean_params;
    Eigen::VectorXf log_std;
    if (warm_start != nullptr) {
      warm_start->Validate("AIRL warm start");
      warm_start->CheckFeatures(env.ObservationFeatures(), env.ActionFeatures(),
                                "the environment (" + env_description_ + ")");
      normalizer_ = warm_start->input;
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
    policy_ = internal::TorchGaussian(mean_params, log_std, o_.min_log_std);
    value_ = nn::TorchMlp(SpecOf(obs_dim_, o_.value_hidden, 1, nn::Activation::kTanh));
    value_->LoadParams(
        internal::InitialParams(value_->spec(), internal::DeriveSeed(o_.seed, kValueInit)));
    disc_ = internal::AirlDiscriminator(
        internal::InitialParams(SpecOf(obs_dim_, o_.reward_hidden, 1, nn::Activation::kRelu),
                                internal::DeriveSeed(o_.seed, kRewardInit)),
        internal::InitialParams(SpecOf(obs_dim_, o_.shaping_hidden, 1, nn::Activation::kRelu),
                                internal::DeriveSeed(o_.seed, kShapingInit)),
        o_.discriminator_discount);
    policy_opt_ = std::make_unique<torch::optim::Adam>(policy_->parameters(),
                                                       torch::optim::AdamOptions(o_.policy_lr));
    value_opt_ = std::make_unique<torch::optim::Adam>(value_->parameters(),
                                                      torch::optim::AdamOptions(o_.value_lr));
    disc_opt_ = std::make_unique<torch::optim::Adam>(
        disc_->parameters(), torch::optim::AdamOptions(o_.discriminator_lr));

    BuildExpertTensors();

    const long n = static_cast<long>(episodes_) * horizon_;
    obs_.resize(obs_dim_, n);
    next_obs_.resize(obs_dim_, n);
    actions_.resize(act_dim_, n);
  }

  void SetJoint(JointTerm* joint) { joint_ = joint; }
  double JointLoss() const {
    return joint_ != nullptr && joint_->batches > 0 ? joint_->loss_sum / joint_->batches : 0.0;
  }

  int episodes() const { return episodes_; }
  int horizon() const { return horizon_; }
  long expert_count() const { return expert_count_; }
  bool warm_started() const { return warm_started_; }
  int completed() const { return completed_; }
  long env_steps() const { return env_steps_; }
  const std::vector<AirlIterationStats>& history() const { return history_; }
  double previous_seconds() const { return previous_seconds_; }

  GaussianPolicy Policy() {
    GaussianPolicy p = policy_->Export(normalizer_);
    p.observation_features = observation_features_;
    p.action_features = action_features_;
    return p;
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
    Rollout(rollout_rng, stats);
    timing.rollout_seconds += watch.Seconds();

    watch.Restart();
    const torch::Tensor x = nn::ToTensor(normalizer_.Apply(obs_));
    const torch::Tensor x_next = nn::ToTensor(normalizer_.Apply(next_obs_));
    const torch::Tensor a = nn::ToTensor(actions_);
    UpdateDiscriminator(x, x_next, a, disc_rng, stats);
    timing.discriminator_seconds += watch.Seconds();

    watch.Restart();
    if (joint_ != nullptr) joint_->Prepare(obs_, act_dim_);
    Ppo(x, x_next, a, ppo_rng, stats);
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
    return {{"format", kCheckpointFormat},
            {"version", kCheckpointVersion},
            {"completed_iterations", completed_},
            {"env_steps", env_steps_},
            {"options", TrainingShapingOptions(o_)},
            {"demonstrations_fingerprint", std::to_string(Fingerprint(demos_))},
            {"environment", env_description_},
            {"horizon", horizon_},
            {"episodes_per_iteration", episodes_},
            {"policy_spec", SpecJson(policy_spec_)},
            {"warm_started", warm_started_},
            {"joint", joint_ != nullptr ? joint_->options.ToJson() : nlohmann::json(nullptr)},
            {"reward_stat", {reward_stat_.count, reward_stat_.mean, reward_stat_.m2}},
            {"curve", rows}};
  }

  void SaveCheckpoint(const std::string& path, double seconds) {
    namespace ser = torch::serialize;
    ser::OutputArchive archive;
    auto nested = [&archive](const char* key, auto&& save) {
      ser::OutputArchive child(archive.compilation_unit());
      save(child);
      archive.write(key, child);
    };
    nested("policy", [&](ser::OutputArchive& a) { policy_->save(a); });
    nested("value", [&](ser::OutputArchive& a) { value_->save(a); });
    nested("discriminator", [&](ser::OutputArchive& a) { disc_->save(a); });
    nested("policy_adam", [&](ser::OutputArchive& a) { policy_opt_->save(a); });
    nested("value_adam", [&](ser::OutputArchive& a) { value_opt_->save(a); });
    nested("discriminator_adam", [&](ser::OutputArchive& a) { disc_opt_->save(a); });
    archive.write("normalizer_mean", NormalizerTensor(normalizer_.mean));
    archive.write("normalizer_scale", NormalizerTensor(normalizer_.scale));
    nlohmann::json meta = Meta();
    meta["seconds"] = seconds;
    const std::string text = meta.dump();
    archive.write("meta", torch::from_blob(const_cast<char*>(text.data()),
                                           {static_cast<std::int64_t>(text.size())}, torch::kUInt8)
                              .clone());
    std::ostringstream bytes;
    archive.save_to(bytes);
    CreateDirectories(std::filesystem::path(path).parent_path().string());
    WriteFileAtomically(path, FrameCheckpoint(bytes.str()));
  }

  // Restores everything from `path`; throws naming the file and the first mismatch.
  void LoadCheckpoint(const std::string& path) {
    namespace ser = torch::serialize;
    const std::string file = ReadFile(path);
    const std::string_view bytes = UnframeCheckpoint(file, path);
    ser::InputArchive archive;
    nlohmann::json meta;
    try {
      std::istringstream in{std::string(bytes)};
      archive.load_from(in);
      torch::Tensor meta_tensor;
      archive.read("meta", meta_tensor);
      const torch::Tensor m = meta_tensor.contiguous();
      meta = nlohmann::json::parse(
          std::string(reinterpret_cast<const char*>(m.data_ptr<std::uint8_t>()), m.numel()));
    } catch (const c10::Error& e) {
      SECURE_THROW(path << ": not a readable AIRL checkpoint (" << FirstLine(e.what()) << ")");
    } catch (const nlohmann::json::exception& e) {
      SECURE_THROW(path << ": AIRL checkpoint metadata is not valid JSON (" << e.what() << ")");
    }
    SECURE_CHECK(meta.value("format", "") == kCheckpointFormat,
                 path << ": not an AIRL checkpoint (format '" << meta.value("format", "") << "')");
    SECURE_CHECK(meta.value("version", 0) == kCheckpointVersion,
                 path << ": AIRL checkpoint version " << meta.value("version", 0)
                      << ", this build reads version " << kCheckpointVersion);
    // Everything that shapes training must match.
    const nlohmann::json mine = Meta();
    for (const char* key : {"demonstrations_fingerprint", "environment", "horizon",
                            "episodes_per_iteration", "policy_spec", "warm_started", "joint"}) {
      SECURE_CHECK(meta.contains(key) && meta[key] == mine[key],
                   path << ": cannot resume: the checkpoint's " << key << " is "
                        << (meta.contains(key) ? meta[key].dump() : "missing") << ", this run's is "
                        << mine[key].dump());
    }
    SECURE_CHECK(meta.contains("options") && meta["options"].is_object(),
                 path << ": checkpoint has no options");
    for (const auto& [key, value] : mine["options"].items()) {
      SECURE_CHECK(
          meta["options"].contains(key) && meta["options"][key] == value,
          path << ": cannot resume: the checkpoint was trained with AirlOptions::" << key << " = "
               << (meta["options"].contains(key) ? meta["options"][key].dump() : "(missing)")
               << ", this run has " << value.dump());
    }
    try {
      auto nested = [&archive](const char* key, auto&& load) {
        ser::InputArchive child;
        archive.read(key, child);
        load(child);
      };
      nested("policy", [&](ser::InputArchive& a) { policy_->load(a); });
      nested("value", [&](ser::InputArchive& a) { value_->load(a); });
      nested("discriminator", [&](ser::InputArchive& a) { disc_->load(a); });
      nested("policy_adam", [&](ser::InputArchive& a) { policy_opt_->load(a); });
      nested("value_adam", [&](ser::InputArchive& a) { value_opt_->load(a); });
      nested("discriminator_adam", [&](ser::InputArchive& a) { disc_opt_->load(a); });
      torch::Tensor mean, scale;
      archive.read("normalizer_mean", mean);
      archive.read("normalizer_scale", scale);
      normalizer_.mean = EigenVector(mean);
      normalizer_.scale = EigenVector(scale);
      normalizer_.Validate(path + " normalizer");
    } catch (const c10::Error& e) {
      SECURE_THROW(path << ": corrupt AIRL checkpoint (" << FirstLine(e.what()) << ")");
    }
    // The expert tensors depend on the normaliser (the same unless a different warm start).
    BuildExpertTensors();
    completed_ = meta.at("completed_iterations").get<int>();
    env_steps_ = meta.at("env_steps").get<long>();
    const auto& rs = meta.at("reward_stat");
    reward_stat_ = {rs.at(0).get<double>(), rs.at(1).get<double>(), rs.at(2).get<double>()};
    history_.clear();
    for (const auto& row : meta.at("curve")) history_.push_back(StatsFromJson(row));
    previous_seconds_ = meta.value("seconds", 0.0);
  }

 private:
  void BuildExpertTensors() {
    expert_x_ = nn::ToTensor(normalizer_.Apply(data::SelectColumns(demos_.states, expert_cols_)));
    expert_next_ =
        nn::ToTensor(normalizer_.Apply(data::SelectColumns(demos_.states, expert_next_cols_)));
    expert_a_ = nn::ToTensor(data::SelectColumns(demos_.actions, expert_cols_));
    // A fixed random subset for the D-on-expert statistic.
    std::vector<std::int64_t> all(expert_count_);
    std::iota(all.begin(), all.end(), std::int64_t{0});
    Rng rng(internal::DeriveSeed(o_.seed, kExpertSubset));
    Shuffle(all.begin(), all.end(), rng);
    all.resize(std::min<long>(expert_count_, kExpertStatTransitions));
    std::sort(all.begin(), all.end());
    expert_stat_index_ = internal::IndexTensor(all);
  }

  static std::string FirstLine(const std::string& text) { return text.substr(0, text.find('\n')); }

  // Fixed-horizon episodes in lock-step: one batched mean evaluation per time step.
  void Rollout(Rng& rng, AirlIterationStats& stats) {
    const GaussianPolicy current = Policy();
    PolicyEvaluator evaluator(current, std::max(1, episodes_));
    const Eigen::VectorXf sigma = evaluator.sigma();
    std::vector<Rng> episode_rngs;
    for (int e = 0; e < episodes_; ++e) episode_rngs.push_back(rng.Split());
    Eigen::MatrixXf current_obs(obs_dim_, episodes_), mus(act_dim_, episodes_);
    Eigen::VectorXf action(act_dim_), next(obs_dim_);
    std::vector<char> reached(episodes_, 0), collided(episodes_, 0);
    long collision_events = 0;
    for (int e = 0; e < episodes_; ++e) envs_[e]->Reset(episode_rngs[e], current_obs.col(e));
    for (int t = 0; t < horizon_; ++t) {
      evaluator.Means(current_obs, mus);
      for (int e = 0; e < episodes_; ++e) {
        const long column = static_cast<long>(e) * horizon_ + t;
        for (int i = 0; i < act_dim_; ++i)
          action[i] = mus(i, e) + sigma[i] * static_cast<float>(episode_rngs[e].Normal());
        const domains::StepOutcome outcome = envs_[e]->Step(action, next);
        obs_.col(column) = current_obs.col(e);
        actions_.col(column) = action;
        next_obs_.col(column) = next;
        current_obs.col(e) = next;
        reached[e] |= outcome.reached_goal;
        collided[e] |= outcome.collided;
        collision_events += outcome.collisions;
      }
    }
    stats.episodes = episodes_;
    stats.success_rate =
        std::count(reached.begin(), reached.end(), 1) / static_cast<double>(episodes_);
    stats.collision_rate =
        std::count(collided.begin(), collided.end(), 1) / static_cast<double>(episodes_);
    stats.mean_collisions = static_cast<double>(collision_events) / episodes_;
  }

  void UpdateDiscriminator(const torch::Tensor& x, const torch::Tensor& x_next,
                           const torch::Tensor& a, Rng& rng, AirlIterationStats& stats) {
    const long n_policy = x.size(0);
    const int b = o_.discriminator_batch;
    std::vector<std::int64_t> ie(b), ip(b);
    double loss_sum = 0.0;
    for (int k = 0; k < o_.discriminator_updates; ++k) {
      for (int i = 0; i < b; ++i)
        ie[i] = static_cast<std::int64_t>(rng.UniformIndex(expert_count_));
      for (int i = 0; i < b; ++i) ip[i] = static_cast<std::int64_t>(rng.UniformIndex(n_policy));
      const torch::Tensor te = internal::IndexTensor(ie), tp = internal::IndexTensor(ip);
      const torch::Tensor xe = expert_x_.index_select(0, te), xp = x.index_select(0, tp);
      torch::Tensor log_pi_e, log_pi_p;
      {
        torch::NoGradGuard no_grad;
        log_pi_e = policy_->LogProb(xe, expert_a_.index_select(0, te));
        log_pi_p = policy_->LogProb(xp, a.index_select(0, tp));
      }
      const torch::Tensor fe = disc_->F(xe, expert_next_.index_select(0, te));
      const torch::Tensor fp = disc_->F(xp, x_next.index_select(0, tp));
      // Mean cross-entropy over the 2b samples: expert label 1, policy label 0.
      const torch::Tensor loss =
          -0.5 * (internal::LogD(fe, log_pi_e).mean() + internal::Log1mD(fp, log_pi_p).mean());
      disc_opt_->zero_grad();
      loss.backward();
      disc_opt_->step();
      loss_sum += loss.item<double>();
    }
    stats.discriminator_loss = o_.discriminator_updates > 0
                                   ? loss_sum / o_.discriminator_updates
                                   : std::numeric_limits<double>::quiet_NaN();
    // D on a fixed subset of the expert transitions (a statistic; all of them would cost a
    // policy forward pass over the whole demonstration set every iteration).
    torch::NoGradGuard no_grad;
    const torch::Tensor xs = expert_x_.index_select(0, expert_stat_index_);
    const torch::Tensor fe = disc_->F(xs, expert_next_.index_select(0, expert_stat_index_));
    const torch::Tensor log_pi =
        policy_->LogProb(xs, expert_a_.index_select(0, expert_stat_index_));
    stats.d_expert = torch::exp(internal::LogD(fe, log_pi)).mean().item<double>();
  }

  void Ppo(const torch::Tensor& x, const torch::Tensor& x_next, const torch::Tensor& a, Rng& rng,
           AirlIterationStats& stats) {
    const long n = x.size(0);
    torch::Tensor old_log_pi, rewards, values, last_values;
    {
      torch::NoGradGuard no_grad;
      old_log_pi = policy_->LogProb(x, a);
      const torch::Tensor f = disc_->F(x, x_next);
      stats.d_policy = torch::exp(internal::LogD(f, old_log_pi)).mean().item<double>();
      rewards = internal::AirlPolicyReward(o_.reward, f, disc_->G(x), old_log_pi)
                    .to(torch::kFloat64)
                    .contiguous();
      values = value_->forward(x).squeeze(1).to(torch::kFloat64).contiguous();
      // V of the state after each episode's last step: the bootstrap at the time limit.
      std::vector<std::int64_t> last(episodes_);
      for (int e = 0; e < episodes_; ++e) last[e] = static_cast<std::int64_t>(e + 1) * horizon_ - 1;
      last_values = value_->forward(x_next.index_select(0, internal::IndexTensor(last)))
                        .squeeze(1)
                        .to(torch::kFloat64)
                        .contiguous();
    }
    const double* r = rewards.data_ptr<double>();
    const double* v = values.data_ptr<double>();
    const double* v_last = last_values.data_ptr<double>();
    stats.mean_reward = rewards.mean().item<double>();

    // Reward scale: running std of the discounted return within each episode.
    double scale = 1.0;
    if (o_.normalize_rewards) {
      std::vector<double> returns(n);
      for (int e = 0; e < episodes_; ++e) {
        double ret = 0.0;
        for (int t = 0; t < horizon_; ++t) {
          const long i = static_cast<long>(e) * horizon_ + t;
          ret = o_.gamma * ret + r[i];
          returns[i] = ret;
        }
      }
      reward_stat_.AddBatch(returns);
      scale = 1.0 / std::max(reward_stat_.Std(), 1e-8);
    }

    // GAE(gamma, lambda) per episode; the episode is truncated, not terminated, at the horizon.
    std::vector<float> advantages(n), targets(n);
    for (int e = 0; e < episodes_; ++e) {
      double gae = 0.0;
      for (int t = horizon_ - 1; t >= 0; --t) {
        const long i = static_cast<long>(e) * horizon_ + t;
        const double next_value = t == horizon_ - 1 ? v_last[e] : v[i + 1];
        const double delta = r[i] * scale + o_.gamma * next_value - v[i];
        gae = delta + o_.gamma * o_.gae_lambda * gae;
        advantages[i] = static_cast<float>(gae);
        targets[i] = static_cast<float>(gae + v[i]);
      }
    }
    double mean = 0.0, var = 0.0;
    for (float adv : advantages) mean += adv;
    mean /= static_cast<double>(n);
    for (float adv : advantages) var += (adv - mean) * (adv - mean);
    const double sd = std::sqrt(var / static_cast<double>(n)) + 1e-8;
    for (float& adv : advantages) adv = static_cast<float>((adv - mean) / sd);
    const torch::Tensor adv_t = torch::from_blob(advantages.data(), {n}, torch::kFloat32).clone();
    const torch::Tensor target_t = torch::from_blob(targets.data(), {n}, torch::kFloat32).clone();

    std::vector<std::int64_t> order(n);
    std::iota(order.begin(), order.end(), std::int64_t{0});
    const std::vector<torch::Tensor> policy_params = policy_->parameters();
    const std::vector<torch::Tensor> value_params = value_->parameters();
    double policy_loss_sum = 0.0, value_loss_sum = 0.0, kl_sum = 0.0, clipped_sum = 0.0;
    double bc_nll_sum = 0.0;
    long batches = 0, last_epoch_samples = 0;
    for (int epoch = 0; epoch < o_.ppo_epochs; ++epoch) {
      const bool last_epoch = epoch + 1 == o_.ppo_epochs;
      Shuffle(order.begin(), order.end(), rng);
      const torch::Tensor perm = torch::from_blob(order.data(), {n}, torch::kInt64);
      for (long first = 0; first < n; first += o_.minibatch_size) {
        const long m = std::min<long>(o_.minibatch_size, n - first);
        const torch::Tensor idx = perm.slice(0, first, first + m);
        const torch::Tensor xb = x.index_select(0, idx);
        const torch::Tensor adv = adv_t.index_select(0, idx);
        const torch::Tensor log_ratio =
            policy_->LogProb(xb, a.index_select(0, idx)) - old_log_pi.index_select(0, idx);
        const torch::Tensor ratio = torch::exp(log_ratio);
        const torch::Tensor surrogate =
            -torch::min(ratio * adv, torch::clamp(ratio, 1.0 - o_.clip, 1.0 + o_.clip) * adv)
                 .mean();
        torch::Tensor policy_loss = surrogate;
        if (joint_ != nullptr && joint_->options.weight > 0) {
          Eigen::MatrixXf eps(act_dim_, m);
          for (long c = 0; c < m; ++c)
            for (int k = 0; k < act_dim_; ++k) eps(k, c) = static_cast<float>(rng.Normal());
          const torch::Tensor sampled =
              policy_->Mean(xb) + torch::exp(policy_->LogStd()) * nn::ToTensor(eps);
          policy_loss = policy_loss + joint_->options.weight * joint_->Loss(idx, sampled);
        }
        if (o_.bc_weight > 0) {
          std::vector<std::int64_t> ie(static_cast<std::size_t>(m));
          for (auto& k : ie) k = static_cast<std::int64_t>(rng.UniformIndex(expert_count_));
          const torch::Tensor te = internal::IndexTensor(ie);
          const torch::Tensor bc_nll =
              -policy_->LogProb(expert_x_.index_select(0, te), expert_a_.index_select(0, te))
                   .mean();
          policy_loss = policy_loss + o_.bc_weight * bc_nll;
          bc_nll_sum += bc_nll.item<double>();
        }
        if (o_.entropy_coef > 0)
          policy_loss =
              policy_loss - o_.entropy_coef * internal::GaussianEntropy(policy_->LogStd());
        policy_opt_->zero_grad();
        policy_loss.backward();
        if (o_.max_grad_norm > 0)
          torch::nn::utils::clip_grad_norm_(policy_params, o_.max_grad_norm);
        policy_opt_->step();

        const torch::Tensor value_loss =
            (value_->forward(xb).squeeze(1) - target_t.index_select(0, idx)).pow(2).mean();
        value_opt_->zero_grad();
        value_loss.backward();
        if (o_.max_grad_norm > 0) torch::nn::utils::clip_grad_norm_(value_params, o_.max_grad_norm);
        value_opt_->step();

        policy_loss_sum += surrogate.item<double>();
        value_loss_sum += value_loss.item<double>();
        ++batches;
        if (last_epoch) {
          torch::NoGradGuard no_grad;
          const torch::Tensor lr = log_ratio.detach();
          kl_sum += ((torch::exp(lr) - 1.0) - lr).sum().item<double>();
          clipped_sum +=
              ((torch::exp(lr) - 1.0).abs() > o_.clip).to(torch::kFloat64).sum().item<double>();
          last_epoch_samples += m;
        }
      }
    }
    stats.policy_loss = policy_loss_sum / std::max(1L, batches);
    stats.bc_nll = o_.bc_weight > 0 ? bc_nll_sum / std::max(1L, batches)
                                    : std::numeric_limits<double>::quiet_NaN();
    stats.value_loss = value_loss_sum / std::max(1L, batches);
    stats.approx_kl = kl_sum / std::max(1L, last_epoch_samples);
    stats.clip_fraction = clipped_sum / std::max(1L, last_epoch_samples);
    torch::NoGradGuard no_grad;
    const torch::Tensor log_std = policy_->LogStd();
    stats.entropy = internal::GaussianEntropy(log_std).item<double>();
    stats.mean_sigma = torch::exp(log_std).mean().item<double>();
  }

  const AirlOptions& o_;
  const data::TrajectorySet& demos_;
  int horizon_ = 0, episodes_ = 0, obs_dim_ = 0, act_dim_ = 0;
  std::string env_description_;
  std::vector<std::string> observation_features_, action_features_;
  std::vector<std::unique_ptr<domains::Environment>> envs_;
  long expert_count_ = 0;
  std::vector<long> expert_cols_, expert_next_cols_;
  bool warm_started_ = false;
  nn::Normalizer normalizer_;
  nn::MlpSpec policy_spec_;
  internal::TorchGaussian policy_{nullptr};
  nn::TorchMlp value_{nullptr};
  internal::AirlDiscriminator disc_{nullptr};
  std::unique_ptr<torch::optim::Adam> policy_opt_, value_opt_, disc_opt_;
  torch::Tensor expert_x_, expert_next_, expert_a_, expert_stat_index_;
  Eigen::MatrixXf obs_, next_obs_, actions_;  // (dim x episodes * horizon), episode-major
  RunningStat reward_stat_;
  int completed_ = 0;
  long env_steps_ = 0;
  std::vector<AirlIterationStats> history_;
  double previous_seconds_ = 0.0;
  JointTerm* joint_ = nullptr;  // TrainAirlJoint only
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

}  // namespace

namespace {

GaussianPolicy TrainAirlImpl(const AirlOptions& options, const data::TrajectorySet& demos,
                             const domains::Environment& env, const GaussianPolicy* warm_start,
                             AirlSummary* summary, const AirlCallback& callback,
                             JointTerm* joint) {
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
      std::fprintf(stderr, "[airl] resumed from %s at iteration %d\n",
                   options.checkpoint_path.c_str(), run.completed());
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
      std::fprintf(stderr,
                   "[airl] it %d/%d steps %ld success %.3f collide %.3f D exp %.3f pol %.3f "
                   "r %.3f ent %.3f sigma %.3f kl %.4f %.1f s\n",
                   stats.iteration, options.iterations, stats.env_steps, stats.success_rate,
                   stats.collision_rate, stats.d_expert, stats.d_policy, stats.mean_reward,
                   stats.entropy, stats.mean_sigma, stats.approx_kl, stats.seconds);
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
  if (joint != nullptr) policy.provenance["joint"] = joint->options.ToJson();
  policy.Validate("AIRL policy");
  if (summary != nullptr) *summary = s;
  return policy;
}

}  // namespace

GaussianPolicy TrainAirl(const AirlOptions& options, const data::TrajectorySet& demos,
                         const domains::Environment& env, const GaussianPolicy* warm_start,
                         AirlSummary* summary, const AirlCallback& callback) {
  return TrainAirlImpl(options, demos, env, warm_start, summary, callback, nullptr);
}

GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint_options,
                              const cbf::CarBarrierNet& barrier,
                              const domains::DynamicsModel& model,
                              const data::TrajectorySet& demos, const domains::Environment& env,
                              const GaussianPolicy* warm_start, AirlSummary* summary,
                              const AirlCallback& callback) {
  joint_options.Validate();
  SECURE_CHECK(model.state_dim() == env.observation_dim() &&
                   model.action_dim() == env.action_dim(),
               "joint optimisation: the dynamics model (" << model.Describe() << ") maps "
                   << model.state_dim() << "-D states and " << model.action_dim()
                   << "-D actions; the environment (" << env.Describe() << ") has "
                   << env.observation_dim() << "-D observations and " << env.action_dim()
                   << "-D actions");
  SECURE_CHECK(barrier.state_dim() == env.observation_dim(),
               "joint optimisation: the barrier reads " << barrier.state_dim()
                   << "-D states; the environment (" << env.Describe() << ") has "
                   << env.observation_dim() << "-D observations");
  JointTerm joint;
  joint.options = joint_options;
  joint.model = &model;
  joint.barrier = cbf::internal::CarBarrierTorch(barrier);
  joint.barrier->Freeze();
  return TrainAirlImpl(options, demos, env, warm_start, summary, callback, &joint);
}

}  // namespace secure::policy
