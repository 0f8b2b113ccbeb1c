// AirlOptions, AirlIterationStats and AirlSummary: validation, YAML, JSON and reports
// (no LibTorch here).
#include <cmath>
#include <cstdio>
#include <set>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/strings.h"
#include "secure/common/yaml_value.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/internal/options_util.h"

namespace secure::policy {
namespace {

void CheckWidths(const std::vector<int>& widths, const char* field) {
  CheckLayerWidths(widths, "AirlOptions", field);
}

void CheckPositive(double x, const char* field) {
  SECURE_CHECK_FIELD(std::isfinite(x) && x > 0, "AirlOptions", field, x, "> 0");
}

}  // namespace

void AirlOptions::Validate() const {
  CheckWidths(policy_hidden, "policy_hidden");
  CheckWidths(value_hidden, "value_hidden");
  CheckWidths(reward_hidden, "reward_hidden");
  CheckWidths(shaping_hidden, "shaping_hidden");
  SECURE_CHECK_FIELD(std::isfinite(init_log_std), "AirlOptions", "init_log_std", init_log_std,
                     "finite");
  SECURE_CHECK_FIELD(std::isfinite(min_log_std) && min_log_std <= init_log_std, "AirlOptions",
                     "min_log_std", min_log_std,
                     "finite and <= init_log_std (" << init_log_std << ")");
  SECURE_CHECK_FIELD(iterations > 0, "AirlOptions", "iterations", iterations, "> 0");
  SECURE_CHECK_FIELD(steps_per_iteration > 0, "AirlOptions", "steps_per_iteration",
                     steps_per_iteration, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(gamma) && gamma > 0 && gamma <= 1, "AirlOptions", "gamma", gamma,
                     "in (0, 1]");
  SECURE_CHECK_FIELD(std::isfinite(gae_lambda) && gae_lambda >= 0 && gae_lambda <= 1, "AirlOptions",
                     "gae_lambda", gae_lambda, "in [0, 1]");
  SECURE_CHECK_FIELD(std::isfinite(clip) && clip > 0 && clip < 1, "AirlOptions", "clip", clip,
                     "in (0, 1)");
  SECURE_CHECK_FIELD(ppo_epochs > 0, "AirlOptions", "ppo_epochs", ppo_epochs, "> 0");
  SECURE_CHECK_FIELD(minibatch_size > 0, "AirlOptions", "minibatch_size", minibatch_size, "> 0");
  CheckPositive(policy_lr, "policy_lr");
  CheckPositive(value_lr, "value_lr");
  SECURE_CHECK_FIELD(std::isfinite(entropy_coef) && entropy_coef >= 0, "AirlOptions",
                     "entropy_coef", entropy_coef, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(bc_weight) && bc_weight >= 0, "AirlOptions", "bc_weight",
                     bc_weight, "finite and >= 0");
  SECURE_CHECK_FIELD(std::isfinite(max_grad_norm) && max_grad_norm >= 0, "AirlOptions",
                     "max_grad_norm", max_grad_norm, ">= 0 (0: no clipping)");
  CheckPositive(discriminator_lr, "discriminator_lr");
  SECURE_CHECK_FIELD(discriminator_updates >= 0, "AirlOptions", "discriminator_updates",
                     discriminator_updates, ">= 0");
  SECURE_CHECK_FIELD(discriminator_batch > 0, "AirlOptions", "discriminator_batch",
                     discriminator_batch, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(discriminator_discount) && discriminator_discount >= 0 &&
                         discriminator_discount <= 1,
                     "AirlOptions", "discriminator_discount", discriminator_discount, "in [0, 1]");
  SECURE_CHECK_FIELD(checkpoint_every > 0, "AirlOptions", "checkpoint_every", checkpoint_every,
                     "> 0");
  SECURE_CHECK_FIELD(stop_after_iterations >= 0, "AirlOptions", "stop_after_iterations",
                     stop_after_iterations, ">= 0 (0: off)");
  SECURE_CHECK_FIELD(!resume || !checkpoint_path.empty(), "AirlOptions", "resume", "true",
                     "false when checkpoint_path is empty");
}

void AirlOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  using internal::YamlValue;
  static const std::set<std::string> known = {"policy_hidden",
                                              "value_hidden",
                                              "reward_hidden",
                                              "shaping_hidden",
                                              "init_log_std",
                                              "min_log_std",
                                              "iterations",
                                              "steps_per_iteration",
                                              "gamma",
                                              "gae_lambda",
                                              "clip",
                                              "ppo_epochs",
                                              "minibatch_size",
                                              "policy_lr",
                                              "value_lr",
                                              "entropy_coef",
                                              "bc_weight",
                                              "max_grad_norm",
                                              "normalize_rewards",
                                              "absorbing_goal",
                                              "discriminator_lr",
                                              "discriminator_updates",
                                              "discriminator_batch",
                                              "discriminator_discount",
                                              "reward",
                                              "seed",
                                              "verbose",
                                              "curve_path",
                                              "checkpoint_path",
                                              "checkpoint_every",
                                              "resume",
                                              "stop_after_iterations"};
  const auto apply = [&](const std::string& key, const YAML::Node& v) {
    auto dbl = [&] { return YamlValue<double>(v, key, source); };
    auto integer = [&] { return YamlValue<int>(v, key, source); };
    if (key == "policy_hidden")
      policy_hidden = internal::YamlWidths(v, key, source);
    else if (key == "value_hidden")
      value_hidden = internal::YamlWidths(v, key, source);
    else if (key == "reward_hidden")
      reward_hidden = internal::YamlWidths(v, key, source);
    else if (key == "shaping_hidden")
      shaping_hidden = internal::YamlWidths(v, key, source);
    else if (key == "init_log_std")
      init_log_std = dbl();
    else if (key == "min_log_std")
      min_log_std = dbl();
    else if (key == "iterations")
      iterations = integer();
    else if (key == "steps_per_iteration")
      steps_per_iteration = integer();
    else if (key == "gamma")
      gamma = dbl();
    else if (key == "gae_lambda")
      gae_lambda = dbl();
    else if (key == "clip")
      clip = dbl();
    else if (key == "ppo_epochs")
      ppo_epochs = integer();
    else if (key == "minibatch_size")
      minibatch_size = integer();
    else if (key == "policy_lr")
      policy_lr = dbl();
    else if (key == "value_lr")
      value_lr = dbl();
    else if (key == "entropy_coef")
      entropy_coef = dbl();
    else if (key == "bc_weight")
      bc_weight = dbl();
    else if (key == "max_grad_norm")
      max_grad_norm = dbl();
    else if (key == "normalize_rewards")
      normalize_rewards = YamlValue<bool>(v, key, source);
    else if (key == "absorbing_goal")
      absorbing_goal = YamlValue<bool>(v, key, source);
    else if (key == "discriminator_lr")
      discriminator_lr = dbl();
    else if (key == "discriminator_updates")
      discriminator_updates = integer();
    else if (key == "discriminator_batch")
      discriminator_batch = integer();
    else if (key == "discriminator_discount")
      discriminator_discount = dbl();
    else if (key == "reward")
      reward =
          FromString(kAirlRewardNames, YamlValue<std::string>(v, key, source), source + ": reward");
    else if (key == "seed")
      seed = YamlValue<std::uint64_t>(v, key, source);
    else if (key == "verbose")
      verbose = YamlValue<bool>(v, key, source);
    else if (key == "curve_path")
      curve_path = YamlValue<std::string>(v, key, source);
    else if (key == "checkpoint_path")
      checkpoint_path = YamlValue<std::string>(v, key, source);
    else if (key == "checkpoint_every")
      checkpoint_every = integer();
    else if (key == "resume")
      resume = YamlValue<bool>(v, key, source);
    else if (key == "stop_after_iterations")
      stop_after_iterations = integer();
  };
  ForEachYamlField(node, known, "AIRL options", source, apply);
}

nlohmann::json AirlOptions::ToJson() const {
  nlohmann::json j = {{"policy_hidden", policy_hidden},
                      {"value_hidden", value_hidden},
                      {"reward_hidden", reward_hidden},
                      {"shaping_hidden", shaping_hidden},
                      {"init_log_std", init_log_std},
                      {"min_log_std", min_log_std},
                      {"iterations", iterations},
                      {"steps_per_iteration", steps_per_iteration},
                      {"gamma", gamma},
                      {"gae_lambda", gae_lambda},
                      {"clip", clip},
                      {"ppo_epochs", ppo_epochs},
                      {"minibatch_size", minibatch_size},
                      {"policy_lr", policy_lr},
                      {"value_lr", value_lr},
                      {"entropy_coef", entropy_coef},
                      {"bc_weight", bc_weight},
                      {"max_grad_norm", max_grad_norm},
                      {"normalize_rewards", normalize_rewards},
                      {"discriminator_lr", discriminator_lr},
                      {"discriminator_updates", discriminator_updates},
                      {"discriminator_batch", discriminator_batch},
                      {"discriminator_discount", discriminator_discount},
                      {"reward", ToString(kAirlRewardNames, reward)},
                      {"seed", seed},
                      {"curve_path", curve_path},
                      {"checkpoint_path", checkpoint_path},
                      {"checkpoint_every", checkpoint_every},
                      {"resume", resume},
                      {"stop_after_iterations", stop_after_iterations}};
  // Only when set, so that models and checkpoints of runs without it keep their bytes.
  if (absorbing_goal) j["absorbing_goal"] = true;
  return j;
}

std::vector<std::string> AirlIterationStats::Columns() {
  return {"iteration",       "env_steps",  "episodes", "success_rate",       "collision_rate",
          "mean_collisions", "d_expert",   "d_policy", "discriminator_loss", "mean_reward",
          "policy_loss",     "value_loss", "entropy",  "mean_sigma",         "approx_kl",
          "clip_fraction",   "bc_nll",     "seconds"};
}

std::vector<double> AirlIterationStats::Values() const {
  return {static_cast<double>(iteration),
          static_cast<double>(env_steps),
          static_cast<double>(episodes),
          success_rate,
          collision_rate,
          mean_collisions,
          d_expert,
          d_policy,
          discriminator_loss,
          mean_reward,
          policy_loss,
          value_loss,
          entropy,
          mean_sigma,
          approx_kl,
          clip_fraction,
          bc_nll,
          seconds};
}

nlohmann::json AirlIterationStats::ToJson() const {
  nlohmann::json j = nlohmann::json::object();
  const auto columns = Columns();
  const auto values = Values();
  for (std::size_t i = 0; i < columns.size(); ++i) {
    if (!std::isfinite(values[i])) {
      j[columns[i]] = nullptr;
    } else if (i < 3) {
      j[columns[i]] = static_cast<long>(values[i]);
    } else {
      j[columns[i]] = values[i];
    }
  }
  return j;
}

std::string AirlSummary::BriefReport() const {
  char line[512];
  std::snprintf(line, sizeof line,
                "AIRL: %d iterations (%s%s), %ld env steps, success %.3f, collisions %.3f, "
                "D expert %.3f policy %.3f, entropy %.3f, %.2f s (%.2f it/s, %.0f steps/s; "
                "rollout %.1f s, discriminator %.1f s, PPO %.1f s)",
                iterations, stop_reason.c_str(), resumed ? ", resumed" : "", env_steps,
                last.success_rate, last.collision_rate, last.d_expert, last.d_policy, last.entropy,
                wall_seconds, iterations_per_second, env_steps_per_second, rollout_seconds,
                discriminator_seconds, ppo_seconds);
  return line;
}

nlohmann::json AirlSummary::ToJson() const {
  return {{"iterations", iterations},
          {"start_iteration", start_iteration},
          {"env_steps", env_steps},
          {"episodes_per_iteration", episodes_per_iteration},
          {"steps_per_iteration", steps_per_iteration},
          {"horizon", horizon},
          {"expert_transitions", expert_transitions},
          {"warm_started", warm_started},
          {"resumed", resumed},
          {"checkpoints_written", checkpoints_written},
          {"stop_reason", stop_reason},
          {"last", last.ToJson()},
          {"wall_seconds", wall_seconds},
          {"rollout_seconds", rollout_seconds},
          {"discriminator_seconds", discriminator_seconds},
          {"ppo_seconds", ppo_seconds},
          {"iterations_per_second", iterations_per_second},
          {"env_steps_per_second", env_steps_per_second},
          {"cbf_loss", cbf_loss}};
}

void JointCbfOptions::Validate() const {
  SECURE_CHECK_FIELD(std::isfinite(weight) && weight >= 0, "JointCbfOptions", "weight", weight,
                     "finite and >= 0");
  SECURE_CHECK_FIELD(std::isfinite(class_k_gain) && class_k_gain > 0, "JointCbfOptions",
                     "class_k_gain", class_k_gain, "finite and > 0");
  SECURE_CHECK_FIELD(std::isfinite(dt) && dt > 0, "JointCbfOptions", "dt", dt, "finite and > 0");
  SECURE_CHECK_FIELD(std::isfinite(unsafe_weight) && unsafe_weight > 0, "JointCbfOptions",
                     "unsafe_weight", unsafe_weight, "finite and > 0");
  SECURE_CHECK_FIELD(std::isfinite(unsafe_margin) && unsafe_margin >= 0, "JointCbfOptions",
                     "unsafe_margin", unsafe_margin, "finite and >= 0");
}

void JointCbfOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  using internal::YamlValue;
  SECURE_CHECK(node.IsMap(), source << ": expected a mapping of joint-optimisation options");
  for (const auto& item : node) {
    const std::string key = YamlKey(item.first, source);
    double* field = key == "weight"          ? &weight
                    : key == "class_k_gain"  ? &class_k_gain
                    : key == "dt"            ? &dt
                    : key == "unsafe_weight" ? &unsafe_weight
                    : key == "unsafe_margin" ? &unsafe_margin
                                             : nullptr;
    SECURE_CHECK(field != nullptr,
                 source << ": unknown field '" << key
                        << "' in the joint-optimisation options (valid: weight, class_k_gain, dt, "
                           "unsafe_weight, unsafe_margin)");
    *field = YamlValue<double>(item.second, key, source);
  }
}

nlohmann::json JointCbfOptions::ToJson() const {
  return {{"weight", weight},
          {"class_k_gain", class_k_gain},
          {"dt", dt},
          {"unsafe_weight", unsafe_weight},
          {"unsafe_margin", unsafe_margin}};
}

}  // namespace secure::policy
