#include "secure/eval/episode_table.h"

#include <sstream>

#include "secure/common/error.h"

namespace secure::eval {
namespace {

// "3 17 58 91" (the first `max_listed`, then "...") and the count: " (12)".
std::string Listed(const std::vector<long>& episodes, int max_listed) {
  std::ostringstream out;
  for (std::size_t i = 0; i < episodes.size() && i < static_cast<std::size_t>(max_listed); ++i)
    out << (i ? " " : "") << episodes[i];
  if (episodes.size() > static_cast<std::size_t>(max_listed)) out << " ...";
  out << " (" << episodes.size() << ")";
  return out.str();
}

}  // namespace

std::string EpisodeCsvHeader(bool variant_column) {
  return std::string(variant_column ? "variant," : "") +
         "method,seed,episode,success,dangerous,steps,first_dangerous_step,collision_events,"
         "interventions,no_safe_action_decisions\n";
}

void AppendEpisodeCsvRows(const Evaluation& evaluation, std::uint64_t first_seed,
                          const std::string* variant, std::string* csv) {
  if (variant != nullptr) {
    SECURE_CHECK(variant->find_first_of(",\"\n\r") == std::string::npos,
                 "episode table: variant name '" << *variant
                                                 << "' has a comma, quote or line break");
  }
  std::ostringstream out;
  for (const auto& [method, summary] : evaluation.methods()) {
    const std::string name = ToString(kMethodNames, method);
    for (std::size_t k = 0; k < summary.per_seed.size(); ++k) {
      const SeedResult& r = summary.per_seed[k];
      const std::uint64_t seed = first_seed + k;
      SECURE_CHECK(r.has_episode_outcomes(),
                   "method '" << name << "', seed " << seed << ": no per-episode outcomes ("
                              << r.episode_outcomes.size() << " of " << r.episodes
                              << " episodes recorded)");
      for (const EpisodeOutcome& e : r.episode_outcomes) {
        if (variant != nullptr) out << *variant << ",";
        out << name << "," << seed << "," << e.episode << "," << (e.success ? 1 : 0) << ","
            << (e.dangerous ? 1 : 0) << "," << e.steps << "," << e.first_dangerous_step << ","
            << e.collision_events << "," << e.interventions << "," << e.no_safe_action_decisions
            << "\n";
      }
    }
  }
  *csv += out.str();
}

std::string EpisodeCsv(const Evaluation& evaluation, std::uint64_t first_seed) {
  std::string csv = EpisodeCsvHeader();
  AppendEpisodeCsvRows(evaluation, first_seed, nullptr, &csv);
  return csv;
}

bool HasEpisodeOutcomes(const Evaluation& evaluation) {
  for (const auto& [method, summary] : evaluation.methods())
    for (const SeedResult& r : summary.per_seed)
      if (!r.has_episode_outcomes()) return false;
  return true;
}

std::string EpisodeLists(const Evaluation& evaluation, std::uint64_t first_seed,
                         const RenderCommand& render_command,
                         int max_listed) {
  std::ostringstream out;
  for (const auto& [method, summary] : evaluation.methods()) {
    const std::string name = ToString(kMethodNames, method);
    for (std::size_t k = 0; k < summary.per_seed.size(); ++k) {
      const SeedResult& r = summary.per_seed[k];
      const std::vector<long> dangerous = r.DangerousEpisodes();
      const std::vector<long> failed = r.FailedEpisodes();
      if (dangerous.empty() && failed.empty()) continue;
      const std::uint64_t seed = first_seed + k;
      out << name << " seed " << seed << ":";
      if (!dangerous.empty()) out << " dangerous episodes " << Listed(dangerous, max_listed);
      if (!dangerous.empty() && !failed.empty()) out << ";";
      if (!failed.empty()) out << " failed episodes " << Listed(failed, max_listed);
      const long first = dangerous.empty() ? failed.front() : dangerous.front();
      const std::string command =
          render_command ? render_command(method, seed, first) : std::string();
      if (!command.empty()) out << " (render one: " << command << ")";
      out << "\n";
    }
  }
  return out.str();
}

}  // namespace secure::eval
