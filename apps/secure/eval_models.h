#pragma once
// What `secure eval` and `secure render` share: where a seed's models come from (--run DIR or
// explicit files), loading and checking them against the domain, and the shield options (the
// domain's preset with the shield flags given on top).
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cli_common.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/domains/environment.h"
#include "secure/dynamics/ensemble.h"
#include "secure/eval/policy_eval.h"
#include "secure/experiments/experiment.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::cli {

/// Where the models come from: a run directory (seed-<k>/{bc,airl,joint,barrier,
/// airl_reward}.model per training seed, as `secure demo --out` and `secure experiment --out`
/// write them) and/or explicit files, which override the run's. The barrier may be
/// "ground-truth" (a domain that has one). airl_reward (AIRL's reward and shaping networks) is
/// read only for a shield with aggregation = top-q.
struct ModelSources {
  std::string run_dir, bc, airl, joint, barrier, airl_reward;
  /// `explicit_path` if given, else run_dir/seed-<seed>/<name>.model, else "".
  std::string Path(const std::string& explicit_path, const std::string& name,
                   std::uint64_t seed) const;
};

/// Loads a policy model and checks that its features are the domain's ("<path>: the policy's
/// features do not match the <domain> domain's").
policy::GaussianPolicy LoadDomainPolicy(const std::string& path, const domains::Environment& env,
                                        const std::string& domain);

/// The models `methods` need for one training seed, loaded and checked against the domain (its
/// observation and action features); models() points into this object, which is neither copied
/// nor moved. `domain` must outlive it (a ground-truth barrier is made by it).
class SeedModelSet {
 public:
  /// @throws secure::Error naming the file or flag (a missing model: "the shielded methods need
  /// --barrier or --run").
  /// `shield`: the shielded methods' options (aggregation = top-q also loads AIRL's reward model).
  SeedModelSet(const ModelSources& sources, const experiments::Domain& domain,
               const std::string& domain_name, const domains::Environment& env,
               const std::vector<eval::Method>& methods, std::uint64_t seed,
               const shield::ShieldOptions& shield);
  SeedModelSet(const SeedModelSet&) = delete;
  SeedModelSet& operator=(const SeedModelSet&) = delete;

  const eval::SeedModels& models() const { return models_; }

 private:
  std::optional<policy::GaussianPolicy> bc_, airl_, joint_;
  std::optional<policy::AirlRewardModel> airl_reward_;
  std::optional<cbf::BarrierNet> net_;
  std::optional<cbf::CarBarrierNet> per_obstacle_;
  eval::SeedModels models_;
};

/// How a shield through a learned model aggregates its members (dynamics::PessimismOptions):
/// `--pessimism min|mean-std`, `--pessimism-kappa`, `--pessimism-linear`, `--dynamics-hold`.
struct PessimismFlags {
  std::string aggregate = "min";
  double kappa = 1.0;
  bool linear = false;
  int hold = 1;
  void Add(CLI::App* cmd);
  /// @throws secure::Error naming the flag and value.
  dynamics::PessimismOptions Options() const;
};

/// `env` with the learned dynamics model at `path` as its shield model
/// (dynamics::LearnedModelEnvironment), sized for the shield's batches (max(M, N)), pessimistic
/// by `pessimism`: `secure eval --dynamics`. @throws secure::Error naming the file on a bad
/// model or features that are not the environment's.
std::unique_ptr<domains::Environment> MakeLearnedModelEnvironment(
    std::unique_ptr<domains::Environment> env, const std::string& path,
    const shield::ShieldOptions& shield, const dynamics::PessimismOptions& pessimism = {});

/// Checks, before any work, that `path` (the value of `flag`) can be written as a file: not a
/// directory, in an existing directory that this process may write to. @throws secure::Error
/// "<flag> = '<path>': <reason>".
void CheckOutputFile(const std::string& flag, const std::string& path);

/// The options given to `cmd` that `secure render` takes as they are (the shield flags,
/// --barrier, --airl-reward), as " --name value ...", for a render command line to print.
std::string GivenRenderFlags(const CLI::App& cmd);

}  // namespace secure::cli
