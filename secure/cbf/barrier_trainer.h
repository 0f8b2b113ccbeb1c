#pragma once
// Learning a barrier from safe and near-dangerous states (paper Section 4.1, Eq. 4):
//
//   L(w) = w_safe * sum_{s in S_s}  max(m_safe - h(s), 0)
//        + w_nd   * sum_{s in S_nd} max(h(s) + m_nd,  0)
//
// Eq. 4 has zero margins, for which h == 0 is a minimiser; the margins m_safe, m_nd > 0 make the
// problem well-posed (the authors' code uses 0.05 and 0.001 on Panda). Minimised with Adam over
// shuffled minibatches; a stratified validation split picks the best epoch (best-checkpoint) and
// stops training early once it has not improved for `patience` epochs.
//
//   BarrierTrainer::Options options;          // documented defaults
//   options.hidden = {64, 64};
//   BarrierTrainer::Summary summary;
//   BarrierNet net = TrainBarrier(options, safe, near_dangerous, &summary);
//   std::cout << summary.BriefReport() << "\n";

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/training_schedule.h"
#include "secure/cbf/validation.h"
#include "secure/data/data.h"
#include "secure/nn/mlp.h"

namespace YAML {
class Node;
}

namespace secure::cbf {

struct BarrierTrainerOptions : TrainingSchedule {
  // Input: the features (by name, in this order) of the training states that the barrier reads;
  // empty: all of them. The model's `features` are these names, so the model file records what it
  // reads; evaluate it on the whole states with BarrierNet::MakeEvaluatorFor. E.g. Panda's
  // barrier reads 9 of the 18 observation features.
  std::vector<std::string> input_features;

  // Architecture.
  std::vector<int> hidden = {64, 64, 64};  // hidden layer widths
  nn::Activation activation = nn::Activation::kTanh;

  // Loss (Eq. 4 with margins and class weights).
  double safe_margin = 0.1;     // m_safe: safe states are pushed to h >= m_safe
  double unsafe_margin = 0.1;   // m_nd: near-dangerous states are pushed to h <= -m_nd
  bool balance_classes = true;  // weight each class by N / (2 N_class) (then the weights below)
  double safe_weight = 1.0;     // extra weight on the safe term (> 0)
  double unsafe_weight = 1.0;   // extra weight on the near-dangerous term (> 0)

  // Ensemble: K barriers trained on the same labels from different initialisations, member k
  // with seed EnsembleMemberSeed(seed, k) (member 0: `seed`, today's barrier), h = min over the
  // K (BarrierNet::more_members, model kind "barrier_ensemble"). 1: one barrier, the same bytes
  // as before the option existed (ToJson leaves the field out).
  int ensemble = 1;  // in [1, kMaxBarrierEnsemble]

  // Optimisation: the shared TrainingSchedule (learning_rate 3e-3 -> final_learning_rate 3e-5,
  // weight_decay 0, batch_size 128, max_epochs 400, patience 0, validation_fraction 0.1, seed,
  // threads 1: fastest for small nets, verbose: one progress line per few seconds).

  /// Throws secure::Error naming the field, value and constraint
  /// ("BarrierTrainerOptions::batch_size = 0, must be > 0").
  void Validate() const;
  /// Reads fields from a YAML mapping; unknown keys are an error naming the key and `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

struct BarrierTrainingSummary {
  int epochs = 0;           // epochs run
  int best_epoch = 0;       // epoch whose weights were kept (1-based)
  long iterations = 0;      // optimizer steps
  double train_loss = 0.0;  // weighted hinge loss of the kept weights on the training split
  double validation_loss = 0.0;
  ClassAccuracy train_accuracy;
  ClassAccuracy validation_accuracy;  // zeros without held-out states (reports: n/a, JSON: null)
  long train_safe = 0, train_near_dangerous = 0, validation_safe = 0, validation_near_dangerous = 0;
  double wall_seconds = 0.0;
  std::string stop_reason;  // "max_epochs", "early_stopping", "callback"
  int members = 1;          // an ensemble's K (the figures above are member 0's)

  std::string BriefReport() const;  // one line
  std::string FullReport() const;   // a small table
  nlohmann::json ToJson() const;
};

/// The training seed of ensemble member k of a barrier trained with `seed`: `seed` for k = 0,
/// else a SplitMix64 mix of (seed, k) (a pure function, the same on every platform).
std::uint64_t EnsembleMemberSeed(std::uint64_t seed, int k);

/// Called after every epoch with (epoch, training loss, validation balanced accuracy); return
/// false to stop training (the best checkpoint so far is kept).
using BarrierEpochCallback = std::function<bool(int epoch, double train_loss, double val_accuracy)>;

/// Trains a BarrierNet on `safe` and `near_dangerous` (same features, each non-empty and finite),
/// projected to options.input_features when given (a name missing from the data is an error that
/// names it and lists the data's features). The returned net records the options and summary in
/// its provenance. With options.ensemble = K > 1 it trains K members one after another (each
/// with its own seed, hence its own initial weights, validation split and minibatch order);
/// `summary` is member 0's with wall_seconds the whole training's, the provenance holds every
/// member's summary ("member_summaries"); `callback` sees every member's epochs in turn.
/// @throws secure::Error on invalid options or data (names the set and the problem).
BarrierNet TrainBarrier(const BarrierTrainerOptions& options, const data::StateSet& safe,
                        const data::StateSet& near_dangerous, BarrierTrainingSummary* summary,
                        const BarrierEpochCallback& callback = nullptr);

}  // namespace secure::cbf
