// TrainingSchedule: validation, YAML and JSON of the barrier trainers' shared fields.
// (No LibTorch in this translation unit.)
#include "secure/cbf/training_schedule.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>

#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"

namespace secure::cbf {

nn::TrainingLoopOptions TrainingSchedule::LoopOptions(long num_samples, const char* name) const {
  // In the order TrainingLoopOptions declares its fields.
  return nn::TrainingLoopOptions{max_epochs, num_samples,   batch_size,          even_batches,
                                 patience,   learning_rate, final_learning_rate, name};
}

const std::vector<std::string>& TrainingSchedule::Keys() {
  static const std::vector<std::string> keys = {
      "learning_rate", "final_learning_rate", "weight_decay",        "batch_size",
      "even_batches",  "max_epochs",          "patience",            "seed",
      "validation_fraction", "threads",       "verbose"};
  return keys;
}

void TrainingSchedule::AddFields(YamlFields* fields) {
  fields->Field("learning_rate", &learning_rate).Field("final_learning_rate", &final_learning_rate);
  fields->Field("weight_decay", &weight_decay).Field("batch_size", &batch_size);
  fields->Field("even_batches", &even_batches);
  fields->Field("max_epochs", &max_epochs).Field("patience", &patience);
  fields->Field("validation_fraction", &validation_fraction).Field("seed", &seed);
  fields->Field("threads", &threads).Field("verbose", &verbose);
}

void TrainingSchedule::ValidateSchedule(const char* o) const {
  SECURE_CHECK_FIELD(std::isfinite(learning_rate) && learning_rate > 0, o, "learning_rate",
                     learning_rate, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(final_learning_rate) && final_learning_rate > 0 &&
                         final_learning_rate <= learning_rate,
                     o, "final_learning_rate", final_learning_rate, "in (0, learning_rate]");
  SECURE_CHECK_FIELD(std::isfinite(weight_decay) && weight_decay >= 0, o, "weight_decay",
                     weight_decay, ">= 0");
  SECURE_CHECK_FIELD(batch_size > 0, o, "batch_size", batch_size, "> 0");
  SECURE_CHECK_FIELD(max_epochs > 0, o, "max_epochs", max_epochs, "> 0");
  SECURE_CHECK_FIELD(patience >= 0, o, "patience", patience, ">= 0");
  SECURE_CHECK_FIELD(
      std::isfinite(validation_fraction) && validation_fraction >= 0 && validation_fraction < 1, o,
      "validation_fraction", validation_fraction, "in [0, 1)");
  SECURE_CHECK_FIELD(threads > 0, o, "threads", threads, "> 0");
}

bool TrainingSchedule::ApplyYamlKey(const std::string& key, const YAML::Node& value,
                                    const std::string& source) {
  const std::vector<std::string>& keys = Keys();
  if (std::find(keys.begin(), keys.end(), key) == keys.end()) return false;
  YamlFields fields;
  AddFields(&fields);
  YAML::Node one;
  one[key] = value;
  fields.Apply(one, source);
  return true;
}

void TrainingSchedule::AddJson(nlohmann::json* json) const {
  json->update({{"learning_rate", learning_rate},
                {"final_learning_rate", final_learning_rate},
                {"weight_decay", weight_decay},
                {"batch_size", batch_size},
                {"max_epochs", max_epochs},
                {"patience", patience},
                {"validation_fraction", validation_fraction},
                {"seed", seed},
                {"threads", threads}});
  if (even_batches) (*json)["even_batches"] = true;
}

}  // namespace secure::cbf
