#include "eval_models.h"

#include <yaml-cpp/yaml.h>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>

#include "secure/common/error.h"
#include "secure/dynamics/learned_environment.h"
#include "secure/nn/model_file.h"

namespace secure::cli {

std::string ModelSources::Path(const std::string& explicit_path, const std::string& name,
                               std::uint64_t seed) const {
  if (!explicit_path.empty() || run_dir.empty()) return explicit_path;
  return run_dir + "/seed-" + std::to_string(seed) + "/" + name + ".model";
}

policy::GaussianPolicy LoadDomainPolicy(const std::string& path, const domains::Environment& env,
                                        const std::string& domain) {
  policy::GaussianPolicy p = policy::GaussianPolicy::Load(path);
  SECURE_CHECK(p.observation_features == env.ObservationFeatures() &&
                   p.action_features == env.ActionFeatures(),
               path << ": the policy's features do not match the " << domain << " domain's");
  return p;
}

SeedModelSet::SeedModelSet(const ModelSources& sources, const experiments::Domain& domain,
                           const std::string& domain_name, const domains::Environment& env,
                           const std::vector<eval::Method>& methods, std::uint64_t seed,
                           const shield::ShieldOptions& shield) {
  bool need_bc = false, need_airl = false, need_joint = false, need_barrier = false;
  for (eval::Method m : methods) {
    if (eval::UsesBcPolicy(m)) {
      need_bc = true;
    } else if (eval::UsesJointPolicy(m)) {
      need_joint = true;
    } else {
      need_airl = true;
    }
    need_barrier = need_barrier || eval::IsShielded(m);
  }
  if (need_bc) bc_ = LoadDomainPolicy(sources.Path(sources.bc, "bc", seed), env, domain_name);
  if (need_airl)
    airl_ = LoadDomainPolicy(sources.Path(sources.airl, "airl", seed), env, domain_name);
  if (need_joint)
    joint_ = LoadDomainPolicy(sources.Path(sources.joint, "joint", seed), env, domain_name);
  models_.bc = bc_ ? &*bc_ : nullptr;
  models_.airl = airl_ ? &*airl_ : nullptr;
  models_.joint = joint_ ? &*joint_ : nullptr;
  if (!need_barrier) return;
  if (shield.aggregation == shield::Aggregation::kTopQ) {
    const std::string reward = sources.Path(sources.airl_reward, "airl_reward", seed);
    SECURE_CHECK(!reward.empty(),
                 "shield aggregation top-q needs AIRL's reward model: give --airl-reward or --run");
    airl_reward_ = policy::AirlRewardModel::Load(reward);
    SECURE_CHECK(
        airl_reward_->observation_features == env.ObservationFeatures(),
        reward << ": the reward model's features do not match the " << domain_name << " domain's");
    models_.airl_reward = &*airl_reward_;
  }
  const std::string path = sources.Path(sources.barrier, "barrier", seed);
  SECURE_CHECK(!path.empty(), "the shielded methods need --barrier or --run");
  const std::string where = "the " + domain_name + " domain";
  if (path == "ground-truth") {
    SECURE_CHECK(domain.MakeGroundTruth() != nullptr,
                 "--barrier ground-truth: the " << domain_name << " domain has no ground truth");
    models_.make_barrier = [&domain] { return domain.MakeGroundTruth(); };
  } else if (nn::ReadModelFile(path).kind == cbf::kCarBarrierModelKind) {
    per_obstacle_ = cbf::CarBarrierNet::Load(path);
    per_obstacle_->CheckFeatures(env.ObservationFeatures(), where, path);
    models_.make_barrier = [this] { return per_obstacle_->MakeEvaluator(256); };
  } else {
    net_ = cbf::BarrierNet::Load(path);
    const std::vector<std::string> features = env.ObservationFeatures();
    cbf::FeatureRows(net_->features, features, where, path);  // fails here on a mismatch
    models_.make_barrier = [this, features, where, path] {
      return net_->MakeEvaluatorFor(features, where, path, 256);
    };
  }
}

void PessimismFlags::Add(CLI::App* cmd) {
  cmd->add_option("--pessimism", aggregate,
                  "learned model: how the members' h(s+) combine: min | mean-std")
      ->capture_default_str();
  cmd->add_option("--pessimism-kappa", kappa,
                  "learned model: kappa of mean-std (mean - kappa std; default 1)");
  cmd->add_flag("--pessimism-linear", linear,
                "learned model: the members' h(s+) to first order through the barrier's gradient "
                "at s (h on M states instead of K M)");
  cmd->add_option("--dynamics-hold", hold,
                  "learned model: the action held for this many model steps per shield step, "
                  "each member on its own chain, the pessimism at the end (1: one step)")
      ->capture_default_str();
}

dynamics::PessimismOptions PessimismFlags::Options() const {
  dynamics::PessimismOptions options;
  options.aggregate = dynamics::PessimismOptions::ParseAggregate(aggregate, "--pessimism");
  options.kappa = kappa;
  SECURE_CHECK(std::isfinite(kappa) && kappa >= 0,
               "--pessimism-kappa = " << kappa << ", must be finite and >= 0");
  options.linear = linear;
  options.hold = hold;
  SECURE_CHECK(hold >= 1 && hold <= dynamics::kMaxHold,
               "--dynamics-hold = " << hold << ", must be in [1, " << dynamics::kMaxHold << "]");
  return options;
}

std::unique_ptr<domains::Environment> MakeLearnedModelEnvironment(
    std::unique_ptr<domains::Environment> env, const std::string& path,
    const shield::ShieldOptions& shield, const dynamics::PessimismOptions& pessimism) {
  auto model = std::make_shared<const dynamics::EnsembleDynamics>(
      dynamics::EnsembleDynamics::Load(path));
  return std::make_unique<dynamics::LearnedModelEnvironment>(
      std::move(env), std::move(model), path,
      std::max(shield.num_samples, shield.num_probes), pessimism);
}

}  // namespace secure::cli

namespace secure::cli {

void CheckOutputFile(const std::string& flag, const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  SECURE_CHECK(!fs::is_directory(path, ec),
               flag << " = '" << path << "': a directory, not a file");
  const fs::path parent = fs::path(path).has_parent_path() ? fs::path(path).parent_path()
                                                           : fs::path(".");
  SECURE_CHECK(fs::is_directory(parent, ec),
               flag << " = '" << path << "': '" << parent.string()
                    << (fs::exists(parent, ec) ? "' is not a directory" : "' does not exist"));
  // A file is written next to its name and renamed over it (WriteFileAtomically): its
  // directory must be writable; a device or FIFO (/dev/stdout) is written directly.
  if (::access(parent.c_str(), W_OK) == 0) return;
  const int error = errno;
  SECURE_CHECK(fs::exists(path, ec) && !fs::is_regular_file(path, ec) &&
                   ::access(path.c_str(), W_OK) == 0,
               flag << " = '" << path << "': cannot write in '" << parent.string()
                    << "': " << std::strerror(error));
}

std::string GivenRenderFlags(const CLI::App& cmd) {
  // The options of `secure eval` that `secure render` has too, with the same meaning.
  static const std::vector<std::string> kNotRender = {
      "domain", "config", "run",      "airl",         "bc",       "joint",   "methods",
      "dynamics", "seeds", "first-seed", "episodes", "tost-bound", "json", "episodes-out",
      "help",   "pessimism", "pessimism-kappa", "pessimism-linear"};
  std::string out;
  for (const CLI::Option* option : cmd.get_options()) {
    if (option->count() == 0 || option->get_lnames().empty()) continue;
    const std::string& name = option->get_lnames().front();
    if (std::find(kNotRender.begin(), kNotRender.end(), name) != kNotRender.end()) continue;
    out += " --" + name;
    if (option->get_expected_min() == 0) continue;  // a flag
    for (const std::string& value : option->results()) out += " " + value;
  }
  return out;
}

}  // namespace secure::cli
