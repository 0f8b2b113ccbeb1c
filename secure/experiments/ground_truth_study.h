#pragma once
// The ground-truth study (the paper's Table 1, Section 5) on any domain with a ground truth
// (Domain::HasGroundTruth): per seed, learn a barrier from n_safe + n_unsafe states drawn and
// labelled by the domain's ground truth (Domain::SampleGroundTruth), then compare it with the
// ground truth on the domain's validation grid (Domain::ValidationGrid; the double integrator's
// holds 9,000,000 states); reported as mean (std) over seeds, beside the paper's numbers when
// the domain has them (Domain::PaperGroundTruthReference).
//
//   const auto d = experiments::DomainRegistry::Global().Make("double-integrator");
//   experiments::GroundTruthStudyOptions o;
//   o.trainer = d->GroundTruthTrainerPreset();
//   std::cout << experiments::RunGroundTruthStudy(*d, o).Table();
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/validation.h"
#include "secure/experiments/domain.h"

namespace secure::experiments {

struct GroundTruthStudyOptions {
  long n_safe = 800;
  long n_unsafe = 800;
  int seeds = 5;
  std::uint64_t first_seed = 0;  // seed i of the study is first_seed + i (data, weights, order)
  cbf::BarrierTrainerOptions trainer;  // usually the domain's GroundTruthTrainerPreset()
  cbf::GridValidationOptions validation;
  bool progress = true;  // one stderr line per seed

  /// @throws secure::Error naming the field and value.
  void Validate() const;
};

struct MeanStd {
  double mean = 0.0;
  double std = 0.0;  // sample standard deviation (n - 1); 0 for a single seed
  static MeanStd Of(const std::vector<double>& values);
  nlohmann::json ToJson() const { return {{"mean", mean}, {"std", std}}; }
};

struct GroundTruthStudyResult {
  std::vector<cbf::Confusion> per_seed;
  std::vector<cbf::BarrierTrainingSummary> training;
  std::vector<double> grid_seconds;
  MeanStd safe_correct, over_conservative, under_conservative, unsafe_correct;
  std::optional<PaperGroundTruthStudy> paper;  // the domain's, if any

  /// The paper's 2 x 2 table, mean (std) in percent, and the paper's numbers beside the rates.
  std::string Table() const;
  /// Keys: safe_correct, over_conservative, under_conservative, unsafe_correct ({mean, std}),
  /// per_seed [{confusion, training, grid_seconds}].
  nlohmann::json ToJson() const;
};

/// Runs the study on `domain` (with its options). @throws secure::Error if the domain has no
/// ground truth (naming the domains that have one) or the options are invalid.
GroundTruthStudyResult RunGroundTruthStudy(const Domain& domain,
                                           const GroundTruthStudyOptions& options);

}  // namespace secure::experiments
