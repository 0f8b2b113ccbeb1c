// The barrier check's options and report (barrier_check.h): CheckThresholds and
// BarrierCheckOptions (Validate, ToJson, ApplyYaml), CheckReport (ToJson, Summary, the
// counterexamples' CSV) and ReadCheckStates, which reads that CSV back as states.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include "secure/cbf/barrier_check.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_value.h"

namespace secure::cbf {
namespace {

std::string FormatNumber(double v) {
  char buffer[40];
  std::snprintf(buffer, sizeof buffer, "%.9g", v);
  return buffer;
}

}  // namespace

void CheckThresholds::Validate() const {
  auto check = [](double v, const char* field) {
    SECURE_CHECK_FIELD(std::isfinite(v) && v >= 0 && v <= 1, "CheckThresholds", field, v,
                       "in [0, 1]");
  };
  check(no_safe_action, "no_safe_action");
  check(near_dangerous, "near_dangerous");
  check(unsafe, "unsafe");
  check(min_accuracy_safe, "min_accuracy_safe");
  check(min_accuracy_near_dangerous, "min_accuracy_near_dangerous");
}

nlohmann::json CheckThresholds::ToJson() const {
  return {{"no_safe_action", no_safe_action},
          {"near_dangerous", near_dangerous},
          {"unsafe", unsafe},
          {"min_accuracy_safe", min_accuracy_safe},
          {"min_accuracy_near_dangerous", min_accuracy_near_dangerous}};
}

void BarrierCheckOptions::Validate() const {
  SECURE_CHECK_FIELD(region_samples > 0 && region_samples <= kMaxStates, "BarrierCheckOptions",
                     "region_samples", region_samples, "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(near_samples > 0 && near_samples <= kMaxStates, "BarrierCheckOptions",
                     "near_samples", near_samples, "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(std::isfinite(near_radius) && near_radius > 0, "BarrierCheckOptions",
                     "near_radius", near_radius, "finite and > 0");
  SECURE_CHECK_FIELD(action_grid == 0 || (action_grid >= 2 && action_grid <= 1000),
                     "BarrierCheckOptions", "action_grid", action_grid,
                     "0 (no grid) or in [2, 1000]");
  SECURE_CHECK_FIELD(action_samples >= 0 && action_samples <= kMaxShieldSamples,
                     "BarrierCheckOptions", "action_samples", action_samples,
                     "in [0, " << kMaxShieldSamples << "]");
  SECURE_CHECK_FIELD(action_grid > 0 || action_samples > 0, "BarrierCheckOptions", "action_samples",
                     action_samples, "> 0 when action_grid is 0");
  SECURE_CHECK_FIELD(action_refine_rounds >= 0, "BarrierCheckOptions", "action_refine_rounds",
                     action_refine_rounds, ">= 0");
  SECURE_CHECK_FIELD(search_starts >= 0, "BarrierCheckOptions", "search_starts", search_starts,
                     ">= 0");
  SECURE_CHECK_FIELD(search_steps >= 0, "BarrierCheckOptions", "search_steps", search_steps,
                     ">= 0");
  SECURE_CHECK_FIELD(search_population > 0 && search_population <= kMaxShieldSamples,
                     "BarrierCheckOptions", "search_population", search_population,
                     "in [1, " << kMaxShieldSamples << "]");
  SECURE_CHECK_FIELD(std::isfinite(search_step) && search_step > 0, "BarrierCheckOptions",
                     "search_step", search_step, "finite and > 0");
  SECURE_CHECK_FIELD(worst_examples >= 0, "BarrierCheckOptions", "worst_examples", worst_examples,
                     ">= 0");
  thresholds.Validate();
}

nlohmann::json BarrierCheckOptions::ToJson() const {
  return {{"region_samples", region_samples},
          {"near_samples", near_samples},
          {"near_radius", near_radius},
          {"action_grid", action_grid},
          {"action_samples", action_samples},
          {"action_refine_rounds", action_refine_rounds},
          {"search_starts", search_starts},
          {"search_steps", search_steps},
          {"search_population", search_population},
          {"search_step", search_step},
          {"worst_examples", worst_examples},
          {"seed", seed},
          {"thresholds", thresholds.ToJson()}};
}

void BarrierCheckOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  SECURE_CHECK(node.IsMap(), source << ": expected a mapping of barrier check options");
  for (const auto& item : node) {
    const std::string key = YamlKey(item.first, source);
    const YAML::Node& v = item.second;
    if (key == "region_samples") {
      region_samples = YamlValue<long>(v, key, source);
    } else if (key == "near_samples") {
      near_samples = YamlValue<long>(v, key, source);
    } else if (key == "near_radius") {
      near_radius = YamlValue<double>(v, key, source);
    } else if (key == "action_grid") {
      action_grid = YamlValue<int>(v, key, source);
    } else if (key == "action_samples") {
      action_samples = YamlValue<int>(v, key, source);
    } else if (key == "action_refine_rounds") {
      action_refine_rounds = YamlValue<int>(v, key, source);
    } else if (key == "search_starts") {
      search_starts = YamlValue<int>(v, key, source);
    } else if (key == "search_steps") {
      search_steps = YamlValue<int>(v, key, source);
    } else if (key == "search_population") {
      search_population = YamlValue<int>(v, key, source);
    } else if (key == "search_step") {
      search_step = YamlValue<double>(v, key, source);
    } else if (key == "worst_examples") {
      worst_examples = YamlValue<int>(v, key, source);
    } else if (key == "seed") {
      seed = YamlValue<std::uint64_t>(v, key, source);
    } else if (key == "thresholds") {
      SECURE_CHECK(v.IsMap(), source << ": field 'thresholds' must be a mapping");
      for (const auto& t : v) {
        const std::string name = YamlKey(t.first, source);
        const std::string where = "thresholds." + name;
        if (name == "no_safe_action") {
          thresholds.no_safe_action = YamlValue<double>(t.second, where, source);
        } else if (name == "near_dangerous") {
          thresholds.near_dangerous = YamlValue<double>(t.second, where, source);
        } else if (name == "unsafe") {
          thresholds.unsafe = YamlValue<double>(t.second, where, source);
        } else if (name == "min_accuracy_safe") {
          thresholds.min_accuracy_safe = YamlValue<double>(t.second, where, source);
        } else if (name == "min_accuracy_near_dangerous") {
          thresholds.min_accuracy_near_dangerous = YamlValue<double>(t.second, where, source);
        } else {
          SECURE_THROW(source << ": unknown field '" << where
                              << "' in the barrier check options (valid: no_safe_action, "
                                 "near_dangerous, unsafe, min_accuracy_safe, "
                                 "min_accuracy_near_dangerous)");
        }
      }
    } else {
      SECURE_THROW(source << ": unknown field '" << key
                          << "' in the barrier check options (valid: the keys of "
                             "BarrierCheckOptions::ToJson, e.g. region_samples, near_radius, "
                             "thresholds)");
    }
  }
}

// ---------------------------------------------------------------------------------------------
const CheckKindStats& CheckReport::Stats(CheckKind kind) const {
  switch (kind) {
    case CheckKind::kNoSafeAction:
      return no_safe_action;
    case CheckKind::kNearDangerous:
      return near_dangerous;
    case CheckKind::kUnsafe:
      return unsafe;
  }
  SECURE_INTERNAL_CHECK(false, "unknown check kind");
  return unsafe;
}

nlohmann::json CheckReport::ToJson() const {
  auto number = [](double v) -> nlohmann::json {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  nlohmann::json kinds = nlohmann::json::object();
  const double tau[3] = {thresholds.no_safe_action, thresholds.near_dangerous, thresholds.unsafe};
  for (int k = 0; k < 3; ++k) {
    const auto kind = static_cast<CheckKind>(k);
    const CheckKindStats& s = Stats(kind);
    long examples = 0;
    for (const CheckExample& e : worst) examples += e.kind == kind;
    kinds[ToString(kCheckKindNames, kind)] = {{"available", s.available},
                                              {"checked", s.checked},
                                              {"counterexamples", s.counterexamples},
                                              {"rate", s.rate()},
                                              {"threshold", tau[k]},
                                              {"flagged", s.available && s.rate() > tau[k]},
                                              {"search_counterexamples", s.search_counterexamples},
                                              {"worst_objective", number(s.worst_objective)},
                                              {"examples", examples}};
  }
  nlohmann::json j = {{"verdict", Verdict()},
                      {"flagged", flagged},
                      {"reasons", reasons},
                      {"barrier", barrier},
                      {"dynamics", dynamics},
                      {"region", region},
                      {"unsafe_test", unsafe_test},
                      {"class_k", class_k},
                      {"dt", dt},
                      {"kinds", kinds},
                      {"options", options.ToJson()}};
  if (has_accuracy) {
    j["accuracy"] = {{"held_out_safe", held_out_safe},
                     {"held_out_near_dangerous", held_out_near_dangerous},
                     {"safe", accuracy_safe},
                     {"near_dangerous", accuracy_near_dangerous}};
  } else {
    j["accuracy"] = nullptr;
  }
  return j;
}

std::string CheckReport::Summary() const {
  std::ostringstream out;
  char line[256];
  if (has_accuracy) {
    std::snprintf(line, sizeof line,
                  "held-out accuracy: safe %.4f (%ld states), near-dangerous %.4f (%ld states)\n",
                  accuracy_safe, held_out_safe, accuracy_near_dangerous, held_out_near_dangerous);
    out << line;
  }
  const char* what[3] = {"(a) h >= 0 but no action with g >= 0",
                         "(b) near a near-dangerous state, h >= 0",
                         "(c) unsafe by the domain's test, h >= 0"};
  const double tau[3] = {thresholds.no_safe_action, thresholds.near_dangerous, thresholds.unsafe};
  for (int k = 0; k < 3; ++k) {
    const CheckKindStats& s = Stats(static_cast<CheckKind>(k));
    if (!s.available) {
      out << what[k] << ": not checked (the domain has no unsafe test)\n";
      continue;
    }
    std::snprintf(line, sizeof line,
                  "%s: %ld of %ld sampled (rate %.4f, threshold %g), local search %ld\n", what[k],
                  s.counterexamples, s.checked, s.rate(), tau[k], s.search_counterexamples);
    out << line;
  }
  out << "verdict: " << Verdict();
  for (std::size_t i = 0; i < reasons.size(); ++i) out << (i ? "; " : " (") << reasons[i];
  if (!reasons.empty()) out << ")";
  out << "\n";
  return out.str();
}

void CheckReport::WriteCsv(const std::string& path) const {
  std::string text = "kind,found_by";
  for (const std::string& f : features) text += "," + f;
  text += ",h,objective\n";
  for (const CheckExample& e : worst) {
    text += ToString(kCheckKindNames, e.kind);
    text += e.from_search ? ",search" : ",sample";
    for (long i = 0; i < e.state.size(); ++i) text += "," + FormatNumber(e.state[i]);
    text += "," + FormatNumber(e.h) + "," + FormatNumber(e.objective) + "\n";
  }
  WriteFileAtomically(path, text);
}

data::StateSet ReadCheckStates(const std::string& path, const std::vector<std::string>& features) {
  // A check without counterexamples writes a header-only file: that adds no states.
  CheckRegularInputFile(path);  // no FIFO, no device, within the input limit
  std::ifstream in(path);
  SECURE_CHECK(in.good(), path << ": cannot open the check CSV");
  std::string header, line;
  std::getline(in, header);
  bool has_rows = false;
  while (std::getline(in, line))
    if (line.find_first_not_of(" \t\r") != std::string::npos) has_rows = true;
  if (!has_rows) {
    data::StateSet empty;
    empty.source = path;
    empty.features = features;
    empty.states.resize(static_cast<long>(features.size()), 0);
    // Still check the columns, so that a file for another model is caught.
    std::set<std::string> names;
    std::stringstream cells(header);
    std::string cell;
    while (std::getline(cells, cell, ',')) {
      while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
      names.insert(cell);
    }
    for (const std::string& f : features)
      SECURE_CHECK(names.count(f), path << ": the check CSV has no column '" << f
                                        << "' (its header: " << header << ")");
    return empty;
  }
  return data::ReadStateSet(path, features);
}

}  // namespace secure::cbf
