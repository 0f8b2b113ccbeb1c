#include "secure/experiments/experiment.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <ostream>
#include <sstream>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/common/yaml_value.h"
#include "secure/experiments/internal/seed_runner.h"
#include "secure/nn/torch_threads.h"

namespace secure::experiments {
namespace {

using internal::Progress;

constexpr const char* kOptions = "ExperimentOptions";


std::string Percent(double fraction) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g%%", 100.0 * fraction);
  return buffer;
}

bool Any(const std::vector<eval::Method>& methods, bool (*predicate)(eval::Method)) {
  return std::any_of(methods.begin(), methods.end(), predicate);
}
// Methods that run the AIRL policy (AIRL itself and every SECURE variant).
bool UsesAirlPolicy(eval::Method m) { return !eval::UsesBcPolicy(m) && !eval::UsesJointPolicy(m); }
bool NeedsBarrier(eval::Method m) { return eval::IsShielded(m) || eval::UsesJointPolicy(m); }

// "prefix.ext" for the baseline variant, "prefix_<name>.ext" (name made file-safe) otherwise.
std::string VariantFile(const std::string& prefix, const BarrierDataVariant& variant,
                        const std::string& ext) {
  if (variant.name == "baseline") return prefix + ext;
  std::string name = variant.name;
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return prefix + "_" + name + ext;
}

// A learned barrier of either kind, with a factory of evaluators for the shields.
struct SeedBarrier {
  std::optional<cbf::CarBarrierNet> per_obstacle;
  std::optional<cbf::BarrierNet> flat;
  nlohmann::json summary;

  // Evaluators on the domain's observations (`env`): a flat barrier that reads a subset of them
  // (BarrierTrainerOptions::input_features) gets its rows picked by name.
  std::function<std::unique_ptr<cbf::Barrier>()> Factory(const Domain& domain,
                                                         const domains::Environment& env) const {
    if (per_obstacle) return [this] { return per_obstacle->MakeEvaluator(256); };
    // Checked once here, so that a mismatch fails before any evaluation.
    const std::vector<std::string> features = env.ObservationFeatures();
    const std::string source = "the " + domain.name() + " domain's observations";
    cbf::FeatureRows(flat->features, features, source, "the flat barrier");
    return [this, features, source] {
      return flat->MakeEvaluatorFor(features, source, "the flat barrier", 256);
    };
  }
  void Save(const std::string& path) const {
    if (per_obstacle) per_obstacle->Save(path);
    if (flat) flat->Save(path);
  }
};

SeedBarrier TrainSeedBarrier(const ExperimentOptions& o, std::uint64_t seed,
                             const data::StateSet& safe, const data::StateSet& near_dangerous,
                             std::string* brief) {
  SeedBarrier b;
  if (o.barrier_kind == BarrierKind::kPerObstacle) {
    cbf::CarBarrierTrainerOptions options = o.per_obstacle_barrier;
    options.seed = seed;
    options.verbose = false;
    cbf::CarBarrierTrainingSummary summary;
    b.per_obstacle = cbf::TrainCarBarrier(options, safe, near_dangerous, &summary);
    b.summary = summary.ToJson();
    *brief = summary.BriefReport();
  } else {
    cbf::BarrierTrainerOptions options = o.flat_barrier;
    options.seed = seed;
    options.verbose = false;
    cbf::BarrierTrainingSummary summary;
    b.flat = cbf::TrainBarrier(options, safe, near_dangerous, &summary);
    b.summary = summary.ToJson();
    *brief = summary.BriefReport();
  }
  return b;
}

// Everything one seed produces: per variant, the method results.
struct SeedOutcome {
  std::vector<std::map<eval::Method, eval::SeedResult>> results;  // per variant
  nlohmann::json summary = nlohmann::json::object();
};

struct SharedData {
  DomainData data;
  bool check = false;
  data::StateSet check_safe, check_near_dangerous;  // held-out, for the barrier check
};

// The barrier check of one seed's barrier.
cbf::CheckReport CheckSeedBarrier(const Domain& domain, const ExperimentOptions& o,
                                  const SharedData& shared,
                                  const std::function<std::unique_ptr<cbf::Barrier>()>& factory) {
  std::unique_ptr<domains::DynamicsModel> dynamics;
  const cbf::BarrierCheckProblem problem = domain.MakeCheckProblem(
      o.shield, shared.check_safe, shared.check_near_dangerous, &dynamics);
  const std::unique_ptr<cbf::Barrier> barrier = factory();
  return cbf::CheckBarrier(*barrier, *dynamics, problem, o.check);
}

std::string CheckBrief(const cbf::CheckReport& r) {
  char line[256];
  std::snprintf(line, sizeof line, "%s (a %.3f, b %.3f, c %.3f; held-out accuracy %.3f / %.3f)",
                r.Verdict().c_str(), r.no_safe_action.rate(), r.near_dangerous.rate(),
                r.unsafe.rate(), r.accuracy_safe, r.accuracy_near_dangerous);
  return line;
}

SeedOutcome RunSeed(const Domain& domain, const ExperimentOptions& o,
                    const std::vector<eval::Method>& methods, int index, const SharedData& shared,
                    const domains::Environment& env,
                    const std::vector<BarrierDataVariant>& variants, Progress& progress) {
  const std::uint64_t seed = o.first_seed + static_cast<std::uint64_t>(index);
  const std::string tag = "[seed " + std::to_string(seed) + "]";
  const std::string dir =
      o.output_dir.empty() ? "" : o.output_dir + "/seed-" + std::to_string(seed);
  CreateDirectories(dir);
  const data::TrajectorySet& demos = shared.data.demonstrations;
  SeedOutcome outcome;
  nlohmann::json& timings = outcome.summary["seconds"];
  const bool needs_airl = Any(methods, UsesAirlPolicy);
  const bool needs_joint = Any(methods, eval::UsesJointPolicy);
  const bool needs_barrier = Any(methods, NeedsBarrier);

  // BC (a method, and the warm start of AIRL and the joint policy).
  std::optional<policy::GaussianPolicy> bc;
  if (Any(methods, eval::UsesBcPolicy) || ((needs_airl || needs_joint) && o.airl_warm_start)) {
    const Stopwatch clock;
    policy::BcOptions options = o.bc;
    options.seed = seed;
    options.verbose = false;
    if (!dir.empty()) options.curve_path = dir + "/bc_curve.csv";
    policy::BcSummary summary;
    bc = policy::TrainBc(options, demos, &summary);
    outcome.summary["bc"] = summary.ToJson();
    timings["bc"] = clock.Seconds();
    if (!dir.empty()) bc->Save(dir + "/bc.model");
    progress.Line([&](std::ostream& out) {
      out << tag << " " << summary.BriefReport();
    });
  }

  // AIRL.
  std::optional<policy::GaussianPolicy> airl;
  if (needs_airl) {
    const Stopwatch clock;
    policy::AirlOptions options = o.airl;
    options.seed = seed;
    options.verbose = false;
    if (!dir.empty()) options.curve_path = dir + "/airl_curve.csv";
    policy::AirlSummary summary;
    const int report_every = std::max(1, options.iterations / 4);
    airl = policy::TrainAirl(
        options, demos, env, o.airl_warm_start ? &*bc : nullptr, &summary,
        [&](const policy::AirlIterationStats& stats) {
          if (stats.iteration % report_every == 0) {
            progress.Line([&](std::ostream& out) {
              out << tag << " AIRL iteration " << stats.iteration << "/" << options.iterations
                  << ": rollout success " << stats.success_rate << ", collisions "
                  << stats.collision_rate << " (" << clock.Seconds() << " s)";
            });
          }
          return true;
        });
    outcome.summary["airl"] = summary.ToJson();
    timings["airl"] = clock.Seconds();
    if (!dir.empty()) airl->Save(dir + "/airl.model");
    progress.Line([&](std::ostream& out) {
      out << tag << " " << summary.BriefReport();
    });
  }

  // One barrier per data variant (only the baseline outside `sensitivity`), each followed by its
  // evaluation.
  outcome.summary["barriers"] = nlohmann::json::object();
  double barrier_seconds = 0.0, evaluation_seconds = 0.0;
  for (const BarrierDataVariant& variant : variants) {
    Stopwatch clock;
    std::optional<SeedBarrier> barrier;
    if (needs_barrier) {
      data::StateSet safe = shared.data.safe, near_dangerous = shared.data.near_dangerous;
      ApplyBarrierDataVariant(variant, seed, &safe, &near_dangerous);
      std::string brief;
      barrier = TrainSeedBarrier(o, seed, safe, near_dangerous, &brief);
      nlohmann::json& record = outcome.summary["barriers"][variant.name];
      record = {{"safe_states", safe.size()},
                {"near_dangerous_states", near_dangerous.size()},
                {"training", barrier->summary}};
      barrier_seconds += clock.Seconds();
      if (!dir.empty()) barrier->Save(dir + "/" + VariantFile("barrier", variant, ".model"));
      progress.Line([&](std::ostream& out) {
        out << tag << " barrier (" << variant.name << ", " << safe.size() << " safe + "
            << near_dangerous.size() << " near-dangerous): " << brief << " (" << clock.Seconds()
            << " s)";
      });

      // The pre-deployment check (its own streams; nothing above or below depends on it), and
      // with augment_flagged one retraining round with the counterexamples as near-dangerous
      // states.
      if (shared.check) {
        const Stopwatch check_clock;
        cbf::CheckReport report = CheckSeedBarrier(domain, o, shared, barrier->Factory(domain, env));
        record["check"] = report.ToJson();
        record["check"]["seconds"] = check_clock.Seconds();
        if (!dir.empty()) report.WriteCsv(dir + "/" + VariantFile("check", variant, ".csv"));
        progress.Line([&](std::ostream& out) {
          out << tag << " barrier check (" << variant.name << "): " << CheckBrief(report) << " ("
              << check_clock.Seconds() << " s)";
        });
        if (o.augment_flagged && report.flagged && !report.worst.empty()) {
          const Stopwatch augment_clock;
          const long added = static_cast<long>(report.worst.size());
          Eigen::MatrixXf states(near_dangerous.states.rows(), near_dangerous.size() + added);
          states.leftCols(near_dangerous.size()) = near_dangerous.states;
          for (long i = 0; i < added; ++i)
            states.col(near_dangerous.size() + i) = report.worst[static_cast<std::size_t>(i)].state;
          near_dangerous.states = std::move(states);
          barrier = TrainSeedBarrier(o, seed, safe, near_dangerous, &brief);
          cbf::CheckReport after = CheckSeedBarrier(domain, o, shared, barrier->Factory(domain, env));
          record["augmented"] = {{"added_near_dangerous_states", added},
                                 {"training", barrier->summary},
                                 {"check", after.ToJson()},
                                 {"seconds", augment_clock.Seconds()}};
          progress.Line([&](std::ostream& out) {
            out << tag << " barrier retrained with " << added
                << " counterexamples as near-dangerous states: " << brief << "; check "
                << CheckBrief(after) << " (" << augment_clock.Seconds() << " s)";
          });
          if (!dir.empty())
            barrier->Save(dir + "/" + VariantFile("barrier", variant, "_augmented.model"));
        }
        if (&variant == &variants.front()) {
          outcome.summary["check"] = record["check"];
          if (record.contains("augmented"))
            outcome.summary["check_augmented"] = record["augmented"]["check"];
        }
      }
    }

    // The joint policy needs the (baseline) barrier.
    std::optional<policy::GaussianPolicy> joint;
    if (needs_joint) {
      SECURE_INTERNAL_CHECK(barrier.has_value(), "the joint method trains a barrier");
      clock.Restart();
      policy::AirlOptions options = o.airl;
      options.seed = seed;
      options.verbose = false;
      if (!dir.empty()) options.curve_path = dir + "/joint_curve.csv";
      policy::AirlSummary summary;
      const policy::GaussianPolicy* start = o.airl_warm_start ? &*bc : nullptr;
      joint = barrier->per_obstacle
                  ? policy::TrainAirlJoint(options, o.joint, *barrier->per_obstacle,
                                           env.ShieldModel(), demos, env, start, &summary)
                  : policy::TrainAirlJoint(options, o.joint, *barrier->flat, env.ShieldModel(),
                                           demos, env, start, &summary);
      outcome.summary["joint"] = summary.ToJson();
      timings["joint"] = clock.Seconds();
      if (!dir.empty()) joint->Save(dir + "/joint.model");
      progress.Line([&](std::ostream& out) {
        out << tag << " joint (AIRL + CBF loss): " << summary.BriefReport() << " ("
            << clock.Seconds() << " s)";
      });
    }

    clock.Restart();
    eval::SeedModels models;
    models.bc = bc ? &*bc : nullptr;
    models.airl = airl ? &*airl : nullptr;
    models.joint = joint ? &*joint : nullptr;
    if (barrier) models.make_barrier = barrier->Factory(domain, env);
    outcome.results.push_back(eval::EvaluateMethods(env, methods, models, o.shield, o.episodes,
                                                    eval::EvaluationSeed(seed)));
    evaluation_seconds += clock.Seconds();
    progress.Line([&](std::ostream& out) {
      out << tag << " evaluated";
      if (variants.size() > 1) out << " (" << variant.name << ")";
      out << ":";
      for (const auto& [method, r] : outcome.results.back()) {
        out << " " << ToString(eval::kMethodNames, method) << " " << 100.0 * r.success_rate()
            << "%/" << 100.0 * r.dangerous_rate() << "%";
      }
      out << " (success/dangerous, " << clock.Seconds() << " s)";
    });
  }
  timings["barriers"] = barrier_seconds;
  timings["evaluation"] = evaluation_seconds;
  return outcome;
}

long RoundedCount(double fraction, long n) {
  return std::max<long>(1, static_cast<long>(std::lround(fraction * static_cast<double>(n))));
}


}  // namespace

// ---------------------------------------------------------------------------------------------
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

void ExperimentOptions::Validate() const {
  flat_barrier.Validate();
  per_obstacle_barrier.Validate();
  bc.Validate();
  airl.Validate();
  joint.Validate();
  shield.Validate();
  check.Validate();
  SECURE_CHECK_FIELD(seeds > 0 && seeds <= kMaxSeeds, kOptions, "seeds", seeds,
                     "in [1, " << kMaxSeeds << "]");
  SECURE_CHECK_FIELD(episodes > 0 && episodes <= kMaxEpisodes, kOptions, "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  SECURE_CHECK_FIELD(threads > 0, kOptions, "threads", threads, "> 0");
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

void ExperimentOptions::ApplyYaml(const YAML::Node& node, const std::string& source,
                                  Domain* domain) {
  SECURE_CHECK(node.IsMap(), source << ": the experiment configuration must be a mapping");
  for (const auto& entry : node) {
    const std::string key = YamlKey(entry.first, source);
    const std::string where = source + " [" + key + "]";
    if (key == "barrier") {
      if (barrier_kind == BarrierKind::kPerObstacle) {
        per_obstacle_barrier.ApplyYaml(entry.second, where);
      } else {
        flat_barrier.ApplyYaml(entry.second, where);
      }
    } else if (key == "flat_barrier") {
      flat_barrier.ApplyYaml(entry.second, where);
    } else if (key == "per_obstacle_barrier") {
      per_obstacle_barrier.ApplyYaml(entry.second, where);
    } else if (key == "bc") {
      bc.ApplyYaml(entry.second, where);
    } else if (key == "airl") {
      airl.ApplyYaml(entry.second, where);
    } else if (key == "joint") {
      joint.ApplyYaml(entry.second, where);
    } else if (key == "check") {
      SECURE_CHECK(entry.second.IsMap(), where << ": expected a mapping of check options");
      YAML::Node rest(YAML::NodeType::Map);
      for (const auto& item : entry.second) {
        const std::string name = YamlKey(item.first, source);
        if (name == "enabled") {
          check_enabled = YamlValue<bool>(item.second, name, where);
        } else if (name == "held_out") {
          check_held_out = YamlValue<long>(item.second, name, where);
        } else if (name == "augment") {
          augment_flagged = YamlValue<bool>(item.second, name, where);
        } else {
          rest[name] = item.second;
        }
      }
      check.ApplyYaml(rest, where);
    } else if (key == "domain" && domain != nullptr) {
      domain->ApplyYaml(entry.second, where);
    } else {
      SECURE_THROW(source << ": unknown section '" << key
                          << "' (valid: barrier, flat_barrier, per_obstacle_barrier, bc, airl, "
                             "joint, check"
                          << (domain != nullptr ? ", domain" : "") << ")");
    }
  }
}

nlohmann::json ExperimentOptions::ToJson() const {
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : methods) method_names.push_back(ToString(eval::kMethodNames, m));
  return {{"data_seed", data_seed},
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
}

// ---------------------------------------------------------------------------------------------
nlohmann::json ExperimentResult::ToJson() const {
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json experiment_json = {
      {"kind", ToString(kExperimentKindNames, kind)},
      {"domain", domain},
      {"domain_options", domain_options},
      {"methods", method_names},
      {"demonstrations", demonstrations},
      {"discarded_demonstrations", discarded_demonstrations},
      {"demonstration_steps", demonstration_steps},
      {"safe_states", safe_states},
      {"near_dangerous_states", near_dangerous_states},
      {"seeds", seed_summaries},
      {"data_seconds", data_seconds},
      {"seconds", seconds},
      {"options", options.ToJson()}};
  if (kind != ExperimentKind::kSensitivity) {
    nlohmann::json j = evaluations.front().second.ToJson();
    j["experiment"] = std::move(experiment_json);
    return j;
  }
  nlohmann::json by_variant = nlohmann::json::object();
  for (std::size_t i = 0; i < evaluations.size(); ++i) {
    nlohmann::json e = evaluations[i].second.ToJson();
    e["variant"] = variants[i].ToJson();
    by_variant[evaluations[i].first] = std::move(e);
  }
  return {{"variants", std::move(by_variant)}, {"experiment", std::move(experiment_json)}};
}

std::string ExperimentResult::Table() const {
  std::ostringstream out;
  out << "SECURE on " << domain_title << ": " << ToString(kExperimentKindNames, kind) << " ("
      << ToString(kBarrierKindNames, options.barrier_kind) << " barrier from " << safe_states
      << " safe + " << near_dangerous_states << " near-dangerous states; " << demonstrations
      << " expert demonstrations)\n\n";
  if (kind != ExperimentKind::kSensitivity) {
    out << evaluations.front().second.Table();
    out << CheckTable();
    return out.str();
  }
  const std::size_t seeds = options.seeds;
  out << "SECURE with barriers learned from modified data, % mean (std) over " << seeds
      << " seeds x " << options.episodes << " episodes\n\n";
  out << "| barrier data | safe : near-dangerous states | success % | dangerous % | "
         "interventions / episode | no-safe-action |\n|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < evaluations.size(); ++i) {
    const eval::MethodSummary& s = evaluations[i].second.methods().at(eval::Method::kSecure);
    long no_safe = 0;
    for (const eval::SeedResult& r : s.per_seed) no_safe += r.no_safe_action_decisions;
    const nlohmann::json& barrier = seed_summaries.front()["barriers"][evaluations[i].first];
    char line[512];
    std::snprintf(line, sizeof line, "| %s | %s | %.1f (%.1f) | %.1f (%.1f) | %.2f | %ld |\n",
                  evaluations[i].first.c_str(),
                  (std::to_string(barrier.value("safe_states", 0L)) + " : " +
                   std::to_string(barrier.value("near_dangerous_states", 0L)))
                      .c_str(),
                  100 * s.success_rate.mean, 100 * s.success_rate.std,
                  100 * s.dangerous_rate.mean, 100 * s.dangerous_rate.std,
                  s.interventions_per_episode.mean, no_safe);
    out << line;
  }
  out << CheckTable();
  return out.str();
}

std::string ExperimentResult::CheckTable() const {
  if (seed_summaries.empty() || !seed_summaries.front().contains("check")) return "";
  const auto& evaluated = evaluations.front().second.methods();
  const auto secure_it = evaluated.find(eval::Method::kSecure);
  std::ostringstream out;
  out << "\nBarrier check per seed (" << evaluations.front().first
      << " barrier; rates: (a) h >= 0 without an action with g >= 0, (b) near a near-dangerous "
         "state with h >= 0, (c) unsafe by the domain's own test with h >= 0)\n\n"
      << "| seed | check | rate (a) | rate (b) | rate (c) | held-out accuracy safe / nd | "
         "SECURE dangerous % |\n|---|---|---|---|---|---|---|\n";
  long flagged = 0;
  for (std::size_t i = 0; i < seed_summaries.size(); ++i) {
    const nlohmann::json& c = seed_summaries[i]["check"];
    const nlohmann::json& kinds = c["kinds"];
    const bool is_flagged = c.value("flagged", false);
    flagged += is_flagged;
    std::string dangerous = "-";
    if (secure_it != evaluated.end() && i < secure_it->second.per_seed.size()) {
      char buffer[32];
      std::snprintf(buffer, sizeof buffer, "%.1f",
                    100 * secure_it->second.per_seed[i].dangerous_rate());
      dangerous = buffer;
    }
    std::string verdict = is_flagged ? "**flagged**" : "pass";
    if (seed_summaries[i].contains("check_augmented"))
      verdict +=
          std::string(" -> retrained: ") +
          (seed_summaries[i]["check_augmented"].value("flagged", false) ? "flagged" : "pass");
    double acc_safe = 0, acc_nd = 0;
    if (c.contains("accuracy") && c["accuracy"].is_object()) {
      acc_safe = c["accuracy"].value("safe", 0.0);
      acc_nd = c["accuracy"].value("near_dangerous", 0.0);
    }
    char line[256];
    std::snprintf(line, sizeof line, "| %llu | %s | %.4f | %.4f | %.4f | %.3f / %.3f | %s |\n",
                  static_cast<unsigned long long>(options.first_seed + i), verdict.c_str(),
                  kinds["no_safe_action"].value("rate", 0.0),
                  kinds["near_dangerous"].value("rate", 0.0), kinds["unsafe"].value("rate", 0.0),
                  acc_safe, acc_nd, dangerous.c_str());
    out << line;
  }
  out << "\n"
      << flagged << " of " << seed_summaries.size()
      << " seeds flagged (thresholds: " << options.check.thresholds.ToJson().dump() << ").\n";
  return out.str();
}

ExperimentResult RunExperiment(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& o, std::ostream* out) {
  domain.Validate();
  o.Validate();
  domain.CheckExperiment(o);
  const std::vector<eval::Method> methods = o.methods.empty() ? DefaultMethods(kind) : o.methods;
  SECURE_CHECK(kind != ExperimentKind::kSensitivity ||
                   std::find(methods.begin(), methods.end(), eval::Method::kSecure) !=
                       methods.end(),
               "the sensitivity experiment reports SECURE: its methods must include secure");
  // Before any work, so that an unusable --out (a file, a read-only place) fails at once.
  CreateDirectories(o.output_dir);
  const Stopwatch clock;
  Progress progress(out, o.verbose);
  nn::SetTorchThreads(1);  // parallelism comes from the seeds; 1 is fastest for small nets
  ExperimentResult result;
  result.kind = kind;
  result.domain = domain.name();
  result.domain_title = domain.Title();
  result.domain_options = domain.OptionsJson();
  result.methods = methods;
  result.options = o;

  // 1. Data.
  SharedData shared;
  shared.data = domain.GenerateData(o.data_seed);
  shared.check = o.check_enabled && domain.HasCheck() && Any(methods, NeedsBarrier);
  if (shared.check) {
    domain.CheckHeldOut(o.data_seed, o.check_held_out, &shared.check_safe,
                        &shared.check_near_dangerous);
  }
  const DomainData& data = shared.data;
  result.demonstrations = data.demonstrations.num_episodes();
  result.discarded_demonstrations = data.discarded_demonstrations;
  result.demonstration_steps = data.demonstrations.num_steps();
  result.safe_states = data.safe.size();
  result.near_dangerous_states = data.near_dangerous.size();
  result.data_seconds = clock.Seconds();
  if (!o.output_dir.empty()) {
    data::WriteTrajectories(o.output_dir + "/demos.csv", data.demonstrations);
    data::WriteStateSet(o.output_dir + "/safe.csv", data.safe);
    data::WriteStateSet(o.output_dir + "/near_dangerous.csv", data.near_dangerous);
    if (shared.check) {
      data::WriteStateSet(o.output_dir + "/check_safe.csv", shared.check_safe);
      data::WriteStateSet(o.output_dir + "/check_near_dangerous.csv", shared.check_near_dangerous);
    }
  }
  progress.Line([&](std::ostream& line) {
    line << "data: " << result.demonstrations << " expert demonstrations ("
         << result.discarded_demonstrations << " discarded), " << result.demonstration_steps
         << " steps; " << result.safe_states << " safe and " << result.near_dangerous_states
         << " near-dangerous states (" << clock.Seconds() << " s)";
  });

  // 2. Seeds, on `threads` workers taking the next seed index.
  result.variants = kind == ExperimentKind::kSensitivity
                        ? SensitivityVariants(o.data_fractions, o.imbalance_ratios, o.label_noise)
                        : std::vector<BarrierDataVariant>{{"baseline", 1.0, 1, 0.0}};
  const std::unique_ptr<domains::Environment> env = domain.MakeEnvironment();
  std::vector<SeedOutcome> outcomes(static_cast<std::size_t>(o.seeds));
  internal::RunJobsInParallel(
      o.seeds, o.threads,
      [&](int i) {
        outcomes[static_cast<std::size_t>(i)] =
            RunSeed(domain, o, methods, i, shared, *env, result.variants, progress);
      },
      "seed", static_cast<long>(o.first_seed));

  // 3. Across seeds, one evaluation per variant.
  for (std::size_t v = 0; v < result.variants.size(); ++v) {
    eval::Evaluation evaluation(o.evaluation);
    for (const SeedOutcome& outcome : outcomes)
      for (const auto& [method, r] : outcome.results[v]) evaluation.Add(method, r);
    evaluation.Finish();
    result.evaluations.emplace_back(
        kind == ExperimentKind::kSensitivity ? result.variants[v].name : "main",
        std::move(evaluation));
  }
  for (const SeedOutcome& outcome : outcomes) result.seed_summaries.push_back(outcome.summary);
  result.seconds = clock.Seconds();
  if (!o.output_dir.empty()) {
    WriteFileAtomically(o.output_dir + "/result.json", result.ToJson().dump(2) + "\n");
  }
  return result;
}

}  // namespace secure::experiments
