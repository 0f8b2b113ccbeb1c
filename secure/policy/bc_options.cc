// BcOptions, BcSummary and CheckDemos: validation, YAML, JSON and reports (no LibTorch here).
#include <cmath>
#include <cstdio>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/strings.h"
#include "secure/common/yaml_fields.h"
#include "secure/common/yaml_value.h"
#include "secure/policy/bc_trainer.h"
#include "secure/policy/internal/options_util.h"

namespace secure::policy {
namespace {

nlohmann::json NumberOrNull(double x) { return std::isfinite(x) ? nlohmann::json(x) : nullptr; }

}  // namespace

void BcOptions::Validate() const {
  CheckLayerWidths(hidden, "BcOptions", "hidden");
  SECURE_CHECK_FIELD(std::isfinite(learning_rate) && learning_rate > 0, "BcOptions",
                     "learning_rate", learning_rate, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(final_learning_rate) && final_learning_rate > 0 &&
                         final_learning_rate <= learning_rate,
                     "BcOptions", "final_learning_rate", final_learning_rate,
                     "in (0, learning_rate]");
  SECURE_CHECK_FIELD(epochs > 0, "BcOptions", "epochs", epochs, "> 0");
  SECURE_CHECK_FIELD(batch_size > 0, "BcOptions", "batch_size", batch_size, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(weight_decay) && weight_decay >= 0, "BcOptions", "weight_decay",
                     weight_decay, ">= 0");
  SECURE_CHECK_FIELD(
      std::isfinite(validation_fraction) && validation_fraction >= 0 && validation_fraction < 1,
      "BcOptions", "validation_fraction", validation_fraction, "in [0, 1)");
  SECURE_CHECK_FIELD(std::isfinite(min_log_std), "BcOptions", "min_log_std", min_log_std, "finite");
  CheckFeatureNames(input_features, "BcOptions", "input_features");
}

YamlFields BcOptions::Fields() {
  return YamlFields()
      .Named("behaviour cloning options")
      .Custom(
          "hidden",
          [this](const YAML::Node& v, const std::string& key, const std::string& source) {
            hidden = internal::YamlWidths(v, key, source);
          },
          [this] { return nlohmann::json(hidden); })
      .Custom(
          "activation",
          [this](const YAML::Node& v, const std::string& key, const std::string& source) {
            activation = FromString(nn::kActivationNames, YamlValue<std::string>(v, key, source),
                                    source + ": activation");
          },
          [this] { return nlohmann::json(ToString(nn::kActivationNames, activation)); })
      .Custom(
          "input_features",
          [this](const YAML::Node& v, const std::string& key, const std::string& source) {
            input_features = internal::YamlStrings(v, key, source);
          },
          [this] { return nlohmann::json(input_features); })
      .Field("learning_rate", &learning_rate)
      .Field("final_learning_rate", &final_learning_rate)
      .Field("epochs", &epochs)
      .Field("batch_size", &batch_size)
      .Field("weight_decay", &weight_decay)
      .Field("validation_fraction", &validation_fraction)
      .Field("min_log_std", &min_log_std)
      .Field("seed", &seed)
      // Read, not written: a run's JSON does not depend on its progress lines.
      .Custom("verbose",
              [this](const YAML::Node& v, const std::string& key, const std::string& source) {
                verbose = YamlValue<bool>(v, key, source);
              })
      .Field("curve_path", &curve_path);
}

SECURE_YAML_JSON_FROM_FIELDS(BcOptions)

std::string BcSummary::BriefReport() const {
  std::string sig;
  for (std::size_t i = 0; i < sigma.size(); ++i) {
    char b[32];
    std::snprintf(b, sizeof b, "%s%.4g", i ? " " : "", sigma[i]);
    sig += b;
  }
  char line[400];
  std::snprintf(line, sizeof line,
                "BC: %d epochs (best %d), %ld steps, %ld+%ld pairs (%ld+%ld episodes), NLL train "
                "%.4f val %.4f, action MSE train %.5f val %.5f, sigma [%s], %.2f s",
                epochs, best_epoch, optimizer_steps, train_pairs, validation_pairs, train_episodes,
                validation_episodes, train_nll, validation_nll, train_action_mse,
                validation_action_mse, sig.c_str(), wall_seconds);
  return line;
}

nlohmann::json BcSummary::ToJson() const {
  return {{"epochs", epochs},
          {"best_epoch", best_epoch},
          {"optimizer_steps", optimizer_steps},
          {"train_episodes", train_episodes},
          {"validation_episodes", validation_episodes},
          {"train_pairs", train_pairs},
          {"validation_pairs", validation_pairs},
          {"train_nll", NumberOrNull(train_nll)},
          {"validation_nll", NumberOrNull(validation_nll)},
          {"train_action_mse", NumberOrNull(train_action_mse)},
          {"validation_action_mse", NumberOrNull(validation_action_mse)},
          {"sigma", sigma},
          {"wall_seconds", wall_seconds}};
}

void CheckDemos(const data::TrajectorySet& demos, int min_episode_rows) {
  const std::string name = "demonstrations (" + demos.source + ")";
  SECURE_CHECK(!demos.state_features.empty(), name << ": no state features");
  SECURE_CHECK(!demos.action_features.empty(), name << ": no action features");
  SECURE_CHECK(demos.states.rows() == static_cast<Eigen::Index>(demos.state_features.size()),
               name << ": states have " << demos.states.rows() << " rows for "
                    << demos.state_features.size() << " state features");
  SECURE_CHECK(demos.actions.rows() == static_cast<Eigen::Index>(demos.action_features.size()),
               name << ": actions have " << demos.actions.rows() << " rows for "
                    << demos.action_features.size() << " action features");
  SECURE_CHECK(
      demos.actions.cols() == demos.states.cols(),
      name << ": " << demos.states.cols() << " states but " << demos.actions.cols() << " actions");
  SECURE_CHECK(demos.num_episodes() >= 1 && demos.num_steps() > 0,
               name << ": no episodes (at least one is needed)");
  SECURE_CHECK(demos.episode_begin.front() == 0 && demos.episode_begin.back() == demos.num_steps(),
               name << ": episode boundaries do not cover the " << demos.num_steps() << " steps");
  for (long e = 0; e < demos.num_episodes(); ++e) {
    const long rows = demos.episode_begin[e + 1] - demos.episode_begin[e];
    SECURE_CHECK(rows >= min_episode_rows, name << ": episode " << e << " has " << rows
                                                << " rows, at least " << min_episode_rows
                                                << " are needed");
  }
  for (Eigen::Index c = 0; c < demos.states.cols(); ++c) {
    SECURE_CHECK(demos.states.col(c).allFinite(),
                 name << ": state " << c << " has a non-finite value");
    SECURE_CHECK(demos.actions.col(c).allFinite(),
                 name << ": action " << c << " has a non-finite value");
  }
}

}  // namespace secure::policy
