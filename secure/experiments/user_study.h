#pragma once
// The user study of the paper's Section 7.2 (Table 4) as a simulation, on any domain with
// participants (Domain::HasPopulation, domain.h): a 2 x 2 within-subject design, policy data
// individual vs grouped x barrier data individual vs grouped.
//
// Protocol, per threshold spread (options.spreads; the population's thresholds' spread about
// their mean is scaled by it, the participants' other draws unchanged):
//   1. the population (options.participants, options.seed); each participant's data
//      (Population::GenerateData: demonstrations and the states they label safe / unsafe);
//   2. the grouped data: all participants' demonstrations and labelled states pooled (the
//      paper's "pooling all participants' data"; grouped_matched = true instead subsamples the
//      pool to one participant's mean size -- whole demonstration episodes drawn at random until
//      the mean number of states is reached, the mean number of safe and of unsafe states drawn
//      without replacement -- so that individual and grouped data differ in whose they are, not
//      in how much there is);
//   3. per participant a behaviour-cloning policy and a barrier (the flat trainer: FC(64, 64) in
//      the paper's Table 2) on their own data, and one grouped policy and one grouped barrier;
//   4. per participant the four conditions (policy, barrier) = (individual, individual),
//      (individual, grouped), (grouped, individual), (grouped, grouped): the policy under the
//      shield (eval::Method::kBcShield) on `episodes` episodes of the participant's environment
//      (Population::MakeEnvironment: a violation of their thresholds is the dangerous event), the
//      same episodes for the four conditions (common random numbers);
//   5. per metric the per-participant values (rows) by condition (columns): mean (standard
//      error) over participants, the Friedman test and pairwise Wilcoxon signed-rank tests with
//      Holm's correction (stats/statistics.h).
// Metrics per participant and condition: task success (fraction of episodes), safety (fraction of
// episodes with a violation of the participant's thresholds), over-conservativeness (fraction of
// steps where the shield changed the action -- the policy's own draw failed the barrier's test --
// although the participant's thresholds held with margin: Population::HeldWithMargin), task time
// (mean episode length: the steps until success, or all of them; in seconds where the population
// gives the step's length).
// Every random stream derives from options.seed and the participant's index, not from the spread
// or the number of workers: the results are deterministic for a seed and independent of threads.
#include <cstdint>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "secure/cbf/barrier_trainer.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/policy/bc_trainer.h"
#include "secure/shield/shield.h"
#include "secure/stats/statistics.h"

namespace secure::experiments {

/// The four conditions in the paper's order: (policy data, barrier data).
inline constexpr int kUserStudyConditions = 4;
/// "(ind, ind)", "(ind, grp)", "(grp, ind)", "(grp, grp)".
const std::vector<std::string>& UserStudyConditionNames();
/// Whether condition c uses the grouped policy / the grouped barrier.
bool GroupedPolicy(int condition);
bool GroupedBarrier(int condition);

struct UserStudyOptions {
  int participants = 12;
  long episodes = 20;  // per participant and condition
  std::uint64_t seed = 0;
  std::vector<double> spreads = {1.0};  // threshold spreads, each in [0, 1]
  bool grouped_matched = false;         // grouped data subsampled to one participant's size
  policy::BcOptions bc;
  cbf::BarrierTrainerOptions barrier;
  shield::ShieldOptions shield;
  int threads = 2;
  bool verbose = true;
  std::string output_dir;  // if set: result.json

  /// The learning and shield settings of a domain's preset (ExperimentOptions: bc, flat_barrier,
  /// shield), and the size of the profile: 12 participants x 20 episodes, or 3 x 3 (quick).
  static UserStudyOptions From(const ExperimentOptions& preset, Profile profile);
  /// @throws secure::Error naming the field, value and rule.
  void Validate() const;
  nlohmann::json ToJson() const;
};

/// One metric of one spread: values[participant][condition].
struct UserStudyMetric {
  std::string key;    // "success", "violations", "over_conservative", "time"
  std::string label;  // "Task success %", ...
  bool higher_is_better = false;
  double scale = 1;  // printed value = scale * value (100 for fractions)
  std::vector<std::vector<double>> values;
  std::optional<stats::FriedmanResult> friedman;  // none if every participant's values tie
  stats::PairwiseWilcoxonResult posthoc;
  double Mean(int condition) const;
  double StandardError(int condition) const;
  /// The condition with the best mean (the first on ties).
  int Best() const;
  nlohmann::json ToJson() const;
};

struct UserStudySpreadResult {
  double spread = 1;
  std::vector<nlohmann::json> participants;        // Population::Participant
  std::vector<UserStudyMetric> metrics;            // success, violations, over_conservative, time
  nlohmann::json data = nlohmann::json::object();  // sizes of the individual and grouped data
  /// "supported", "consistent, not significant", "not supported" or "not supported (no
  /// differences)": whether (grouped policy,
  /// individual barrier) has the best mean on task success and on violations and, for
  /// "supported", differs significantly (Holm-adjusted p < 0.05) from each other condition on at
  /// least one of the two.
  std::string verdict;
  nlohmann::json ToJson() const;
};

struct UserStudyResult {
  std::string domain, domain_title;
  nlohmann::json domain_options;
  std::string population;  // Population::Describe()
  std::optional<PaperUserStudy> paper;
  UserStudyOptions options;
  std::string time_unit;  // "s" or "steps"
  std::vector<UserStudySpreadResult> spreads;
  double seconds = 0;

  nlohmann::json ToJson() const;
  /// Markdown: per spread the conditions' table in Table 4's form beside the paper's ratings,
  /// the tests, the hypothesis; with several spreads the sweep's summary.
  std::string Table() const;
};

/// Runs the study. Progress lines go to `progress` when options.verbose (may be null).
/// @throws secure::Error if the domain has no participants, on invalid options, or if a stage
/// fails (naming the participant).
UserStudyResult RunUserStudy(const Domain& domain, const UserStudyOptions& options,
                             std::ostream* progress);

}  // namespace secure::experiments
