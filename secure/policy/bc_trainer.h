#pragma once
// Behaviour cloning: maximum-likelihood fit of a Gaussian policy to demonstrated (state, action)
// pairs — the BC baseline of the paper (Table 3) and an optional warm start for AIRL.
//
//   minimise  -1/N sum_i log N(a_i; mu(s_i), diag(exp(log_std)^2))
//
// with an MLP mean mu(s) on normalised states (the normaliser is fitted on the training
// episodes' states) and a learned, state-independent log_std (clamped to >= min_log_std). Unlike
// the authors' BC script (official-code-facts.md §5.4: squared error of a reparameterised
// sample, which drives sigma to 0), this estimates sigma as the spread of the demonstrator's
// actions around the mean, which is what the shield's sampling (Algorithm 1) needs.
// Adam over shuffled minibatches with a cosine learning-rate decay; whole episodes are held out
// for validation, and the epoch with the best validation NLL is kept.
//
//   policy::BcOptions options;                       // documented defaults
//   policy::BcSummary summary;
//   policy::GaussianPolicy pi = policy::TrainBc(options, demos, &summary);
//   std::cerr << summary.BriefReport() << "\n";
//   pi.Save("bc.model");
//
// Threads: uses LibTorch's intra-op and OpenBLAS's thread counts as set by the caller (changes
// neither; set both to 1, see README.md "Threads"). Deterministic for a given seed and thread
// counts; safe to run concurrently with other trainers in other threads (no global RNG is used).

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/yaml_fwd.h"
#include "secure/data/data.h"
#include "secure/nn/mlp.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::policy {

struct BcOptions {
  // Architecture of the mean network.
  std::vector<int> hidden = {64, 64};
  nn::Activation activation = nn::Activation::kTanh;
  // The demonstration state features the mean network reads (any order; they are read in the
  // states' order); empty: all. Leaving out the velocities keeps a policy from copying the
  // current velocity into its action (GaussianPolicy::input_features). AIRL keeps its warm
  // start's.
  std::vector<std::string> input_features;

  // Optimisation.
  double learning_rate = 1e-3;        // Adam step size at epoch 1
  double final_learning_rate = 1e-5;  // cosine decay to this at the last epoch
  int epochs = 80;                    // passes over the training episodes' pairs (see README:
                                      // 3.6 s for 20k pairs, 4-D states, 2-D actions)
  int batch_size = 256;               // pairs per minibatch
  double weight_decay = 0.0;          // L2 on the network weights (Adam's coupled decay)
  double validation_fraction = 0.1;   // fraction of whole episodes held out (rounded, at least
                                      // one if > 0 and there are >= 2 episodes); 0: none, then
                                      // the last epoch is kept
  double min_log_std = -5.0;          // lower clamp of the learned log standard deviation
  std::uint64_t seed = 0;             // weights, episode split and minibatch order
  bool verbose = false;               // one progress line per ~10 % of the epochs on stderr
  std::string curve_path;             // if non-empty: CSV learning curve (epoch, train_nll,
                                      // validation_nll, action_mse, seconds), written atomically

  /// Throws secure::Error naming the field, value and rule ("BcOptions::epochs = 0, must be
  /// > 0").
  void Validate() const;
  /// The field table (the YAML keys; the JSON fields, all but verbose): ApplyYaml and ToJson.
  YamlFields Fields();
  /// Reads fields from a YAML mapping; unknown keys are an error naming the key and `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

struct BcSummary {
  int epochs = 0;      // epochs run
  int best_epoch = 0;  // 1-based epoch whose weights were kept
  long optimizer_steps = 0;
  long train_episodes = 0, validation_episodes = 0;
  long train_pairs = 0, validation_pairs = 0;
  double train_nll = 0.0;              // mean NLL per pair of the kept weights (training split)
  double validation_nll = 0.0;         // same on the validation split (NaN without one)
  double train_action_mse = 0.0;       // mean over pairs and dims of (mu(s) - a)^2
  double validation_action_mse = 0.0;  // NaN without a validation split
  std::vector<double> sigma;           // learned exp(log_std) per action dimension
  double wall_seconds = 0.0;

  std::string BriefReport() const;  // one line
  nlohmann::json ToJson() const;
};

/// Trains a Gaussian policy on `demos` (non-empty, finite, with state and action features).
/// The returned policy records the options, the data source and the summary in its provenance.
/// @throws secure::Error on invalid options or data (naming the field or the problem).
GaussianPolicy TrainBc(const BcOptions& options, const data::TrajectorySet& demos,
                       BcSummary* summary = nullptr);

/// Checks a demonstration set: at least one episode, consistent shapes and episode boundaries,
/// feature counts matching the matrices, finite values. `min_episode_rows` (>= 1) is the
/// shortest allowed episode. Errors name `demos.source`.
void CheckDemos(const data::TrajectorySet& demos, int min_episode_rows = 1);

}  // namespace secure::policy
