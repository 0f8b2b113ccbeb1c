#include "domains/double_integrator/table1.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/timer.h"

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

void Table1Options::Validate() const {
  truth.Validate();
  box.Validate();
  grid.Validate();
  SECURE_CHECK(n_safe > 0, "number of safe states = " << n_safe << ", must be > 0");
  SECURE_CHECK(n_unsafe > 0, "number of unsafe states = " << n_unsafe << ", must be > 0");
  SECURE_CHECK(seeds > 0, "seeds = " << seeds << ", must be > 0");
  trainer.Validate();
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

MeanStd MeanStd::Of(const std::vector<double>& values) {
  MeanStd r;
  if (values.empty()) return r;
  for (double v : values) r.mean += v;
  r.mean /= static_cast<double>(values.size());
  if (values.size() > 1) {
    double ss = 0.0;
    for (double v : values) ss += (v - r.mean) * (v - r.mean);
    r.std = std::sqrt(ss / static_cast<double>(values.size() - 1));
  }
  return r;
}

Table1Result RunTable1(const Table1Options& options) {
  options.Validate();
  Table1Result result;
  std::vector<double> sc, oc, uc, ucorr;
  for (int i = 0; i < options.seeds; ++i) {
    const std::uint64_t seed = options.first_seed + static_cast<std::uint64_t>(i);
    const DoubleIntegratorData data = SampleDoubleIntegratorData(
        options.truth, options.box, options.n_safe, options.n_unsafe, seed);
    BarrierTrainerOptions trainer = options.trainer;
    trainer.seed = seed;
    BarrierTrainingSummary summary;
    const BarrierNet net = TrainBarrier(trainer, data.safe, data.unsafe, &summary);
    const Stopwatch clock;
    const Confusion c = di::ValidateAgainstGroundTruth([&] { return net.MakeEvaluator(); }, options.truth,
                                       options.grid, options.validation);
    result.grid_seconds.push_back(clock.Seconds());
    result.per_seed.push_back(c);
    result.training.push_back(summary);
    sc.push_back(c.SafeCorrect());
    oc.push_back(c.OverConservative());
    uc.push_back(c.UnderConservative());
    ucorr.push_back(c.UnsafeCorrect());
    if (options.progress) {
      std::fprintf(stderr,
                   "[table1] seed %llu: over-conservative %.3f%%, under-conservative %.3f%% "
                   "(train %.1f s, grid %.2f s)\n",
                   static_cast<unsigned long long>(seed), 100 * c.OverConservative(),
                   100 * c.UnderConservative(), summary.wall_seconds, result.grid_seconds.back());
    }
  }
  result.safe_correct = MeanStd::Of(sc);
  result.over_conservative = MeanStd::Of(oc);
  result.under_conservative = MeanStd::Of(uc);
  result.unsafe_correct = MeanStd::Of(ucorr);
  return result;
}

std::string Table1Result::Table() const {
  auto cell = [](const MeanStd& m) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.2f%% (%.2f%%)", 100 * m.mean, 100 * m.std);
    return std::string(buf);
  };
  std::ostringstream s;
  s << "Learned CBF vs ground truth on the " << (per_seed.empty() ? 0 : per_seed[0].total())
    << "-state grid, mean (std) over " << per_seed.size() << " seeds\n\n"
    << "| predicted \\ ground truth | safe states | unsafe states |\n"
    << "|---|---:|---:|\n"
    << "| safe | " << cell(safe_correct) << " | " << cell(under_conservative) << " |\n"
    << "| unsafe | " << cell(over_conservative) << " | " << cell(unsafe_correct) << " |\n\n"
    << "over-conservative (pred. unsafe | safe): " << cell(over_conservative)
    << "   [paper: 1.9% (1.0%)]\n"
    << "under-conservative (pred. safe | unsafe): " << cell(under_conservative)
    << "   [paper: 4.1% (2.2%)]\n";
  return s.str();
}

nlohmann::json Table1Result::ToJson() const {
  nlohmann::json seeds = nlohmann::json::array();
  for (std::size_t i = 0; i < per_seed.size(); ++i) {
    seeds.push_back({{"confusion", per_seed[i].ToJson()},
                     {"training", training[i].ToJson()},
                     {"grid_seconds", grid_seconds[i]}});
  }
  return {{"safe_correct", safe_correct.ToJson()},
          {"over_conservative", over_conservative.ToJson()},
          {"under_conservative", under_conservative.ToJson()},
          {"unsafe_correct", unsafe_correct.ToJson()},
          {"per_seed", seeds}};
}

}  // namespace secure::cbf
