// secure dynamics train | validate | collect: a learned one-step dynamics ensemble (issue 36;
// secure/dynamics/README.md), the shield model for a robot without a hand-written one
// (`secure eval --dynamics`).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cctype>
#include <optional>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/dynamics/ensemble.h"
#include "secure/dynamics/trainer.h"
#include "secure/dynamics/transitions.h"
#include "secure/experiments/domain.h"
#include "secure/nn/torch_threads.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::cli {
namespace {

// The state and action features: the flags', else the domain's (observation, action).
void ResolveFeatures(const std::string& domain, const std::string& state_flag,
                     const std::string& action_flag, const Config& config,
                     std::vector<std::string>* states, std::vector<std::string>* actions) {
  if (!domain.empty()) {
    const std::unique_ptr<experiments::Domain> d = MakeConfiguredDomain(domain, false, config);
    const std::unique_ptr<domains::Environment> env = d->MakeEnvironment();
    *states = env->ObservationFeatures();
    *actions = env->ActionFeatures();
  }
  if (!state_flag.empty()) *states = data::SplitList(state_flag);
  if (!action_flag.empty()) *actions = data::SplitList(action_flag);
  SECURE_CHECK(!states->empty() && !actions->empty(),
               "give --domain NAME or both --state-features and --action-features (the "
               "transitions' columns)");
}


/// A feature's group for the error tables: digit runs replaced by '*', and a trailing axis letter
/// x, y or z too ("car3_dx" -> "car*_d*", "ee_vz" -> "ee_v*", "x" -> "*", "q[4]" -> "q[*]");
/// features of one group are summarised together.
std::string FeatureGroup(const std::string& feature) {
  std::string out;
  for (std::size_t i = 0; i < feature.size(); ++i) {
    if (std::isdigit(static_cast<unsigned char>(feature[i]))) {
      if (out.empty() || out.back() != '*') out += '*';
    } else {
      out += feature[i];
    }
  }
  const char last = out.empty() ? '\0' : out.back();
  const char before = out.size() >= 2 ? out[out.size() - 2] : '_';
  // An axis: x/y/z alone, after '_', or after a one-letter quantity (vx, dx, wz).
  const bool axis = (last == 'x' || last == 'y' || last == 'z') &&
                    (out.size() == 1 || before == '_' || out.size() == 2 ||
                     (out.size() >= 3 && out[out.size() - 3] == '_'));
  if (axis) out.back() = '*';
  return out;
}

/// One-step and k-step errors of a learned model against transitions.
struct DynamicsErrors {
  std::vector<std::string> features;
  std::vector<double> rmse;          // one step, per feature: RMS of s'_pred - s'
  std::vector<double> delta_std;     // per feature: std of the true change s' - s
  std::vector<double> relative;      // rmse / delta_std (NaN where the feature never moves)
  std::vector<double> spread;        // RMS over transitions of the members' std of s'_pred
  std::vector<int> horizons;         // k-step: 1..H (trajectories only)
  std::vector<std::vector<double>> k_rmse;  // [h][feature]
  std::vector<long> k_count;         // rollouts that reached horizon h
  long transitions = 0;

  nlohmann::json ToJson() const {
    nlohmann::json per_feature = nlohmann::json::array();
    for (std::size_t f = 0; f < features.size(); ++f) {
      nlohmann::json k = nlohmann::json::array();
      for (std::size_t h = 0; h < horizons.size(); ++h) k.push_back(k_rmse[h][f]);
      per_feature.push_back({{"feature", features[f]},
                             {"group", FeatureGroup(features[f])},
                             {"rmse", rmse[f]},
                             {"delta_std", delta_std[f]},
                             {"relative", std::isfinite(relative[f]) ? nlohmann::json(relative[f])
                                                                     : nlohmann::json(nullptr)},
                             {"spread", spread[f]},
                             {"k_step_rmse", k}});
    }
    return {{"transitions", transitions},
            {"horizons", horizons},
            {"rollouts", k_count},
            {"features", per_feature},
            {"groups", Groups()}};
  }

  // Per group: the RMS of the member features' rmse (and spread) over the RMS of their
  // delta_std.
  nlohmann::json Groups() const {
    struct Sums {
      double rmse = 0, delta = 0, spread = 0;
    };
    std::map<std::string, Sums> sums;
    std::vector<std::string> order;
    for (std::size_t f = 0; f < features.size(); ++f) {
      const std::string g = FeatureGroup(features[f]);
      if (!sums.count(g)) order.push_back(g);
      sums[g].rmse += rmse[f] * rmse[f];
      sums[g].delta += delta_std[f] * delta_std[f];
      sums[g].spread += spread[f] * spread[f];
    }
    auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    nlohmann::json out = nlohmann::json::array();
    for (const std::string& g : order) {
      const Sums& x = sums[g];
      out.push_back({{"group", g},
                     {"relative", number(x.delta > 0 ? std::sqrt(x.rmse / x.delta) : NAN)},
                     {"relative_spread", number(x.delta > 0 ? std::sqrt(x.spread / x.delta) : NAN)}});
    }
    return out;
  }
};

DynamicsErrors ScoreDynamics(const dynamics::EnsembleDynamics& model,
                             const dynamics::Transitions& t, int horizon) {
  const int d = t.state_dim();
  DynamicsErrors e;
  e.features = t.state_features;
  e.transitions = t.size();
  const dynamics::EnsembleModel m(std::make_shared<const dynamics::EnsembleDynamics>(model), 1);
  Eigen::MatrixXf next(d, 1);
  Eigen::VectorXd sq = Eigen::VectorXd::Zero(d), mean = Eigen::VectorXd::Zero(d),
                  mean_sq = Eigen::VectorXd::Zero(d), spread_sq = Eigen::VectorXd::Zero(d);
  for (long c = 0; c < t.size(); ++c) {
    m.Step(t.states.col(c), t.actions.col(c), next);
    const Eigen::VectorXd err = (next.col(0) - t.next_states.col(c)).cast<double>();
    sq += err.cwiseProduct(err);
    // The members' variance about their mean (population), per feature.
    for (int k = 0; k < m.num_members(); ++k) {
      const Eigen::VectorXd dev = (m.last_members().col(k) - next.col(0)).cast<double>();
      spread_sq += dev.cwiseProduct(dev) / m.num_members();
    }
    const Eigen::VectorXd delta = (t.next_states.col(c) - t.states.col(c)).cast<double>();
    mean += delta;
    mean_sq += delta.cwiseProduct(delta);
  }
  const double n = static_cast<double>(t.size());
  for (int f = 0; f < d; ++f) {
    e.rmse.push_back(std::sqrt(sq[f] / n));
    e.spread.push_back(std::sqrt(spread_sq[f] / n));
    const double var = std::max(0.0, mean_sq[f] / n - (mean[f] / n) * (mean[f] / n));
    e.delta_std.push_back(std::sqrt(var));
    e.relative.push_back(var > 1e-24 ? e.rmse[f] / std::sqrt(var) : NAN);
  }
  // k-step: from every transition of a run with k more steps in it, roll the mean model with the
  // recorded actions.
  if (horizon > 0 && t.run_begin.size() >= 2) {
    std::vector<Eigen::VectorXd> k_sq(static_cast<std::size_t>(horizon), Eigen::VectorXd::Zero(d));
    e.k_count.assign(static_cast<std::size_t>(horizon), 0);
    Eigen::VectorXf s(d);
    for (std::size_t r = 0; r + 1 < t.run_begin.size(); ++r) {
      for (long start = t.run_begin[r]; start < t.run_begin[r + 1]; ++start) {
        s = t.states.col(start);
        for (int h = 0; h < horizon && start + h < t.run_begin[r + 1]; ++h) {
          m.Step(s, t.actions.col(start + h), next);
          s = next.col(0);
          const Eigen::VectorXd err = (s - t.next_states.col(start + h)).cast<double>();
          k_sq[static_cast<std::size_t>(h)] += err.cwiseProduct(err);
          ++e.k_count[static_cast<std::size_t>(h)];
        }
      }
    }
    for (int h = 0; h < horizon; ++h) {
      if (e.k_count[static_cast<std::size_t>(h)] == 0) break;
      e.horizons.push_back(h + 1);
      std::vector<double> row;
      for (int f = 0; f < d; ++f)
        row.push_back(std::sqrt(k_sq[static_cast<std::size_t>(h)][f] /
                                static_cast<double>(e.k_count[static_cast<std::size_t>(h)])));
      e.k_rmse.push_back(row);
    }
    e.k_count.resize(e.horizons.size());
  }
  return e;
}

dynamics::Transitions ReadAll(const std::string& list, const std::vector<std::string>& states,
                              const std::vector<std::string>& actions) {
  dynamics::Transitions all;
  for (const std::string& path : data::SplitList(list))
    dynamics::Append(dynamics::ReadTransitions(path, states, actions), &all);
  return all;
}

// ------------------------------------------------------------------------------------------------
struct DynamicsTrainCommand {
  std::string transitions, out, domain, state_features, action_features, hidden = "64,64";
  dynamics::DynamicsTrainerOptions options;
  std::string activation = "tanh";
  bool json = false;
  const Config* config = nullptr;

  void Register(CLI::App& parent, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = parent.add_subcommand(
        "train", "Learn an ensemble of MLPs predicting s' - s from (s, a) (the shield model for "
                 "`eval --dynamics`)");
    AddConfigFlag(cmd, cfg);
    cmd->add_option("--transitions", transitions,
                    "comma-separated CSV/HDF5 files: (s, a, next_<f>) triples, or trajectories "
                    "with an episode column (demos.csv, `dynamics collect`)")
        ->required();
    cmd->add_option("--out", out, "output model file")->required();
    AddDomainOption(cmd, &domain, "take the features from this domain (observation, action)");
    cmd->add_option("--state-features", state_features, "comma-separated state columns");
    cmd->add_option("--action-features", action_features, "comma-separated action columns");
    cmd->add_option("--members", options.members, "K, ensemble members")->capture_default_str();
    cmd->add_option("--hidden", hidden, "hidden layer widths, comma-separated ('' for linear)")
        ->capture_default_str();
    cmd->add_option("--activation", activation, "tanh | relu")->capture_default_str();
    cmd->add_option("--epochs", options.epochs, "at most")->capture_default_str();
    cmd->add_option("--batch-size", options.batch_size)->capture_default_str();
    cmd->add_option("--patience", options.patience, "early stopping (0: never)")
        ->capture_default_str();
    cmd->add_option("--learning-rate", options.learning_rate)->capture_default_str();
    cmd->add_option("--final-learning-rate", options.final_learning_rate)->capture_default_str();
    cmd->add_option("--validation-fraction", options.validation_fraction,
                    "held-out transitions for early stopping")
        ->capture_default_str();
    cmd->add_option("--min-transitions", options.min_transitions)->capture_default_str();
    AddSeedOption(cmd, "--seed", &options.seed, "seed of the training");
    cmd->add_flag("--json", json, "print the training summary as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    options.hidden.clear();
    for (const std::string& w : data::SplitList(hidden)) {
      std::size_t used = 0;
      int v = 0;
      try {
        v = std::stoi(w, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      SECURE_CHECK(used == w.size() && used > 0, "--hidden = '" << hidden << "': '" << w
                                                                << "' is not an integer");
      options.hidden.push_back(v);
    }
    options.activation = FromString(nn::kActivationNames, activation, "--activation");
    options.verbose = !json;
    options.Validate();
    std::vector<std::string> states, actions;
    ResolveFeatures(domain, state_features, action_features, *config, &states, &actions);
    const dynamics::Transitions data = ReadAll(transitions, states, actions);
    nn::SetTorchThreads(1);
    dynamics::DynamicsTrainingSummary summary;
    const dynamics::EnsembleDynamics model = dynamics::TrainDynamics(options, data, &summary);
    model.Save(out);
    if (json) {
      PrintJson({{"command", "dynamics train"},
                 {"out", out},
                 {"transitions", data.size()},
                 {"options", options.ToJson()},
                 {"summary", summary.ToJson()}});
    } else {
      std::cout << "dynamics: " << summary.BriefReport() << "\nsaved " << out << "\n";
    }
  }
};

// ------------------------------------------------------------------------------------------------
struct DynamicsValidateCommand {
  std::string model_path, transitions;
  int horizon = 10;
  bool json = false;

  void Register(CLI::App& parent) {
    CLI::App* cmd = parent.add_subcommand(
        "validate", "One-step and k-step error per feature of a learned dynamics model on "
                    "held-out transitions");
    cmd->add_option("--model", model_path, "learned dynamics model")->required();
    cmd->add_option("--transitions", transitions, "comma-separated CSV/HDF5 files")->required();
    cmd->add_option("--horizon", horizon,
                    "k-step errors for k = 1..H along trajectories (0: one-step only)")
        ->capture_default_str();
    cmd->add_flag("--json", json, "print every number as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    CheckRange("--horizon", horizon, 0, 1000);
    const dynamics::EnsembleDynamics model = dynamics::EnsembleDynamics::Load(model_path);
    const dynamics::Transitions data =
        ReadAll(transitions, model.state_features, model.action_features);
    const DynamicsErrors e = ScoreDynamics(model, data, horizon);
    if (json) {
      nlohmann::json r = e.ToJson();
      r["command"] = "dynamics validate";
      r["model"] = model_path;
      r["members"] = model.num_members();
      PrintJson(r);
      return;
    }
    std::cout << model_path << " on " << e.transitions << " transitions (" << transitions
              << "); relative = one-step RMSE / std of the true change; spread = RMS of the "
                 "members' std about their mean\n";
    std::cout << std::left << std::setw(18) << "feature" << std::right << std::setw(12) << "rmse"
              << std::setw(12) << "delta std" << std::setw(10) << "relative" << std::setw(12)
              << "spread";
    for (int h : e.horizons)
      if (h == 1 || h == e.horizons.back() || h == 5) std::cout << std::setw(11) << ("rmse@" + std::to_string(h));
    std::cout << "\n";
    for (std::size_t f = 0; f < e.features.size(); ++f) {
      std::cout << std::left << std::setw(18) << e.features[f] << std::right << std::setw(12)
                << std::setprecision(4) << e.rmse[f] << std::setw(12) << e.delta_std[f]
                << std::setw(10) << e.relative[f] << std::setw(12) << e.spread[f];
      for (std::size_t h = 0; h < e.horizons.size(); ++h) {
        const int k = e.horizons[h];
        if (k == 1 || k == e.horizons.back() || k == 5) std::cout << std::setw(11) << e.k_rmse[h][f];
      }
      std::cout << "\n";
    }
    auto text = [](const nlohmann::json& v) {
      return v.is_null() ? std::string("-") : std::to_string(v.get<double>());
    };
    std::cout << "groups (relative error / relative spread):";
    for (const auto& g : e.Groups())
      std::cout << " " << g["group"].get<std::string>() << " " << text(g["relative"]) << " / "
                << text(g["relative_spread"]);
    std::cout << "\n";
  }
};

// ------------------------------------------------------------------------------------------------
struct DynamicsCollectCommand {
  std::string domain, out, policy_path;
  long episodes = 20;
  double noise = 1.0;
  std::uint64_t seed = 0;
  bool json = false;
  const Config* config = nullptr;

  void Register(CLI::App& parent, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = parent.add_subcommand(
        "collect", "Exploratory rollouts in a domain's environment, recorded as (s, a, s') "
                   "trajectories for `dynamics train` (the actions applied, as executed)");
    AddConfigFlag(cmd, cfg);
    AddDomainOption(cmd, &domain)->required();
    cmd->add_option("--out", out, "output CSV (episode, step, observation, action)")->required();
    cmd->add_option("--policy", policy_path,
                    "a Gaussian policy (e.g. BC) whose mean + noise x sigma is applied; without "
                    "one, actions are uniform in the actuator box");
    cmd->add_option("--noise", noise, "with --policy: the scale of its sigma")->capture_default_str();
    cmd->add_option("--episodes", episodes)->capture_default_str();
    AddSeedOption(cmd, "--seed", &seed, "seed of the rollouts");
    cmd->add_flag("--json", json, "print counts as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    CheckRange("--episodes", episodes, 1, kMaxEpisodes);
    SECURE_CHECK(std::isfinite(noise) && noise >= 0, "--noise = " << noise << ", must be >= 0");
    const std::unique_ptr<experiments::Domain> d = MakeConfiguredDomain(domain, false, *config);
    const std::unique_ptr<domains::Environment> env = d->MakeEnvironment();
    const int od = env->observation_dim(), ad = env->action_dim();
    Eigen::VectorXf low(ad), high(ad);
    env->ActionBounds(low, high);
    std::optional<policy::GaussianPolicy> pi;
    std::optional<policy::PolicyEvaluator> evaluator;
    if (!policy_path.empty()) {
      pi = policy::GaussianPolicy::Load(policy_path);
      SECURE_CHECK(pi->observation_features == env->ObservationFeatures() &&
                       pi->action_features == env->ActionFeatures(),
                   policy_path << ": the policy's features do not match the " << domain
                               << " domain's");
      evaluator.emplace(*pi);
    } else {
      SECURE_CHECK(low.allFinite() && high.allFinite(),
                   "the " << domain << " domain's action box is unbounded: give --policy");
    }
    data::TrajectorySet set;
    set.source = out;
    set.state_features = env->ObservationFeatures();
    set.action_features = env->ActionFeatures();
    std::vector<Eigen::VectorXf> obs_list, act_list;
    Eigen::VectorXf obs(od), mu(ad), action(ad);
    for (long e = 0; e < episodes; ++e) {
      Rng rng(seed * 1000003ULL + static_cast<std::uint64_t>(e));
      env->Reset(rng, obs);
      set.episode_begin.push_back(static_cast<long>(obs_list.size()));
      for (int t = 0; t < env->max_steps(); ++t) {
        if (evaluator) {
          evaluator->Mean(obs, mu);
          for (int i = 0; i < ad; ++i)
            action[i] = mu[i] + static_cast<float>(noise * evaluator->sigma()[i] * rng.Normal());
        } else {
          for (int i = 0; i < ad; ++i)
            action[i] = static_cast<float>(rng.Uniform(low[i], high[i]));
        }
        action = action.cwiseMax(low).cwiseMin(high);  // as the actuator applies it
        obs_list.push_back(obs);
        act_list.push_back(action);
        const domains::StepOutcome o = env->Step(action, obs);
        if (o.reached_goal || o.collided) break;
      }
      // The final observation closes the episode (its action is never applied: repeat the last).
      obs_list.push_back(obs);
      act_list.push_back(act_list.back());
    }
    set.episode_begin.push_back(static_cast<long>(obs_list.size()));
    set.states.resize(od, static_cast<Eigen::Index>(obs_list.size()));
    set.actions.resize(ad, static_cast<Eigen::Index>(obs_list.size()));
    for (std::size_t j = 0; j < obs_list.size(); ++j) {
      set.states.col(static_cast<Eigen::Index>(j)) = obs_list[j];
      set.actions.col(static_cast<Eigen::Index>(j)) = act_list[j];
    }
    data::WriteTrajectories(out, set);
    const long transitions = set.num_steps() - set.num_episodes();
    if (json) {
      PrintJson({{"command", "dynamics collect"},
                 {"out", out},
                 {"episodes", episodes},
                 {"transitions", transitions}});
    } else {
      std::cout << episodes << " episodes, " << transitions << " transitions -> " << out << "\n";
    }
  }
};

}  // namespace

void RegisterDynamicsCommands(CLI::App& app, const Config& config) {
  static DynamicsTrainCommand train;
  static DynamicsValidateCommand validate;
  static DynamicsCollectCommand collect;
  CLI::App* cmd = app.add_subcommand(
      "dynamics", "Learn the one-step dynamics from transitions: the shield model for a robot "
                  "without a hand-written one");
  cmd->require_subcommand(1);
  train.Register(*cmd, config);
  validate.Register(*cmd);
  collect.Register(*cmd, config);
  // `secure experiment model-source` (RegisterExperimentCommands made `experiment` first).
  RegisterModelSourceCommand(*app.get_subcommand("experiment"), config);
}

}  // namespace secure::cli
