#include "domains/double_integrator/table1.h"

#include <string>
#include <utility>

#include "secure/common/rng.h"

namespace secure::cbf {

namespace di = domains::double_integrator;

BarrierTrainerOptions DoubleIntegratorTrainerPreset() {
  BarrierTrainerOptions o;
  o.safe_margin = 0.2;
  o.unsafe_margin = 0.05;
  o.learning_rate = 1e-3;
  o.final_learning_rate = 1e-5;
  o.max_epochs = 200;
  o.validation_fraction = 0.0;
  return o;
}

DoubleIntegratorData SampleDoubleIntegratorData(const di::GroundTruth& truth,
                                                const di::StateBox& box, long n_safe, long n_unsafe,
                                                std::uint64_t seed) {
  // The data stream is derived from the seed but independent of the trainer's stream.
  Rng rng(seed ^ 0x5ec0'da7a'0000'0000ULL);
  di::LabelledStates sample = di::SampleLabelled(truth, box, n_safe, n_unsafe, rng);
  const std::string source = "double-integrator sampler (seed " + std::to_string(seed) + ")";
  DoubleIntegratorData out;
  out.safe = {source + " safe", di::StateFeatures(), std::move(sample.safe)};
  out.unsafe = {source + " unsafe", di::StateFeatures(), std::move(sample.unsafe)};
  return out;
}

}  // namespace secure::cbf
