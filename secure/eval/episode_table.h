#pragma once
// Per-episode outcomes of an evaluation (SeedResult::episode_outcomes) as a CSV table and as the
// lists `secure eval` prints: which episodes of which seed were dangerous or failed, to replay
// them with `secure render --seed S --episode E`.
//
// The CSV (`secure eval --episodes-out FILE`, an experiment's <run>/episodes.csv): a header, then
// one row per method (table order), seed (ascending) and episode (ascending):
//   method,seed,episode,success,dangerous,steps,first_dangerous_step,collision_events,
//   interventions,no_safe_action_decisions
// seed: the training seed (`secure render --seed`); episode: the index in that seed's evaluation
// (`secure render --episode`); success, dangerous: 0/1; first_dangerous_step: the 0-based step
// whose outcome was the first collision, -1 if none; interventions and no_safe_action_decisions:
// the shield's, 0 for unshielded methods. A sensitivity experiment prefixes a column `variant`.
// Summed per method and seed, the columns give the seed's successes, dangerous, steps,
// collision_events, interventions and no_safe_action_decisions.
#include <cstdint>
#include <functional>
#include <string>

#include "secure/eval/policy_eval.h"

namespace secure::eval {

/// The CSV's header line (with a newline); `variant_column`: prefixed by "variant,".
std::string EpisodeCsvHeader(bool variant_column = false);

/// Appends the rows of `evaluation` (seed k of each method is training seed first_seed + k) to
/// `csv`, each prefixed by `variant` and a comma when `variant` is non-null (it must not contain a
/// comma, quote or newline).
/// @throws secure::Error naming the method and seed if a result has no per-episode outcomes.
void AppendEpisodeCsvRows(const Evaluation& evaluation, std::uint64_t first_seed,
                          const std::string* variant, std::string* csv);

/// The header and the rows of `evaluation` (no variant column).
std::string EpisodeCsv(const Evaluation& evaluation, std::uint64_t first_seed);

/// Whether every seed of every method of `evaluation` has its per-episode outcomes.
bool HasEpisodeOutcomes(const Evaluation& evaluation);

/// The command line that replays episode `episode` of `method` with training seed `seed` ("": no
/// such command).
using RenderCommand = std::function<std::string(Method method, std::uint64_t seed, long episode)>;

/// For `secure eval`'s text output: per method, one line per seed with dangerous or failed
/// episodes, listing the first `max_listed` indices of each and how many there were, and how to
/// render the first one (render_command(M, S, E), nothing when it is empty), e.g.
///   secure seed 14: dangerous episodes 3 17 58 91 (4); failed episodes 3 5 (2) (render one:
///   secure render --domain D --run R --seed 14 --episode 3 --method secure)
/// Empty when no episode was dangerous or failed. Seeds without outcomes are skipped.
std::string EpisodeLists(const Evaluation& evaluation, std::uint64_t first_seed,
                         const RenderCommand& render_command,
                         int max_listed = 10);

}  // namespace secure::eval
