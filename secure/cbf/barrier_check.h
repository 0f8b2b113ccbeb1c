#pragma once
// A check of a learned barrier before deployment: held-out accuracy, and a counterexample search
// for the three ways a barrier that "looks accurate" can still fail in closed loop.
//
//   (a) no_safe_action  states the barrier calls safe (h(s) >= 0) from which no action in the
//                       action box satisfies the shield's condition
//                         g(s, a) = (h(T(s, a)) - h(s)) / dt + alpha(h(s)) >= 0
//                       (the shield would have nothing to return). Objective: max_a g over the
//                       box (approximate: a grid, random actions and a shrinking refinement),
//                       a counterexample when it is < 0.
//   (b) near_dangerous  states within `near_radius` (L-infinity, in normalised units: each
//                       feature divided by its standard deviation over the labelled
//                       near-dangerous set) of a labelled near-dangerous state with h >= 0.
//                       Objective: h, a counterexample when h >= 0.
//   (c) unsafe          states the caller's ground truth / collision test calls unsafe with
//                       h >= 0 (only when a predicate is given). Objective: h.
//
// How: `region_samples` states from the caller's region sampler serve (a) (those with h >= 0)
// and (c) (those the predicate calls unsafe); `near_samples` states drawn uniformly in the boxes
// around randomly chosen near-dangerous states serve (b). The RATES (the verdict's inputs) are
// counterexamples / eligible samples of this sampling phase, i.e. estimates over the sampling
// distribution. Then a gradient-free local search (an elitist (1 + lambda) evolution strategy:
// step x1.5 after an improvement, x0.6 after none, moves along plateaus) starts from the
// `search_starts` most promising samples of each kind (ties: the smaller h first) and
// pushes the objective further (lower max_a g, higher h), staying eligible (h >= 0 for (a); inside
// the near-dangerous box for (b); unsafe for (c)); its results feed the worst examples (and the
// counts `search_counterexamples`), not the rates.
//
// Limits: (a) is judged under the given dynamics model (the shield's), so the model's own blind
// spots are invisible to it as they are to the shield; the rates estimate failures over the
// sampling distribution only. A passing check is a screen, not a certificate (docs/RESULTS.md:
// on Derby it flags the flat MLP barrier but not a velocity-aware per-car barrier that fails).
//
// Generic: the inputs are a Barrier, a DynamicsModel, an action box, the class-K function, a
// region sampler and an optional unsafe predicate; the glue of a concrete domain (its region,
// predicate, dynamics and box) lives with the domain (experiments::Domain::MakeCheckProblem),
// which the CLI's `cbf check` and the experiments call.
// Deterministic for a seed; the check uses its own Rng only.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"

namespace YAML {
class Node;
}

namespace secure::cbf {

enum class CheckKind { kNoSafeAction, kNearDangerous, kUnsafe };
inline constexpr EnumTable<CheckKind, 3> kCheckKindNames{{
    {CheckKind::kNoSafeAction, "no_safe_action"},
    {CheckKind::kNearDangerous, "near_dangerous"},
    {CheckKind::kUnsafe, "unsafe"},
}};

/// A barrier is flagged when a rate exceeds its threshold (strictly), or when the held-out
/// accuracy of a class falls below its minimum.
struct CheckThresholds {
  double no_safe_action = 0.01;    // tau_a: rate (a) over states with h >= 0
  double near_dangerous = 0.05;    // tau_b: rate (b) over states near the near-dangerous set
  double unsafe = 0.01;            // tau_c: rate (c) over states the predicate calls unsafe
  double min_accuracy_safe = 0.0;  // held-out safe accuracy below this flags (0: off)
  double min_accuracy_near_dangerous = 0.0;  // held-out near-dangerous accuracy (0: off)

  void Validate() const;
  nlohmann::json ToJson() const;
};

struct BarrierCheckOptions {
  long region_samples = 1000;    // states from the region sampler, for (a) and (c)
  long near_samples = 1000;      // states around the near-dangerous set, for (b)
  double near_radius = 0.05;     // (b)'s box half-width, in per-feature standard deviations
  int action_grid = 7;           // max_a g: points per action dimension of a grid over the box
                                 // (used while action_grid^action_dim <= 4096, else none)
  int action_samples = 16;       // max_a g: uniform random actions, and per refinement round
  int action_refine_rounds = 2;  // max_a g: rounds around the best action, each half as wide
  int search_starts = 4;         // local search: starts per kind (the most promising samples)
  int search_steps = 10;         // local search: iterations per start
  int search_population = 6;     // local search: candidates per iteration (lambda)
  double search_step = 0.05;     // local search: initial step, in per-feature standard deviations
                                 // of the sampled states (of the near-dangerous set for (b))
  int worst_examples = 20;       // counterexamples kept per kind (the worst first)
  std::uint64_t seed = 0x0c4ec4ULL;  // the check's own stream
  CheckThresholds thresholds;

  /// Throws secure::Error naming the field ("BarrierCheckOptions::near_radius = nan, must be
  /// finite and > 0").
  void Validate() const;
  nlohmann::json ToJson() const;
  /// Overrides the fields present in `node` (the keys of ToJson(); `thresholds` is a mapping
  /// with the keys of CheckThresholds::ToJson()); unknown keys are errors naming `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// What the check needs besides the barrier and the dynamics. The glue of a domain fills it.
struct BarrierCheckProblem {
  Eigen::VectorXf action_lo, action_hi;   // the action box (action_dim each, lo <= hi)
  double dt = 0.1;                        // dt in g (the shield's)
  std::function<double(double)> class_k;  // alpha(h) (the shield's)
  std::string class_k_description;        // e.g. "linear, k = 2", for reports
  /// Draws one state of the region into `state` (state_dim).
  std::function<void(Rng&, Eigen::Ref<Eigen::VectorXf>)> sample_region;
  /// Optional: maps a state moved by the local search back into the region (e.g. a box clamp).
  std::function<void(Eigen::Ref<Eigen::VectorXf>)> project;
  /// Optional: the domain's own "this state is unsafe" (ground truth, collision test): (c).
  std::function<bool(const Eigen::Ref<const Eigen::VectorXf>&)> is_unsafe;
  std::string is_unsafe_description;  // e.g. "ground truth h < 0"
  data::StateSet near_dangerous;      // labelled near-dangerous states, for (b) (non-empty)
  /// Optional held-out labelled states for the accuracy per class (both or neither).
  std::optional<data::StateSet> held_out_safe, held_out_near_dangerous;
  std::string region_description;  // for reports
};

struct CheckKindStats {
  bool available = true;            // false for (c) without a predicate
  long checked = 0;                 // eligible samples (the rate's denominator)
  long counterexamples = 0;         // eligible samples that are counterexamples
  long search_counterexamples = 0;  // local-search runs that ended in a counterexample
  double worst_objective = 0.0;     // over samples and search (NaN if nothing was eligible)
  double rate() const { return checked > 0 ? double(counterexamples) / double(checked) : 0.0; }
};

struct CheckExample {
  CheckKind kind = CheckKind::kNoSafeAction;
  bool from_search = false;
  Eigen::VectorXf state;
  double h = 0.0;
  double objective = 0.0;  // (a): max_a g; (b), (c): h
};

struct CheckReport {
  std::string barrier, dynamics, region, unsafe_test, class_k;
  double dt = 0.0;
  std::vector<std::string> features;
  // Held-out accuracy (fraction of safe states with h >= 0, of near-dangerous states with h < 0).
  bool has_accuracy = false;
  long held_out_safe = 0, held_out_near_dangerous = 0;
  double accuracy_safe = 0.0, accuracy_near_dangerous = 0.0;
  CheckKindStats no_safe_action, near_dangerous, unsafe;
  std::vector<CheckExample> worst;  // per kind (a, b, c), the worst first
  CheckThresholds thresholds;
  BarrierCheckOptions options;
  bool flagged = false;
  std::vector<std::string> reasons;  // why flagged ("rate(a) 0.031 > 0.01")

  const CheckKindStats& Stats(CheckKind kind) const;
  /// "pass" or "flagged".
  std::string Verdict() const { return flagged ? "flagged" : "pass"; }
  /// {"verdict", "reasons", "accuracy", "kinds": {name: {checked, counterexamples, rate,
  /// threshold, search_counterexamples, worst_objective}}, "options", ...}. Deterministic.
  nlohmann::json ToJson() const;
  /// One line per kind plus the verdict.
  std::string Summary() const;
  /// The worst examples as CSV (docs/FILE_FORMATS.md): kind, found_by, <features...>, h,
  /// objective; one row per example. A header-only file when there are none. Atomic.
  void WriteCsv(const std::string& path) const;
};

/// Runs the check. `barrier` and `dynamics` must agree on the state dimension, the box on the
/// action dimension, and the near-dangerous set on the state dimension.
/// @throws secure::Error on a dimension mismatch, an empty or non-finite near-dangerous set,
///   missing callbacks, invalid options, or a region sampler that returns non-finite states.
CheckReport CheckBarrier(Barrier& barrier, const domains::DynamicsModel& dynamics,
                         const BarrierCheckProblem& problem, const BarrierCheckOptions& options);

/// max_a g(state, a) over the box, approximately (the (a) objective), for tests and tools.
double MaxCbfCondition(Barrier& barrier, const domains::DynamicsModel& dynamics,
                       const BarrierCheckProblem& problem, const BarrierCheckOptions& options,
                       const Eigen::Ref<const Eigen::VectorXf>& state, Rng& rng);

/// Reads the states of a check CSV (the columns `features`, every row) for augmentation.
/// @throws secure::Error as data::ReadStateSet (a missing feature column names the file).
data::StateSet ReadCheckStates(const std::string& path, const std::vector<std::string>& features);

}  // namespace secure::cbf
