#pragma once
// The training fields both barrier trainers share (BarrierTrainerOptions, CarBarrierTrainerOptions
// derive from it): Adam's step sizes and decay, the minibatches, the epochs and early stopping,
// the validation split, the seed, the threads and the progress lines. Declared, validated, read
// and written once here; each trainer's options add their model and loss and keep their own
// default for max_epochs. No LibTorch.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/nn/training_loop.h"

namespace YAML {
class Node;
}

namespace secure {
class YamlFields;
}  // namespace secure

namespace secure::cbf {

struct TrainingSchedule {
  double learning_rate = 3e-3;        // Adam step size
  double final_learning_rate = 3e-5;  // cosine decay from learning_rate to this over max_epochs
                                      // (= learning_rate: constant)
  double weight_decay = 0.0;          // L2 on weights (Adam's coupled decay)
  int batch_size = 128;               // states per minibatch (both classes shuffled together)
  bool even_batches = false;          // minibatches of near-equal sizes instead of batch_size
                                      // and a small remainder (nn::TrainingLoopOptions); off
                                      // by default: it changes every model whose training set
                                      // is not a multiple of batch_size
  int max_epochs = 400;               // passes over the training split (the car trainer: 30)
  int patience = 0;                   // stop after this many epochs without a better validation
                                      // score (0: never stop early, keep the best checkpoint)
  double validation_fraction = 0.1;   // per class, held out for best-checkpoint selection; 0: none
  std::uint64_t seed = 0;             // weights, splits and minibatch order
  int threads = 1;                    // LibTorch (and OpenBLAS) intra-op threads
  bool verbose = false;               // progress lines on stderr

  /// nn::RunTrainingLoop's options from these fields, for `num_samples` training samples; its
  /// errors name `name` ("cbf::TrainBarrier").
  nn::TrainingLoopOptions LoopOptions(long num_samples, const char* name) const;
  /// The YAML keys of the fields above (AddFields' keys).
  static const std::vector<std::string>& Keys();
  /// Throws secure::Error "owner::field = value, must be ..." for the first field out of range.
  void ValidateSchedule(const char* owner) const;
  /// Sets the field `key` (one of Keys()) from `value`; false if `key` is not one of them.
  bool ApplyYamlKey(const std::string& key, const YAML::Node& value, const std::string& source);
  /// Adds the fields' keys to a field table.
  void AddFields(YamlFields* fields);
  /// Adds the fields (not verbose) to `json`, an object; even_batches only when set (model and
  /// job files written before it existed keep their bytes).
  void AddJson(nlohmann::json* json) const;
};

}  // namespace secure::cbf
