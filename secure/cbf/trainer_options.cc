// BarrierTrainerOptions and BarrierTrainingSummary: validation, YAML, JSON and reports.
// (No LibTorch in this translation unit.)
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>

#include "secure/cbf/barrier_trainer.h"
#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/strings.h"
#include "secure/common/yaml_value.h"

namespace secure::cbf {

void BarrierTrainerOptions::Validate() const {
  CheckFeatureNames(input_features, "BarrierTrainerOptions", "input_features");
  CheckLayerWidths(hidden, "BarrierTrainerOptions", "hidden");
  SECURE_CHECK_FIELD(std::isfinite(safe_margin) && safe_margin >= 0, "BarrierTrainerOptions",
                     "safe_margin", safe_margin, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(unsafe_margin) && unsafe_margin >= 0, "BarrierTrainerOptions",
                     "unsafe_margin", unsafe_margin, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(safe_weight) && safe_weight > 0, "BarrierTrainerOptions",
                     "safe_weight", safe_weight, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(unsafe_weight) && unsafe_weight > 0, "BarrierTrainerOptions",
                     "unsafe_weight", unsafe_weight, "> 0");
  SECURE_CHECK_FIELD(ensemble >= 1 && ensemble <= kMaxBarrierEnsemble, "BarrierTrainerOptions",
                     "ensemble", ensemble, "in [1, " << kMaxBarrierEnsemble << "]");
  ValidateSchedule("BarrierTrainerOptions");
}

void BarrierTrainerOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  static const std::set<std::string> known = [] {
    std::set<std::string> k = {"hidden",          "activation",  "safe_margin",   "unsafe_margin",
                               "balance_classes", "safe_weight", "unsafe_weight", "input_features",
                               "ensemble"};
    k.insert(Keys().begin(), Keys().end());
    return k;
  }();
  const auto apply = [&](const std::string& key, const YAML::Node& v) {
    if (key == "input_features") {
      input_features = YamlList<std::string>(v, key, source, "feature names");
    } else if (key == "hidden") {
      hidden = YamlWidths(v, key, source);
    } else if (key == "activation") {
      activation = FromString(nn::kActivationNames, YamlValue<std::string>(v, key, source),
                              source + ": activation");
    } else if (key == "safe_margin") {
      safe_margin = YamlValue<double>(v, key, source);
    } else if (key == "unsafe_margin") {
      unsafe_margin = YamlValue<double>(v, key, source);
    } else if (key == "balance_classes") {
      balance_classes = YamlValue<bool>(v, key, source);
    } else if (key == "safe_weight") {
      safe_weight = YamlValue<double>(v, key, source);
    } else if (key == "unsafe_weight") {
      unsafe_weight = YamlValue<double>(v, key, source);
    } else if (key == "ensemble") {
      ensemble = YamlValue<int>(v, key, source);
    } else {
      ApplyYamlKey(key, v, source);
    }
  };
  ForEachYamlField(node, known, "barrier trainer options", source, apply);
}

nlohmann::json BarrierTrainerOptions::ToJson() const {
  nlohmann::json j = {{"input_features", input_features},
                      {"hidden", hidden},
                      {"activation", ToString(nn::kActivationNames, activation)},
                      {"safe_margin", safe_margin},
                      {"unsafe_margin", unsafe_margin},
                      {"balance_classes", balance_classes},
                      {"safe_weight", safe_weight},
                      {"unsafe_weight", unsafe_weight}};
  // Only an ensemble names it: one barrier's options (and model bytes) are as before.
  if (ensemble != 1) j["ensemble"] = ensemble;
  AddJson(&j);
  return j;
}

namespace {

// A figure for the human-readable reports: "n/a" when undefined (not finite).
std::string Figure(const char* format, double value) {
  if (!std::isfinite(value)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, value);
  return buf;
}

constexpr const char* kNoHeldOut = "n/a (no held-out states)";

}  // namespace

std::string BarrierTrainingSummary::BriefReport() const {
  const bool validated = validation_safe + validation_near_dangerous > 0;
  std::ostringstream s;
  s << "epochs " << epochs << " (best " << best_epoch << ", " << stop_reason << "), " << iterations
    << " steps, train acc safe " << Figure("%.4f", train_accuracy.safe) << " nd "
    << Figure("%.4f", train_accuracy.near_dangerous) << ", val acc ";
  if (validated) {
    s << "safe " << Figure("%.4f", validation_accuracy.safe) << " nd "
      << Figure("%.4f", validation_accuracy.near_dangerous);
  } else {
    s << kNoHeldOut;
  }
  if (members > 1) s << " (member 0 of " << members << ")";
  s << ", " << Figure("%.2f", wall_seconds) << " s";
  return s.str();
}

std::string BarrierTrainingSummary::FullReport() const {
  const bool validated = validation_safe + validation_near_dangerous > 0;
  std::ostringstream s;
  s << "| split | safe states | near-dangerous states | loss | acc safe | acc near-dangerous |\n"
    << "|---|---:|---:|---:|---:|---:|\n";
  s << "| train | " << train_safe << " | " << train_near_dangerous << " | "
    << Figure("%.5f", train_loss) << " | " << Figure("%.4f", train_accuracy.safe) << " | "
    << Figure("%.4f", train_accuracy.near_dangerous) << " |\n";
  s << "| validation | " << validation_safe << " | " << validation_near_dangerous << " | ";
  if (validated) {
    s << Figure("%.5f", validation_loss) << " | " << Figure("%.4f", validation_accuracy.safe)
      << " | " << Figure("%.4f", validation_accuracy.near_dangerous) << " |\n";
  } else {
    s << "n/a | " << kNoHeldOut << " | " << kNoHeldOut << " |\n";
  }
  char buf[160];
  std::snprintf(buf, sizeof buf, "epochs %d, best epoch %d, stop: %s, %ld steps, %.2f s\n", epochs,
                best_epoch, stop_reason.c_str(), iterations, wall_seconds);
  s << buf;
  return s.str();
}

nlohmann::json BarrierTrainingSummary::ToJson() const {
  auto acc = [](const ClassAccuracy& a) {
    return nlohmann::json{
        {"safe", a.safe}, {"near_dangerous", a.near_dangerous}, {"balanced", a.Balanced()}};
  };
  nlohmann::json j = {{"epochs", epochs},
          {"best_epoch", best_epoch},
          {"iterations", iterations},
          {"train_loss", train_loss},
          {"validation_loss", validation_loss},
          {"train_accuracy", acc(train_accuracy)},
          // null without held-out states: an accuracy of nothing is undefined, not 0.
          {"validation_accuracy", validation_safe + validation_near_dangerous > 0
                                      ? acc(validation_accuracy)
                                      : nlohmann::json(nullptr)},
          {"train_counts", {{"safe", train_safe}, {"near_dangerous", train_near_dangerous}}},
          {"validation_counts",
           {{"safe", validation_safe}, {"near_dangerous", validation_near_dangerous}}},
          {"wall_seconds", wall_seconds},
          {"stop_reason", stop_reason}};
  // Only an ensemble's summary (member 0's figures) says so: one barrier's is as before.
  if (members > 1) j["members"] = members;
  return j;
}

}  // namespace secure::cbf
