// The experiment's options (experiment.h): ExperimentOptions and ClosedLoopCheckOptions
// (Validate, ApplyYaml, ToJson), the sensitivity experiment's barrier-data variants and each
// kind's default methods.
#include "secure/experiments/experiment.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/common/yaml_fields.h"
#include "secure/common/yaml_value.h"
#include "secure/experiments/internal/numbers.h"

namespace secure::experiments {
namespace {

using internal::Percent;

constexpr const char* kOptions = "ExperimentOptions";

long RoundedCount(double fraction, long n) {
  return std::max<long>(1, static_cast<long>(std::lround(fraction * static_cast<double>(n))));
}

}  // namespace

nlohmann::json BarrierDataVariant::ToJson() const {
  return {{"name", name},
          {"data_fraction", data_fraction},
          {"imbalance", imbalance},
          {"label_noise", label_noise}};
}

std::vector<BarrierDataVariant> SensitivityVariants(const std::vector<double>& data_fractions,
                                                    const std::vector<int>& imbalance_ratios,
                                                    const std::vector<double>& label_noise) {
  std::vector<BarrierDataVariant> variants = {{"baseline", 1.0, 1, 0.0}};
  for (double f : data_fractions)
    if (f != 1.0) variants.push_back({"data " + Percent(f), f, 1, 0.0});
  for (int k : imbalance_ratios)
    if (k != 1) variants.push_back({"imbalance 1:" + std::to_string(k), 1.0, k, 0.0});
  for (double p : label_noise)
    if (p != 0.0) variants.push_back({"label noise " + Percent(p), 1.0, 1, p});
  return variants;
}

void ApplyBarrierDataVariant(const BarrierDataVariant& v, std::uint64_t seed,
                             data::StateSet* safe, data::StateSet* near_dangerous) {
  SECURE_CHECK(v.data_fraction > 0 && v.data_fraction <= 1,
               "barrier data variant '" << v.name << "': data_fraction = " << v.data_fraction
                                        << ", must be in (0, 1]");
  SECURE_CHECK(v.imbalance >= 1, "barrier data variant '" << v.name << "': imbalance = "
                                                          << v.imbalance << ", must be >= 1");
  SECURE_CHECK(v.label_noise >= 0 && v.label_noise < 1,
               "barrier data variant '" << v.name << "': label_noise = " << v.label_noise
                                        << ", must be in [0, 1)");
  if (v.data_fraction == 1.0 && v.imbalance == 1 && v.label_noise == 0.0) return;
  Rng rng(seed ^ 0xda7a5e7ULL);
  auto shuffled = [&](const data::StateSet& set) {
    std::vector<long> order(static_cast<std::size_t>(set.size()));
    for (long i = 0; i < set.size(); ++i) order[static_cast<std::size_t>(i)] = i;
    Shuffle(order.begin(), order.end(), rng);
    return order;
  };
  std::vector<long> safe_order = shuffled(*safe), nd_order = shuffled(*near_dangerous);
  // Size and imbalance: keep a random subset of each class.
  const long n_safe = RoundedCount(v.data_fraction, safe->size());
  const long n_nd = RoundedCount(v.data_fraction / v.imbalance, near_dangerous->size());
  safe_order.resize(static_cast<std::size_t>(n_safe));
  nd_order.resize(static_cast<std::size_t>(n_nd));
  // Label noise: the first round(p n) of each (random) order change class.
  const long flip_safe = std::lround(v.label_noise * static_cast<double>(n_safe));
  const long flip_nd = std::lround(v.label_noise * static_cast<double>(n_nd));
  std::vector<long> new_safe(nd_order.begin(), nd_order.begin() + flip_nd);
  std::vector<long> new_nd(safe_order.begin(), safe_order.begin() + flip_safe);
  const std::vector<long> kept_safe(safe_order.begin() + flip_safe, safe_order.end());
  const std::vector<long> kept_nd(nd_order.begin() + flip_nd, nd_order.end());
  const Eigen::MatrixXf safe_states = safe->states, nd_states = near_dangerous->states;
  auto gather = [](const Eigen::MatrixXf& a, const std::vector<long>& ia, const Eigen::MatrixXf& b,
                   const std::vector<long>& ib) {
    Eigen::MatrixXf out(a.rows(), static_cast<long>(ia.size() + ib.size()));
    long c = 0;
    for (long i : ia) out.col(c++) = a.col(i);
    for (long i : ib) out.col(c++) = b.col(i);
    return out;
  };
  safe->states = gather(safe_states, kept_safe, nd_states, new_safe);
  near_dangerous->states = gather(nd_states, kept_nd, safe_states, new_nd);
  SECURE_CHECK(safe->size() > 0 && near_dangerous->size() > 0,
               "barrier data variant '" << v.name << "' leaves " << safe->size() << " safe and "
                                        << near_dangerous->size()
                                        << " near-dangerous states; both must be > 0");
}

std::vector<eval::Method> DefaultMethods(ExperimentKind kind) {
  using eval::Method;
  switch (kind) {
    case ExperimentKind::kMethodComparison: return {Method::kBc, Method::kAirl, Method::kSecure};
    case ExperimentKind::kJoint: return {Method::kAirl, Method::kSecure, Method::kJoint};
    case ExperimentKind::kAblation:
      return {Method::kSecure, Method::kSecureRandomSafe, Method::kSecureNoResampling,
              Method::kSecureMyopic};
    case ExperimentKind::kSensitivity: return {Method::kSecure};
  }
  SECURE_INTERNAL_CHECK(false, "unknown experiment kind");
  return {};
}

void ClosedLoopCheckOptions::Validate() const {
  constexpr const char* kOwner = "ClosedLoopCheckOptions";
  SECURE_CHECK_FIELD(episodes > 0 && episodes <= kMaxEpisodes, kOwner, "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  SECURE_CHECK_FIELD(min_success >= 0 && min_success <= 1, kOwner, "min_success", min_success,
                     "in [0, 1]");
  SECURE_CHECK_FIELD(max_dangerous >= 0 && max_dangerous <= 1, kOwner, "max_dangerous",
                     max_dangerous, "in [0, 1]");
  SECURE_CHECK_FIELD(max_candidates >= 1 && max_candidates <= 64, kOwner, "max_candidates",
                     max_candidates, "in [1, 64]");
  SECURE_CHECK_FIELD(repair_rounds >= 0 && repair_rounds <= 16, kOwner, "repair_rounds",
                     repair_rounds, "in [0, 16]");
  SECURE_CHECK_FIELD(repair_lookback >= 1 && repair_lookback <= 1000, kOwner, "repair_lookback",
                     repair_lookback, "in [1, 1000]");
}

void ClosedLoopCheckOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  YamlFields()
      .Field("enabled", &enabled)
      .Field("episodes", &episodes)
      .Field("min_success", &min_success)
      .Field("max_dangerous", &max_dangerous)
      .Field("max_candidates", &max_candidates)
      .Field("repair_rounds", &repair_rounds)
      .Field("repair_lookback", &repair_lookback)
      .Apply(node, source);
}

nlohmann::json ClosedLoopCheckOptions::ToJson() const {
  nlohmann::json j = {{"enabled", enabled},
                      {"episodes", episodes},
                      {"min_success", min_success},
                      {"max_dangerous", max_dangerous},
                      {"max_candidates", max_candidates}};
  // Only with repair, so that results without it keep their bytes.
  if (repair_rounds > 0) {
    j["repair_rounds"] = repair_rounds;
    j["repair_lookback"] = repair_lookback;
  }
  return j;
}

void ExperimentOptions::Validate() const {
  flat_barrier.Validate();
  per_obstacle_barrier.Validate();
  bc.Validate();
  airl.Validate();
  joint.Validate();
  shield.Validate();
  check.Validate();
  closed_loop.Validate();
  SECURE_CHECK_FIELD(seeds > 0 && seeds <= kMaxSeeds, kOptions, "seeds", seeds,
                     "in [1, " << kMaxSeeds << "]");
  SECURE_CHECK_FIELD(episodes > 0 && episodes <= kMaxEpisodes, kOptions, "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  // Seeds run in parallel, one worker each: more workers than seeds only idle, and 10^8 of
  // them "ran" (issue 34). 1024 as the user study's --threads.
  SECURE_CHECK_FIELD(threads > 0 && threads <= 1024, kOptions, "threads", threads,
                     "in [1, 1024]");
  // The last seed, first_seed + seeds - 1, must not wrap around to 0.
  SECURE_CHECK_FIELD(first_seed <= std::numeric_limits<std::uint64_t>::max() -
                                       static_cast<std::uint64_t>(seeds - 1),
                     kOptions, "first_seed", first_seed,
                     "at most 2^64 - seeds (the last seed, first_seed + seeds - 1 with seeds = "
                         << seeds << ", must not wrap around)");
  SECURE_CHECK_FIELD(shards >= 1, kOptions, "shards", shards, ">= 1");
  SECURE_CHECK_FIELD(shard >= 0 && shard < shards, kOptions, "shard", shard,
                     "in [0, shards - 1] (shards = " << shards << ")");
  SECURE_CHECK_FIELD(std::isfinite(evaluation.tost_bound) && evaluation.tost_bound > 0, kOptions,
                     "evaluation.tost_bound", evaluation.tost_bound, "> 0");
  for (double f : data_fractions)
    SECURE_CHECK_FIELD(f > 0 && f <= 1, kOptions, "data_fractions[]", f, "in (0, 1]");
  for (int k : imbalance_ratios)
    SECURE_CHECK_FIELD(k >= 1, kOptions, "imbalance_ratios[]", k, ">= 1");
  for (double p : label_noise)
    SECURE_CHECK_FIELD(p >= 0 && p < 1, kOptions, "label_noise[]", p, "in [0, 1)");
  SECURE_CHECK_FIELD(check_held_out > 0 && check_held_out <= kMaxStates, kOptions,
                     "check_held_out", check_held_out, "in [1, " << kMaxStates << "]");
}

namespace {

using SectionReader = std::function<void(const YAML::Node&, const std::string&)>;

// A section read whole by its options struct's ApplyYaml.
template <typename Options>
SectionReader ReadInto(Options* options) {
  return [options](const YAML::Node& node, const std::string& where) {
    options->ApplyYaml(node, where);
  };
}

// The `check:` section: the experiment's own keys (enabled, held_out, augment), the rest the
// check's options.
void ApplyCheckSection(const YAML::Node& node, const std::string& source, const std::string& where,
                       ExperimentOptions* o) {
  SECURE_CHECK(node.IsMap(), where << ": expected a mapping of check options");
  YAML::Node rest(YAML::NodeType::Map);
  for (const auto& item : node) {
    const std::string name = YamlKey(item.first, source);
    if (name == "enabled") {
      o->check_enabled = YamlValue<bool>(item.second, name, where);
    } else if (name == "held_out") {
      o->check_held_out = YamlValue<long>(item.second, name, where);
    } else if (name == "augment") {
      o->augment_flagged = YamlValue<bool>(item.second, name, where);
    } else {
      rest[name] = item.second;
    }
  }
  o->check.ApplyYaml(rest, where);
}

}  // namespace

void ExperimentOptions::ApplyYaml(const YAML::Node& node, const std::string& source,
                                  Domain* domain) {
  SECURE_CHECK(node.IsMap(), source << ": the experiment configuration must be a mapping");
  // The sections, in the order the error lists them; `barrier` is the kind's barrier.
  std::vector<std::pair<std::string, SectionReader>> sections = {
      {"barrier", barrier_kind == BarrierKind::kPerObstacle ? ReadInto(&per_obstacle_barrier)
                                                            : ReadInto(&flat_barrier)},
      {"flat_barrier", ReadInto(&flat_barrier)},
      {"per_obstacle_barrier", ReadInto(&per_obstacle_barrier)},
      {"bc", ReadInto(&bc)},
      {"airl", ReadInto(&airl)},
      {"joint", ReadInto(&joint)},
      {"shield", ReadInto(&shield)},
      {"check",
       [this, &source](const YAML::Node& n, const std::string& where) {
         ApplyCheckSection(n, source, where, this);
       }},
      {"closed_loop", ReadInto(&closed_loop)},
  };
  if (domain != nullptr) sections.emplace_back("domain", ReadInto(domain));
  for (const auto& entry : node) {
    const std::string key = YamlKey(entry.first, source);
    const auto section = std::find_if(sections.begin(), sections.end(),
                                      [&key](const auto& s) { return s.first == key; });
    if (section == sections.end()) {
      std::vector<std::string> valid;
      for (const auto& s : sections) valid.push_back(s.first);
      SECURE_THROW(source << ": unknown section '" << key << "' (valid: " << Join(valid) << ")");
    }
    section->second(entry.second, source + " [" + key + "]");
  }
}

nlohmann::json ExperimentOptions::ToJson() const {
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json j = {{"data_seed", data_seed},
          {"barrier_kind", ToString(kBarrierKindNames, barrier_kind)},
          {"flat_barrier", flat_barrier.ToJson()},
          {"per_obstacle_barrier", per_obstacle_barrier.ToJson()},
          {"bc", bc.ToJson()},
          {"airl", airl.ToJson()},
          {"airl_warm_start", airl_warm_start},
          {"joint", joint.ToJson()},
          {"shield", shield.ToJson()},
          {"methods", method_names},
          {"seeds", seeds},
          {"episodes", episodes},
          {"first_seed", first_seed},
          {"data_fractions", data_fractions},
          {"imbalance_ratios", imbalance_ratios},
          {"label_noise", label_noise},
          {"check_enabled", check_enabled},
          {"check_held_out", check_held_out},
          {"check", check.ToJson()},
          {"augment_flagged", augment_flagged},
          {"threads", threads}};
  if (closed_loop.enabled) j["closed_loop"] = closed_loop.ToJson();
  return j;
}

}  // namespace secure::experiments
