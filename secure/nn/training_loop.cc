#include "secure/nn/training_loop.h"

#include <algorithm>
#include <cmath>

#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/option_check.h"

namespace secure::nn {

namespace {
constexpr EnumTable<StopReason, 3> kStopReasonNames{{
    {StopReason::kMaxEpochs, "max_epochs"},
    {StopReason::kEarlyStopping, "early_stopping"},
    {StopReason::kCallback, "callback"},
}};
}  // namespace

const char* ToString(StopReason reason) { return NameOf(kStopReasonNames, reason); }

void TrainingLoopOptions::Validate() const {
  SECURE_CHECK_FIELD(max_epochs > 0, "TrainingLoopOptions", "max_epochs", max_epochs, "> 0");
  SECURE_CHECK_FIELD(num_samples >= 0, "TrainingLoopOptions", "num_samples", num_samples, ">= 0");
  SECURE_CHECK_FIELD(batch_size > 0, "TrainingLoopOptions", "batch_size", batch_size, "> 0");
  SECURE_CHECK_FIELD(patience >= 0, "TrainingLoopOptions", "patience", patience, ">= 0");
}

std::vector<long> BatchSizes(long num_samples, int batch_size, bool even_batches) {
  const long count = (num_samples + batch_size - 1) / batch_size;
  std::vector<long> sizes(static_cast<std::size_t>(count), batch_size);
  if (count == 0) return sizes;
  if (!even_batches) {
    sizes.back() = num_samples - (count - 1) * batch_size;
    return sizes;
  }
  const long base = num_samples / count, extra = num_samples % count;
  for (long i = 0; i < count; ++i) sizes[static_cast<std::size_t>(i)] = base + (i < extra ? 1 : 0);
  return sizes;
}

double CosineLearningRate(double initial, double final_rate, int epoch, int max_epochs) {
  // The trainers' schedule, term for term (their model files depend on the exact doubles).
  const double progress = static_cast<double>(epoch - 1) / std::max(1, max_epochs - 1);
  return final_rate + 0.5 * (initial - final_rate) * (1.0 + std::cos(M_PI * progress));
}

namespace internal {

void ThrowTrainingAborted(const TrainingLoopOptions& options, int epoch) {
  SECURE_THROW(options.name << ": aborted by the epoch callback after epoch " << epoch << " of "
                            << options.max_epochs);
}

void ThrowMissingStep(const TrainingLoopOptions& options, const char* step) {
  SECURE_THROW(options.name << ": the training loop needs the step '" << step << "'");
}

}  // namespace internal
}  // namespace secure::nn
