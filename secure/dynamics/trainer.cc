#include "secure/dynamics/trainer.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/data/data.h"
#include "secure/nn/model_file.h"
#include "secure/nn/torch_mlp.h"
#include "secure/nn/torch_training.h"
#include "secure/nn/training_loop.h"

namespace secure::dynamics {
namespace {

constexpr const char* kOwner = "DynamicsTrainerOptions";

std::uint64_t DeriveSeed(std::uint64_t seed, std::uint64_t salt) {
  Rng rng(seed ^ (0x9e3779b97f4a7c15ULL * (salt + 1)));
  return rng.NextU64();
}

Eigen::MatrixXf Columns(const Eigen::MatrixXf& m, const std::vector<long>& idx) {
  Eigen::MatrixXf out(m.rows(), static_cast<Eigen::Index>(idx.size()));
  for (std::size_t j = 0; j < idx.size(); ++j) out.col(static_cast<Eigen::Index>(j)) = m.col(idx[j]);
  return out;
}

double Mse(nn::TorchMlp& model, const torch::Tensor& x, const torch::Tensor& y) {
  torch::NoGradGuard no_grad;
  return torch::mse_loss(model->forward(x), y).item<double>();
}

}  // namespace

void DynamicsTrainerOptions::Validate() const {
  SECURE_CHECK_FIELD(members >= 1 && members <= kMaxMembers, kOwner, "members", members,
                     "in [1, " << kMaxMembers << "]");
  for (std::size_t i = 0; i < hidden.size(); ++i)
    SECURE_CHECK_FIELD(hidden[i] >= 1 && hidden[i] <= kMaxLayerWidth, kOwner,
                       "hidden[" + std::to_string(i) + "]", hidden[i],
                       "in [1, " << kMaxLayerWidth << "]");
  SECURE_CHECK_FIELD(hidden.size() <= 8, kOwner, "hidden", hidden.size() << " layers",
                     "at most 8 layers");
  SECURE_CHECK_FIELD(std::isfinite(learning_rate) && learning_rate > 0, kOwner, "learning_rate",
                     learning_rate, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(final_learning_rate) && final_learning_rate > 0 &&
                         final_learning_rate <= learning_rate,
                     kOwner, "final_learning_rate", final_learning_rate,
                     "in (0, learning_rate = " << learning_rate << "]");
  SECURE_CHECK_FIELD(epochs >= 1 && epochs <= 1'000'000, kOwner, "epochs", epochs,
                     "in [1, 1000000]");
  SECURE_CHECK_FIELD(batch_size >= 1 && batch_size <= 1'000'000, kOwner, "batch_size", batch_size,
                     "in [1, 1000000]");
  SECURE_CHECK_FIELD(patience >= 0, kOwner, "patience", patience, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(validation_fraction) && validation_fraction >= 0 &&
                         validation_fraction < 1,
                     kOwner, "validation_fraction", validation_fraction, "in [0, 1)");
  SECURE_CHECK_FIELD(std::isfinite(weight_decay) && weight_decay >= 0, kOwner, "weight_decay",
                     weight_decay, ">= 0");
  SECURE_CHECK_FIELD(min_transitions >= 2 && min_transitions <= kMaxStates, kOwner,
                     "min_transitions", min_transitions, "in [2, " << kMaxStates << "]");
}

nlohmann::json DynamicsTrainerOptions::ToJson() const {
  return {{"members", members},
          {"hidden", hidden},
          {"activation", std::string(ToString(nn::kActivationNames, activation))},
          {"learning_rate", learning_rate},
          {"final_learning_rate", final_learning_rate},
          {"epochs", epochs},
          {"batch_size", batch_size},
          {"patience", patience},
          {"validation_fraction", validation_fraction},
          {"weight_decay", weight_decay},
          {"min_transitions", min_transitions},
          {"seed", seed}};
}

nlohmann::json DynamicsTrainingSummary::ToJson() const {
  return {{"train_transitions", train_transitions},
          {"validation_transitions", validation_transitions},
          {"epochs", epochs},
          {"best_epochs", best_epochs},
          {"validation_loss", validation_loss},
          {"ensemble_validation_loss", ensemble_validation_loss},
          {"wall_seconds", wall_seconds}};
}

std::string DynamicsTrainingSummary::BriefReport() const {
  std::ostringstream out;
  out << epochs.size() << " members on " << train_transitions << " transitions ("
      << validation_transitions << " held out); normalised validation MSE per member";
  for (double l : validation_loss) out << " " << l;
  out << "; ensemble mean " << ensemble_validation_loss << " (" << wall_seconds << " s)";
  return out.str();
}

EnsembleDynamics TrainDynamics(const DynamicsTrainerOptions& options, const Transitions& data,
                               DynamicsTrainingSummary* summary) {
  options.Validate();
  const Stopwatch clock;
  const long n = data.size();
  SECURE_CHECK(n >= options.min_transitions,
               data.source << ": " << n << " transitions, need at least "
                           << options.min_transitions << " (min_transitions)");
  SECURE_CHECK(data.state_dim() >= 1 && data.action_dim() >= 1,
               data.source << ": transitions need state and action features");
  for (long c = 0; c < n; ++c) {
    const bool finite = data.states.col(c).allFinite() && data.actions.col(c).allFinite() &&
                        data.next_states.col(c).allFinite();
    SECURE_CHECK(finite, data.source << ":"
                                     << (c < static_cast<long>(data.lines.size()) ? data.lines[c] : c)
                                     << ": a non-finite value in the transition");
  }
  const int d = data.state_dim(), a = data.action_dim();
  Rng rng(DeriveSeed(options.seed, 0));
  const data::IndexSplit split = data::SplitForValidation(n, options.validation_fraction, rng);
  const bool has_validation = !split.validation.empty();

  Eigen::MatrixXf x(d + a, n);
  x.topRows(d) = data.states;
  x.bottomRows(a) = data.actions;
  const Eigen::MatrixXf delta = data.next_states - data.states;
  const Eigen::MatrixXf x_train = Columns(x, split.train), x_val = Columns(x, split.validation);
  const Eigen::MatrixXf d_train = Columns(delta, split.train);
  const Eigen::MatrixXf d_val = Columns(delta, split.validation);

  EnsembleDynamics model;
  model.state_features = data.state_features;
  model.action_features = data.action_features;
  model.input = nn::Normalizer::Fit(x_train);
  model.delta = nn::Normalizer::Fit(d_train);
  const torch::Tensor xt = nn::ToTensor(model.input.Apply(x_train));
  const torch::Tensor yt = nn::ToTensor(model.delta.Apply(d_train));
  const torch::Tensor xv = has_validation ? nn::ToTensor(model.input.Apply(x_val)) : xt;
  const torch::Tensor yv = has_validation ? nn::ToTensor(model.delta.Apply(d_val)) : yt;

  nn::MlpSpec spec;
  spec.input_dim = d + a;
  spec.hidden = options.hidden;
  spec.output_dim = d;
  spec.activation = options.activation;

  DynamicsTrainingSummary s;
  s.train_transitions = static_cast<long>(split.train.size());
  s.validation_transitions = static_cast<long>(split.validation.size());
  torch::Tensor ensemble_sum = torch::zeros_like(yv);
  for (int k = 0; k < options.members; ++k) {
    nn::TorchMlp net(spec, DeriveSeed(options.seed, 100 + static_cast<std::uint64_t>(k)));
    torch::optim::Adam optimizer(
        net->parameters(),
        torch::optim::AdamOptions(options.learning_rate).weight_decay(options.weight_decay));
    nn::MlpParams best = net->ToParams();
    nn::TrainingLoopOptions loop;
    loop.max_epochs = options.epochs;
    loop.num_samples = static_cast<long>(split.train.size());
    loop.batch_size = options.batch_size;
    loop.patience = options.patience;
    loop.learning_rate = options.learning_rate;
    loop.final_learning_rate = options.final_learning_rate;
    loop.name = "dynamics::TrainDynamics";
    nn::TrainingSteps<double> steps;
    nn::UseAdam(
        optimizer,
        [&](const torch::Tensor& idx) {
          return torch::mse_loss(net->forward(xt.index_select(0, idx)), yt.index_select(0, idx));
        },
        &steps);
    steps.evaluate = [&](int) { return Mse(net, xv, yv); };
    steps.better = [](double candidate, double best_loss) { return candidate < best_loss; };
    steps.baseline = std::numeric_limits<double>::infinity();
    steps.save_best = [&] { best = net->ToParams(); };
    steps.restore_best = [&] { net->LoadParams(best); };
    Rng member_rng(DeriveSeed(options.seed, 200 + static_cast<std::uint64_t>(k)));
    const nn::TrainingLoopResult r = nn::RunTrainingLoop(loop, member_rng, steps);
    const double loss = Mse(net, xv, yv);
    {
      torch::NoGradGuard no_grad;
      ensemble_sum += net->forward(xv);
    }
    s.epochs.push_back(r.epochs);
    s.best_epochs.push_back(r.best_epoch);
    s.validation_loss.push_back(loss);
    if (options.verbose)
      std::fprintf(stderr, "[dynamics] member %d/%d: %d epochs (best %d), validation MSE %.3g\n",
                   k + 1, options.members, r.epochs, r.best_epoch, loss);
    model.members.push_back(best);
  }
  s.ensemble_validation_loss =
      torch::mse_loss(ensemble_sum / static_cast<double>(options.members), yv).item<double>();
  s.wall_seconds = clock.Seconds();
  model.provenance = {{"trainer", "secure::dynamics::TrainDynamics (ensemble of MLPs, delta s)"},
                      {"options", options.ToJson()},
                      {"summary", nn::WithoutTiming(s.ToJson())},
                      {"transitions", {{"source", data.source}, {"count", n}}}};
  model.Validate("learned dynamics");
  if (summary != nullptr) *summary = s;
  return model;
}

}  // namespace secure::dynamics
