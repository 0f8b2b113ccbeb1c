#include "secure/cbf/barrier_trainer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "secure/cbf/internal/two_class_training.h"
#include "secure/common/error.h"
#include "secure/common/progress.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/nn/model_file.h"
#include "secure/nn/torch_mlp.h"
#include "secure/nn/torch_threads.h"
#include "secure/nn/torch_training.h"
#include "secure/nn/training_loop.h"

namespace secure::cbf {
namespace {

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

// `set` with only the rows `rows`, in that order, named `features`.
data::StateSet ProjectRows(const data::StateSet& set, const std::vector<int>& rows,
                           const std::vector<std::string>& features) {
  data::StateSet projected;
  projected.source = set.source;
  projected.features = features;
  projected.states.resize(static_cast<Eigen::Index>(rows.size()), set.states.cols());
  for (std::size_t k = 0; k < rows.size(); ++k)
    projected.states.row(static_cast<Eigen::Index>(k)) = set.states.row(rows[k]);
  return projected;
}

// One MLP (the whole of TrainBarrier for ensemble = 1), seeded by options.seed.
BarrierNet TrainMember(const BarrierTrainerOptions& options, const data::StateSet& all_safe,
                       const data::StateSet& all_near_dangerous, BarrierTrainingSummary* summary,
                       const BarrierEpochCallback& callback) {
  SECURE_CHECK(all_safe.features == all_near_dangerous.features,
               "safe states (" << all_safe.source << ") and near-dangerous states ("
                               << all_near_dangerous.source << ") have different features");
  // The columns the barrier reads (BarrierTrainerOptions::input_features), checked by name.
  std::optional<data::StateSet> projected_safe, projected_nd;
  if (!options.input_features.empty() && options.input_features != all_safe.features) {
    const std::vector<int> rows =
        FeatureRows(options.input_features, all_safe.features,
                    "the safe and near-dangerous states (" + all_safe.source + ")",
                    "BarrierTrainerOptions::input_features");
    projected_safe = ProjectRows(all_safe, rows, options.input_features);
    projected_nd = ProjectRows(all_near_dangerous, rows, options.input_features);
  }
  const data::StateSet& safe = projected_safe ? *projected_safe : all_safe;
  const data::StateSet& near_dangerous = projected_nd ? *projected_nd : all_near_dangerous;
  data::CheckNonEmptyFinite(safe, "safe states");
  data::CheckNonEmptyFinite(near_dangerous, "near-dangerous states");
  const Stopwatch clock;
  const nn::ScopedTorchThreads threads(options.threads);
  Rng rng(options.seed);

  const internal::TwoClassSplit split(safe, near_dangerous, options.validation_fraction, rng);

  Eigen::MatrixXf train_all(safe.dim(), split.train_safe.cols() + split.train_nd.cols());
  train_all << split.train_safe, split.train_nd;
  BarrierNet net;
  net.features = safe.features;
  net.normalizer = nn::Normalizer::Fit(train_all);

  // Class weights: balanced (each class contributes half of the loss), times the user weights.
  const double n_train = static_cast<double>(train_all.cols());
  double w_safe = options.safe_weight, w_nd = options.unsafe_weight;
  if (options.balance_classes) {
    w_safe *= n_train / (2.0 * static_cast<double>(split.train_safe.cols()));
    w_nd *= n_train / (2.0 * static_cast<double>(split.train_nd.cols()));
  }
  const Batch train =
      MakeBatch(split.train_safe, split.train_nd, net.normalizer, options, w_safe, w_nd);
  const Batch val = MakeBatch(split.val_safe, split.val_nd, net.normalizer, options, w_safe, w_nd);

  nn::MlpSpec spec;
  spec.input_dim = safe.dim();
  spec.hidden = options.hidden;
  spec.output_dim = 1;
  spec.activation = options.activation;
  // Initial weights from the seed, through a generator of the model's own (never LibTorch's
  // global one): concurrent trainings need no lock.
  nn::TorchMlp model(spec, options.seed);
  torch::optim::Adam optimizer(
      model->parameters(),
      torch::optim::AdamOptions(options.learning_rate).weight_decay(options.weight_decay));

  BarrierTrainingSummary s;
  s.train_safe = split.train_safe.cols();
  s.train_near_dangerous = split.train_nd.cols();
  s.validation_safe = split.val_safe.cols();
  s.validation_near_dangerous = split.val_nd.cols();
  nn::MlpParams best_params;

  const nn::TrainingLoopOptions loop = options.LoopOptions(train.x.size(0), "cbf::TrainBarrier");
  nn::TrainingSteps<Score> steps;
  nn::UseAdam(
      optimizer,
      [&](const torch::Tensor& idx) {
        const torch::Tensor h = model->forward(train.x.index_select(0, idx)).squeeze(1);
        return HingeLoss(h, train.y.index_select(0, idx), train.w.index_select(0, idx),
                         train.margin.index_select(0, idx));
      },
      &steps);
  // Best checkpoint on the validation split (or on the training split without one).
  steps.evaluate = [&](int) { return Evaluate(model, split.has_validation ? val : train); };
  steps.better = Better;
  steps.save_best = [&] { best_params = model->ToParams(); };
  steps.restore_best = [&] { model->LoadParams(best_params); };
  steps.on_epoch = [&](const nn::EpochReport<Score>& r) {
    if (options.verbose && (r.epoch % 50 == 0 || r.epoch == options.max_epochs)) {
      PrintStatusLineF("[cbf train] epoch %d/%d loss %.5f %s balanced acc %.4f (best %.4f @ %d)\n",
                       r.epoch, options.max_epochs, r.train_loss,
                       split.has_validation ? "val" : "train", r.score->accuracy.Balanced(),
                       r.best->accuracy.Balanced(), r.best_epoch);
    }
    if (callback && !callback(r.epoch, r.train_loss, r.score->accuracy.Balanced()))
      return nn::EpochDecision::kStop;
    return nn::EpochDecision::kContinue;
  };
  const nn::TrainingLoopResult result = nn::RunTrainingLoop(loop, rng, steps);
  internal::RecordLoop(result, &s);

  const Score train_score = Evaluate(model, train);
  s.train_loss = train_score.loss;
  s.train_accuracy = train_score.accuracy;
  if (split.has_validation) {
    const Score val_score = Evaluate(model, val);
    s.validation_loss = val_score.loss;
    s.validation_accuracy = val_score.accuracy;
  }
  s.wall_seconds = clock.Seconds();

  net.mlp = std::move(best_params);
  // The summary without its wall-clock time: same seed and data, same model file bytes.
  net.provenance = internal::TrainingProvenance("secure::cbf::TrainBarrier (Eq. 4 hinge loss)",
                                                options.ToJson(), s.ToJson(), safe, near_dangerous);
  net.Validate();
  if (summary != nullptr) *summary = s;
  return net;
}

}  // namespace

std::uint64_t EnsembleMemberSeed(std::uint64_t seed, int k) {
  if (k == 0) return seed;
  // SplitMix64 of the seed advanced k steps: distinct, well-mixed seeds for k = 1, 2, ...
  std::uint64_t z = seed + 0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(k);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

BarrierNet TrainBarrier(const BarrierTrainerOptions& options, const data::StateSet& safe,
                        const data::StateSet& near_dangerous, BarrierTrainingSummary* summary,
                        const BarrierEpochCallback& callback) {
  options.Validate();
  if (options.ensemble == 1) return TrainMember(options, safe, near_dangerous, summary, callback);
  const Stopwatch clock;
  BarrierNet net;
  BarrierTrainingSummary first;
  nlohmann::json member_summaries = nlohmann::json::array();
  for (int k = 0; k < options.ensemble; ++k) {
    BarrierTrainerOptions member_options = options;
    member_options.ensemble = 1;
    member_options.seed = EnsembleMemberSeed(options.seed, k);
    BarrierTrainingSummary s;
    BarrierNet member = TrainMember(member_options, safe, near_dangerous, &s, callback);
    member_summaries.push_back(nn::WithoutTiming(s.ToJson()));
    if (k == 0) {
      net = std::move(member);
      first = s;
    } else {
      net.more_members.push_back({std::move(member.mlp), std::move(member.normalizer)});
    }
  }
  // Member 0's provenance with the ensemble's options and every member's summary.
  net.provenance["trainer"] = "secure::cbf::TrainBarrier (Eq. 4 hinge loss), ensemble of " +
                              std::to_string(options.ensemble) + " (h = min over the members)";
  net.provenance["options"] = options.ToJson();
  net.provenance["member_summaries"] = std::move(member_summaries);
  net.Validate();
  first.wall_seconds = clock.Seconds();
  first.members = options.ensemble;
  if (summary != nullptr) *summary = first;
  return net;
}

}  // namespace secure::cbf
