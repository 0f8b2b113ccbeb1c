#include "secure/policy/bc_trainer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numeric>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/option_check.h"
#include "secure/common/random_order.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/common/timer.h"
#include "secure/nn/model_file.h"
#include "secure/nn/torch_training.h"
#include "secure/nn/training_loop.h"
#include "secure/policy/internal/torch_policy.h"

namespace secure::policy {
namespace {

// The options as the model file records them: without where the curve went and verbosity, which
// do not change the model (issue 34: the same experiment under two --out names gave different
// model bytes).
nlohmann::json ModelFileOptions(const BcOptions& o) {
  nlohmann::json j = o.ToJson();
  for (const char* key : {"curve_path", "verbose"}) j.erase(key);
  return j;
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Split {
  std::vector<long> train_columns, validation_columns;
  long train_episodes = 0, validation_episodes = 0;
};

// Whole episodes go to validation: round(fraction * E), at least 1 and at most E - 1.
Split SplitEpisodes(const data::TrajectorySet& demos, double fraction, Rng& rng) {
  const long episodes = demos.num_episodes();
  long n_val = 0;
  if (fraction > 0 && episodes >= 2)
    n_val = std::clamp(std::lround(fraction * static_cast<double>(episodes)), 1L, episodes - 1);
  const std::vector<long> order = RandomPermutation(episodes, rng);
  std::vector<bool> is_val(episodes, false);
  for (long i = 0; i < n_val; ++i) is_val[order[i]] = true;
  Split split;
  for (long e = 0; e < episodes; ++e) {
    auto& columns = is_val[e] ? split.validation_columns : split.train_columns;
    for (long c = demos.episode_begin[e]; c < demos.episode_begin[e + 1]; ++c) columns.push_back(c);
    ++(is_val[e] ? split.validation_episodes : split.train_episodes);
  }
  return split;
}

struct Pairs {
  torch::Tensor x, a;  // normalised states (N x d_s), actions (N x d_a)
  long size() const { return x.defined() ? x.size(0) : 0; }
};

// The rows of options.input_features in the demonstration states, ascending; empty when the
// options name none or every feature.
std::vector<int> InputRows(const BcOptions& options, const data::TrajectorySet& demos) {
  std::vector<int> rows;
  for (const std::string& name : options.input_features) {
    const auto& f = demos.state_features;
    const auto it = std::find(f.begin(), f.end(), name);
    SECURE_CHECK_FIELD(it != f.end(), "BcOptions", "input_features", "'" << name << "'",
                       "a state feature of the demonstrations (" << Join(f) << ")");
    rows.push_back(static_cast<int>(it - f.begin()));
  }
  std::sort(rows.begin(), rows.end());
  if (rows.size() == demos.state_features.size()) rows.clear();
  return rows;
}

Pairs MakePairs(const data::TrajectorySet& demos, const std::vector<long>& columns,
                const std::vector<int>& rows, const nn::Normalizer& normalizer) {
  if (columns.empty()) return {};
  return {nn::ToTensor(
              normalizer.Apply(PolicyInputs(data::SelectColumns(demos.states, columns), rows))),
          nn::ToTensor(data::SelectColumns(demos.actions, columns))};
}

struct Score {
  double nll = kNaN, mse = kNaN;
};

Score Evaluate(internal::TorchGaussian& model, const Pairs& pairs) {
  if (pairs.size() == 0) return {};
  torch::NoGradGuard no_grad;
  const torch::Tensor mu = model->Mean(pairs.x);
  Score s;
  s.nll = -internal::GaussianLogProb(mu, model->LogStd(), pairs.a).mean().item<double>();
  s.mse = (mu - pairs.a).pow(2).mean().item<double>();
  return s;
}

std::string CurveCsv(const std::vector<std::array<double, 5>>& rows) {
  std::string out = "epoch,train_nll,validation_nll,action_mse,seconds\n";
  char buf[64];
  for (const auto& row : rows) {
    for (int i = 0; i < 5; ++i) {
      if (i > 0) out += ',';
      if (i == 0) {
        std::snprintf(buf, sizeof buf, "%d", static_cast<int>(row[i]));
      } else if (std::isfinite(row[i])) {
        std::snprintf(buf, sizeof buf, "%.9g", row[i]);
      } else {
        buf[0] = '\0';  // no validation split: empty cell
      }
      out += buf;
    }
    out += '\n';
  }
  return out;
}

}  // namespace

GaussianPolicy TrainBc(const BcOptions& options, const data::TrajectorySet& demos,
                       BcSummary* summary) {
  options.Validate();
  CheckDemos(demos, 1);
  const Stopwatch clock;
  Rng rng(internal::DeriveSeed(options.seed, 0));

  const Split split = SplitEpisodes(demos, options.validation_fraction, rng);
  const bool has_validation = !split.validation_columns.empty();
  const std::vector<int> rows = InputRows(options, demos);
  const nn::Normalizer normalizer = nn::Normalizer::Fit(
      PolicyInputs(data::SelectColumns(demos.states, split.train_columns), rows));
  const Pairs train = MakePairs(demos, split.train_columns, rows, normalizer);
  const Pairs val = MakePairs(demos, split.validation_columns, rows, normalizer);

  // Initial weights from secure::Rng; log sigma starts at the spread of the demo actions.
  const int obs_dim = static_cast<int>(rows.empty() ? demos.state_features.size() : rows.size());
  const int act_dim = static_cast<int>(demos.action_features.size());
  const nn::MlpSpec spec{obs_dim, options.hidden, act_dim, options.activation};
  const Eigen::MatrixXf train_actions = data::SelectColumns(demos.actions, split.train_columns);
  Eigen::VectorXf log_std(act_dim);
  for (int i = 0; i < act_dim; ++i) {
    const Eigen::ArrayXd row = train_actions.row(i).cast<double>().transpose().array();
    const double sd = std::sqrt((row - row.mean()).square().mean());
    log_std[i] = static_cast<float>(std::max(options.min_log_std, sd > 0 ? std::log(sd) : 0.0));
  }
  internal::TorchGaussian model(
      internal::InitialParams(spec, internal::DeriveSeed(options.seed, 1)), log_std,
      options.min_log_std);
  // Weight decay on the mean network only, not on log sigma.
  std::vector<torch::optim::OptimizerParamGroup> groups;
  groups.emplace_back(
      model->mean->parameters(),
      std::make_unique<torch::optim::AdamOptions>(
          torch::optim::AdamOptions(options.learning_rate).weight_decay(options.weight_decay)));
  groups.emplace_back(std::vector<torch::Tensor>{model->log_std},
                      std::make_unique<torch::optim::AdamOptions>(
                          torch::optim::AdamOptions(options.learning_rate)));
  torch::optim::Adam optimizer(std::move(groups), torch::optim::AdamOptions(options.learning_rate));

  BcSummary s;
  s.train_episodes = split.train_episodes;
  s.validation_episodes = split.validation_episodes;
  s.train_pairs = train.size();
  s.validation_pairs = val.size();
  std::vector<std::array<double, 5>> curve;
  // The initial weights are the checkpoint until an epoch beats the baseline (with a validation
  // split: the first epoch with a finite NLL; without one: every epoch, so the last is kept).
  GaussianPolicy best = model->Export(normalizer);

  nn::TrainingLoopOptions loop;
  loop.max_epochs = options.epochs;
  loop.num_samples = train.size();
  loop.batch_size = options.batch_size;
  loop.learning_rate = options.learning_rate;
  loop.final_learning_rate = options.final_learning_rate;
  loop.name = "policy::TrainBc";
  nn::TrainingSteps<Score> steps;
  nn::UseAdam(
      optimizer,
      [&](const torch::Tensor& idx) {
        return -model->LogProb(train.x.index_select(0, idx), train.a.index_select(0, idx)).mean();
      },
      &steps);
  // Validation NLL and action MSE (the action MSE on the training pairs without a validation
  // split).
  steps.evaluate = [&](int) {
    Score score = has_validation ? Evaluate(model, val) : Score{};
    score.mse = has_validation ? score.mse : Evaluate(model, train).mse;
    return score;
  };
  // Best epoch by validation NLL; without validation, the last epoch.
  steps.better = [&](const Score& a, const Score& b) { return !has_validation || a.nll < b.nll; };
  if (has_validation) steps.baseline = Score{std::numeric_limits<double>::infinity(), kNaN};
  steps.save_best = [&] { best = model->Export(normalizer); };
  steps.restore_best = [&] {
    torch::NoGradGuard no_grad;
    model->mean->LoadParams(best.mean);
    model->log_std.copy_(torch::from_blob(best.log_std.data(), {act_dim}, torch::kFloat32));
  };
  const int report_every = std::max(1, options.epochs / 10);
  steps.on_epoch = [&](const nn::EpochReport<Score>& r) {
    curve.push_back(
        {static_cast<double>(r.epoch), r.train_loss, r.score->nll, r.score->mse, clock.Seconds()});
    if (options.verbose && (r.epoch % report_every == 0 || r.epoch == options.epochs)) {
      std::fprintf(stderr,
                   "[bc] epoch %d/%d train NLL %.4f val NLL %.4f action MSE %.5f (best %d) "
                   "%.1f s\n",
                   r.epoch, options.epochs, r.train_loss, r.score->nll, r.score->mse, r.best_epoch,
                   clock.Seconds());
    }
    return nn::EpochDecision::kContinue;
  };
  const nn::TrainingLoopResult result = nn::RunTrainingLoop(loop, rng, steps);
  s.epochs = result.epochs;
  s.best_epoch = result.best_epoch;
  s.optimizer_steps = result.steps;

  // Score the kept weights (restored by the loop).
  const Score train_score = Evaluate(model, train);
  const Score val_score = Evaluate(model, val);
  s.train_nll = train_score.nll;
  s.train_action_mse = train_score.mse;
  s.validation_nll = val_score.nll;
  s.validation_action_mse = val_score.mse;
  for (int i = 0; i < act_dim; ++i) s.sigma.push_back(std::exp(double{best.log_std[i]}));
  s.wall_seconds = clock.Seconds();

  if (!options.curve_path.empty()) {
    CreateDirectories(std::filesystem::path(options.curve_path).parent_path().string());
    WriteFileAtomically(options.curve_path, CurveCsv(curve));
  }

  best.observation_features = demos.state_features;
  for (const int row : rows) best.input_features.push_back(demos.state_features[row]);
  best.action_features = demos.action_features;
  // The summary without its wall-clock time: same seed and data, same model file bytes.
  best.provenance = {{"trainer", "secure::policy::TrainBc (Gaussian maximum likelihood)"},
                     {"options", ModelFileOptions(options)},
                     {"summary", nn::WithoutTiming(s.ToJson())},
                     {"demonstrations",
                      {{"source", demos.source},
                       {"episodes", demos.num_episodes()},
                       {"steps", demos.num_steps()}}}};
  best.Validate("BC policy");
  if (summary != nullptr) *summary = s;
  return best;
}

}  // namespace secure::policy
