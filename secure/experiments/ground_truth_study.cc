#include "secure/experiments/ground_truth_study.h"

#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

#include "secure/cbf/barrier_net.h"
#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/timer.h"

namespace secure::experiments {

void GroundTruthStudyOptions::Validate() const {
  SECURE_CHECK(n_safe > 0 && n_safe <= kMaxStates,
               "number of safe states = " << n_safe << ", must be in [1, " << kMaxStates << "]");
  SECURE_CHECK(n_unsafe > 0 && n_unsafe <= kMaxStates, "number of unsafe states = "
                                                           << n_unsafe << ", must be in [1, "
                                                           << kMaxStates << "]");
  SECURE_CHECK(seeds > 0, "seeds = " << seeds << ", must be > 0");
  trainer.Validate();
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

GroundTruthStudyResult RunGroundTruthStudy(const Domain& domain,
                                           const GroundTruthStudyOptions& options) {
  SECURE_CHECK(domain.HasGroundTruth(),
               "the " << domain.name()
                      << " domain has no ground truth for the ground-truth study (domains with "
                         "one: "
                      << DomainRegistry::Global().ListOffering(
                             [](const Domain& d) { return d.HasGroundTruth(); })
                      << ")");
  options.Validate();
  domain.Validate();
  const std::optional<cbf::StateSource> grid = domain.ValidationGrid();
  SECURE_CHECK(grid.has_value(), "the " << domain.name() << " domain has no validation grid");
  GroundTruthStudyResult result;
  result.paper = domain.PaperGroundTruthReference();
  std::vector<double> sc, oc, uc, ucorr;
  for (int i = 0; i < options.seeds; ++i) {
    const std::uint64_t seed = options.first_seed + static_cast<std::uint64_t>(i);
    const GroundTruthSample data = domain.SampleGroundTruth(options.n_safe, options.n_unsafe, seed);
    cbf::BarrierTrainerOptions trainer = options.trainer;
    trainer.seed = seed;
    cbf::BarrierTrainingSummary summary;
    const cbf::BarrierNet net = cbf::TrainBarrier(trainer, data.safe, data.unsafe, &summary);
    const Stopwatch clock;
    const cbf::Confusion c =
        cbf::ValidateOnGrid([&] { return net.MakeEvaluator(); },
                            [&] { return domain.MakeGroundTruth(); }, *grid, options.validation);
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

std::string GroundTruthStudyResult::Table() const {
  auto cell = [](double mean, double std) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.2f%% (%.2f%%)", 100 * mean, 100 * std);
    return std::string(buf);
  };
  auto paper_cell = [](double mean, double std) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "   [paper: %.1f%% (%.1f%%)]", mean, std);
    return std::string(buf);
  };
  std::ostringstream s;
  s << "Learned CBF vs ground truth on the " << (per_seed.empty() ? 0 : per_seed[0].total())
    << "-state grid, mean (std) over " << per_seed.size() << " seeds\n\n"
    << "| predicted \\ ground truth | safe states | unsafe states |\n"
    << "|---|---:|---:|\n"
    << "| safe | " << cell(safe_correct.mean, safe_correct.std) << " | "
    << cell(under_conservative.mean, under_conservative.std) << " |\n"
    << "| unsafe | " << cell(over_conservative.mean, over_conservative.std) << " | "
    << cell(unsafe_correct.mean, unsafe_correct.std) << " |\n\n"
    << "over-conservative (pred. unsafe | safe): "
    << cell(over_conservative.mean, over_conservative.std)
    << (paper ? paper_cell(paper->over_conservative, paper->over_conservative_std) : "") << "\n"
    << "under-conservative (pred. safe | unsafe): "
    << cell(under_conservative.mean, under_conservative.std)
    << (paper ? paper_cell(paper->under_conservative, paper->under_conservative_std) : "")
    << "\n";
  return s.str();
}

nlohmann::json GroundTruthStudyResult::ToJson() const {
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

}  // namespace secure::experiments
