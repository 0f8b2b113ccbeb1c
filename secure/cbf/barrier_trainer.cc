#include "secure/cbf/barrier_trainer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/nn/model_file.h"
#include "secure/nn/torch_mlp.h"

namespace secure::cbf {
namespace {

// Restores LibTorch's global intra-op thread count on scope exit.
class TorchThreadsGuard {
 public:
  explicit TorchThreadsGuard(int threads) : previous_(torch::get_num_threads()) {
    torch::set_num_threads(threads);
  }
  ~TorchThreadsGuard() { torch::set_num_threads(previous_); }

 private:
  int previous_;
};


// Labelled, weighted, normalised samples as tensors: x (N x d), y (N) in {+1, -1}, w (N),
// margin (N).
struct Batch {
  torch::Tensor x, y, w, margin;
  long n_safe = 0, n_nd = 0;
};

Batch MakeBatch(const Eigen::MatrixXf& safe, const Eigen::MatrixXf& nd,
                const nn::Normalizer& normalizer, const BarrierTrainerOptions& o, double w_safe,
                double w_nd) {
  Batch b;
  b.n_safe = safe.cols();
  b.n_nd = nd.cols();
  const long n = b.n_safe + b.n_nd;
  Eigen::MatrixXf all(safe.rows(), n);
  all << safe, nd;
  b.x = nn::ToTensor(normalizer.Apply(all));
  b.y = torch::cat({torch::ones({b.n_safe}), -torch::ones({b.n_nd})});
  b.w = torch::cat({torch::full({b.n_safe}, w_safe), torch::full({b.n_nd}, w_nd)});
  b.margin =
      torch::cat({torch::full({b.n_safe}, o.safe_margin), torch::full({b.n_nd}, o.unsafe_margin)});
  return b;
}

// Weighted mean hinge loss: sum_i w_i max(m_i - y_i h_i, 0) / sum_i w_i.
torch::Tensor HingeLoss(const torch::Tensor& h, const torch::Tensor& y, const torch::Tensor& w,
                        const torch::Tensor& margin) {
  return (w * torch::relu(margin - y * h)).sum() / w.sum();
}

struct Score {
  double loss = 0.0;
  ClassAccuracy accuracy;
};

Score Evaluate(nn::TorchMlp& model, const Batch& b) {
  torch::NoGradGuard no_grad;
  const torch::Tensor h = model->forward(b.x).squeeze(1);
  Score s;
  s.loss = HingeLoss(h, b.y, b.w, b.margin).item<double>();
  const torch::Tensor positive = h >= 0;
  if (b.n_safe > 0)
    s.accuracy.safe = positive.slice(0, 0, b.n_safe).to(torch::kFloat64).mean().item<double>();
  if (b.n_nd > 0)
    s.accuracy.near_dangerous =
        1.0 - positive.slice(0, b.n_safe).to(torch::kFloat64).mean().item<double>();
  return s;
}

// Higher balanced accuracy wins; ties go to the lower loss.
bool Better(const Score& a, const Score& b) {
  const double da = a.accuracy.Balanced(), db = b.accuracy.Balanced();
  if (da != db) return da > db;
  return a.loss < b.loss;
}

}  // namespace

BarrierNet TrainBarrier(const BarrierTrainerOptions& options, const data::StateSet& safe,
                        const data::StateSet& near_dangerous, BarrierTrainingSummary* summary,
                        const BarrierEpochCallback& callback) {
  options.Validate();
  data::CheckNonEmptyFinite(safe, "safe states");
  data::CheckNonEmptyFinite(near_dangerous, "near-dangerous states");
  SECURE_CHECK(safe.features == near_dangerous.features,
               "safe states (" << safe.source << ") and near-dangerous states ("
                               << near_dangerous.source << ") have different features");
  const Stopwatch clock;
  TorchThreadsGuard threads(options.threads);
  Rng rng(options.seed);

  const auto [safe_split, nd_split] = data::SplitTwoClassesForValidation(
      safe.size(), near_dangerous.size(), options.validation_fraction, rng);
  const bool has_validation = !safe_split.validation.empty();
  const Eigen::MatrixXf train_safe = data::SelectColumns(safe.states, safe_split.train);
  const Eigen::MatrixXf train_nd = data::SelectColumns(near_dangerous.states, nd_split.train);
  const Eigen::MatrixXf val_safe = data::SelectColumns(safe.states, safe_split.validation);
  const Eigen::MatrixXf val_nd = data::SelectColumns(near_dangerous.states, nd_split.validation);

  Eigen::MatrixXf train_all(safe.dim(), train_safe.cols() + train_nd.cols());
  train_all << train_safe, train_nd;
  BarrierNet net;
  net.features = safe.features;
  net.normalizer = nn::Normalizer::Fit(train_all);

  // Class weights: balanced (each class contributes half of the loss), times the user weights.
  const double n_train = static_cast<double>(train_all.cols());
  double w_safe = options.safe_weight, w_nd = options.unsafe_weight;
  if (options.balance_classes) {
    w_safe *= n_train / (2.0 * static_cast<double>(train_safe.cols()));
    w_nd *= n_train / (2.0 * static_cast<double>(train_nd.cols()));
  }
  const Batch train = MakeBatch(train_safe, train_nd, net.normalizer, options, w_safe, w_nd);
  const Batch val = MakeBatch(val_safe, val_nd, net.normalizer, options, w_safe, w_nd);

  nn::MlpSpec spec;
  spec.input_dim = safe.dim();
  spec.hidden = options.hidden;
  spec.output_dim = 1;
  spec.activation = options.activation;
  // The initial weights come from LibTorch's global generator (seeded here; nothing else in
  // training draws from it): the lock makes concurrent trainings in several threads safe and
  // each one's initialisation a function of its own seed only.
  nn::TorchMlp model = [&] {
    static std::mutex mutex;
    const std::lock_guard<std::mutex> lock(mutex);
    torch::manual_seed(options.seed);
    return nn::TorchMlp(spec);
  }();
  torch::optim::Adam optimizer(
      model->parameters(),
      torch::optim::AdamOptions(options.learning_rate).weight_decay(options.weight_decay));

  BarrierTrainingSummary s;
  s.train_safe = train_safe.cols();
  s.train_near_dangerous = train_nd.cols();
  s.validation_safe = val_safe.cols();
  s.validation_near_dangerous = val_nd.cols();
  s.stop_reason = "max_epochs";
  Score best;
  bool have_best = false;
  nn::MlpParams best_params;
  int epochs_since_best = 0;

  const long n = train.x.size(0);
  std::vector<std::int64_t> order(n);
  std::iota(order.begin(), order.end(), std::int64_t{0});
  for (int epoch = 1; epoch <= options.max_epochs; ++epoch) {
    // Cosine learning-rate decay.
    const double progress = static_cast<double>(epoch - 1) / std::max(1, options.max_epochs - 1);
    const double lr =
        options.final_learning_rate + 0.5 * (options.learning_rate - options.final_learning_rate) *
                                          (1.0 + std::cos(M_PI * progress));
    for (auto& group : optimizer.param_groups())
      static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);

    Shuffle(order.begin(), order.end(), rng);
    const torch::Tensor perm = torch::from_blob(order.data(), {n}, torch::kInt64);
    double epoch_loss = 0.0;
    for (long first = 0; first < n; first += options.batch_size) {
      const long m = std::min<long>(options.batch_size, n - first);
      const torch::Tensor idx = perm.slice(0, first, first + m);
      const torch::Tensor h = model->forward(train.x.index_select(0, idx)).squeeze(1);
      const torch::Tensor loss =
          HingeLoss(h, train.y.index_select(0, idx), train.w.index_select(0, idx),
                    train.margin.index_select(0, idx));
      optimizer.zero_grad();
      loss.backward();
      optimizer.step();
      epoch_loss += loss.item<double>() * static_cast<double>(m);
      ++s.iterations;
    }
    epoch_loss /= static_cast<double>(n);
    s.epochs = epoch;

    // Best checkpoint on the validation split (or on the training split without one).
    const Score score = Evaluate(model, has_validation ? val : train);
    if (!have_best || Better(score, best)) {
      best = score;
      have_best = true;
      best_params = model->ToParams();
      s.best_epoch = epoch;
      epochs_since_best = 0;
    } else {
      ++epochs_since_best;
    }
    if (options.verbose && (epoch % 50 == 0 || epoch == options.max_epochs)) {
      std::fprintf(stderr,
                   "[cbf train] epoch %d/%d loss %.5f %s balanced acc %.4f (best %.4f @ %d)\n",
                   epoch, options.max_epochs, epoch_loss, has_validation ? "val" : "train",
                   score.accuracy.Balanced(), best.accuracy.Balanced(), s.best_epoch);
    }
    if (callback && !callback(epoch, epoch_loss, score.accuracy.Balanced())) {
      s.stop_reason = "callback";
      break;
    }
    if (options.patience > 0 && epochs_since_best >= options.patience) {
      s.stop_reason = "early_stopping";
      break;
    }
  }

  model->LoadParams(best_params);
  const Score train_score = Evaluate(model, train);
  s.train_loss = train_score.loss;
  s.train_accuracy = train_score.accuracy;
  if (has_validation) {
    const Score val_score = Evaluate(model, val);
    s.validation_loss = val_score.loss;
    s.validation_accuracy = val_score.accuracy;
  }
  s.wall_seconds = clock.Seconds();

  net.mlp = std::move(best_params);
  // The summary without its wall-clock time: same seed and data, same model file bytes.
  net.provenance = {{"trainer", "secure::cbf::TrainBarrier (Eq. 4 hinge loss)"},
                    {"options", options.ToJson()},
                    {"summary", nn::WithoutTiming(s.ToJson())},
                    {"safe_states", {{"source", safe.source}, {"count", safe.size()}}},
                    {"near_dangerous_states",
                     {{"source", near_dangerous.source}, {"count", near_dangerous.size()}}}};
  net.Validate();
  if (summary != nullptr) *summary = s;
  return net;
}

}  // namespace secure::cbf
