#pragma once
// What the two barrier trainers (barrier_trainer.cc, car_barrier_trainer.cc) do alike around
// their different models and losses: the stratified validation split of the safe and
// near-dangerous states, the loop's result in the summary, and the model's provenance. No
// LibTorch.
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/nn/model_file.h"
#include "secure/nn/training_loop.h"

namespace secure::cbf::internal {

/// The safe and near-dangerous states split per class for validation (`fraction` of each held
/// out, data::SplitTwoClassesForValidation with `rng`), as column blocks.
struct TwoClassSplit {
  TwoClassSplit(const data::StateSet& safe, const data::StateSet& near_dangerous, double fraction,
                Rng& rng) {
    const auto [safe_split, nd_split] =
        data::SplitTwoClassesForValidation(safe.size(), near_dangerous.size(), fraction, rng);
    has_validation = !safe_split.validation.empty();
    train_safe = data::SelectColumns(safe.states, safe_split.train);
    train_nd = data::SelectColumns(near_dangerous.states, nd_split.train);
    val_safe = data::SelectColumns(safe.states, safe_split.validation);
    val_nd = data::SelectColumns(near_dangerous.states, nd_split.validation);
  }
  bool has_validation = false;
  Eigen::MatrixXf train_safe, train_nd, val_safe, val_nd;
};

/// Records the loop's epochs, best epoch, steps and stop reason in a trainer's summary.
template <class Summary>
void RecordLoop(const nn::TrainingLoopResult& result, Summary* s) {
  s->epochs = result.epochs;
  s->best_epoch = result.best_epoch;
  s->iterations = result.steps;
  s->stop_reason = nn::ToString(result.stop_reason);
}

/// A trained barrier's provenance: the trainer, its options, its summary without timing (same
/// seed and data, same model file bytes) and the two state sets.
inline nlohmann::json TrainingProvenance(const std::string& trainer, nlohmann::json options,
                                         const nlohmann::json& summary, const data::StateSet& safe,
                                         const data::StateSet& near_dangerous) {
  return {{"trainer", trainer},
          {"options", std::move(options)},
          {"summary", nn::WithoutTiming(summary)},
          {"safe_states", {{"source", safe.source}, {"count", safe.size()}}},
          {"near_dangerous_states",
           {{"source", near_dangerous.source}, {"count", near_dangerous.size()}}}};
}

}  // namespace secure::cbf::internal
