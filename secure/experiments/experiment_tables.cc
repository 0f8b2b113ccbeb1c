// An experiment's result (experiment.h): its JSON document (result.json) and its Markdown
// tables (the methods, the closed-loop check per seed, the barrier check per seed).
#include "secure/experiments/experiment.h"

#include <cstdio>
#include <sstream>

#include "secure/common/atomic_file.h"
#include "secure/eval/episode_table.h"
#include "secure/experiments/internal/numbers.h"

namespace secure::experiments {

using internal::Number;
using internal::Percent;

nlohmann::json ExperimentResult::ToJson() const {
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json experiment_json = {
      {"kind", ToString(kExperimentKindNames, kind)},
      {"domain", domain},
      {"domain_options", domain_options},
      {"methods", method_names},
      {"demonstrations", demonstrations},
      {"discarded_demonstrations", discarded_demonstrations},
      {"demonstration_steps", demonstration_steps},
      {"safe_states", safe_states},
      {"near_dangerous_states", near_dangerous_states},
      {"seeds", seed_summaries},
      {"data_seconds", data_seconds},
      {"seconds", seconds},
      {"options", options_json.is_null() ? options.ToJson() : options_json}};
  if (kind != ExperimentKind::kSensitivity) {
    nlohmann::json j = evaluations.front().second.ToJson();
    j["experiment"] = std::move(experiment_json);
    return j;
  }
  nlohmann::json by_variant = nlohmann::json::object();
  for (std::size_t i = 0; i < evaluations.size(); ++i) {
    nlohmann::json e = evaluations[i].second.ToJson();
    e["variant"] = variants[i].ToJson();
    by_variant[evaluations[i].first] = std::move(e);
  }
  return {{"variants", std::move(by_variant)}, {"experiment", std::move(experiment_json)}};
}

std::string ExperimentResult::Table() const {
  std::ostringstream out;
  out << "SECURE on " << domain_title << ": " << ToString(kExperimentKindNames, kind) << " ("
      << ToString(kBarrierKindNames, options.barrier_kind) << " barrier from " << safe_states
      << " safe + " << near_dangerous_states << " near-dangerous states; " << demonstrations
      << " expert demonstrations)\n\n";
  if (kind != ExperimentKind::kSensitivity) {
    out << evaluations.front().second.Table();
    out << ClosedLoopTable();
    out << CheckTable();
    return out.str();
  }
  const std::size_t seeds = options.seeds;
  out << "SECURE with barriers learned from modified data, % mean (std) over " << seeds
      << " seeds x " << options.episodes << " episodes\n\n";
  out << "| barrier data | safe : near-dangerous states | success % | dangerous % | "
         "interventions / episode | no-safe-action |\n|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < evaluations.size(); ++i) {
    const eval::MethodSummary& s = evaluations[i].second.methods().at(eval::Method::kSecure);
    long no_safe = 0;
    for (const eval::SeedResult& r : s.per_seed) no_safe += r.no_safe_action_decisions;
    const nlohmann::json& barrier = seed_summaries.front()["barriers"][evaluations[i].first];
    char line[512];
    std::snprintf(line, sizeof line, "| %s | %s | %.1f (%.1f) | %.1f (%.1f) | %.2f | %ld |\n",
                  evaluations[i].first.c_str(),
                  (std::to_string(barrier.value("safe_states", 0L)) + " : " +
                   std::to_string(barrier.value("near_dangerous_states", 0L)))
                      .c_str(),
                  100 * s.success_rate.mean, 100 * s.success_rate.std,
                  100 * s.dangerous_rate.mean, 100 * s.dangerous_rate.std,
                  s.interventions_per_episode.mean, no_safe);
    out << line;
  }
  out << CheckTable();
  return out.str();
}

std::string ExperimentResult::ClosedLoopTable() const {
  if (seed_summaries.empty() || !seed_summaries.front().contains("closed_loop")) return "";
  std::ostringstream out;
  const nlohmann::json& first = seed_summaries.front()["closed_loop"]["options"];
  out << "\nClosed-loop check per seed (SECURE on " << first.value("episodes", 0L)
      << " held-out episodes per candidate; passes with success >= "
      << Percent(first.value("min_success", 0.0))
      << " and dangerous <= " << Percent(first.value("max_dangerous", 0.0))
      << "; every method of a seed is evaluated "
      << "with its selected candidate)\n\n";
  // With repair: the selected candidate's repairs and its held-out dangerous rate before them.
  const bool repair = first.value("repair_rounds", 0) > 0;
  out << "| seed | candidates | selected | held-out success % | held-out dangerous % |"
      << (repair ? " repairs (dangerous % before) |" : "") << " verdict |\n|---|---|---|---|---|"
      << (repair ? "---|" : "") << "---|\n";
  long replaced = 0, failed = 0, repaired = 0;
  for (std::size_t i = 0; i < seed_summaries.size(); ++i) {
    const nlohmann::json& c = seed_summaries[i]["closed_loop"];
    const nlohmann::json& candidates = c["candidates"];
    const long selected = c.value("selected", 0L);
    const bool pass = c.value("verdict", "") == "pass";
    replaced += selected > 0;
    failed += !pass;
    const nlohmann::json& chosen = candidates.at(static_cast<std::size_t>(selected));
    std::string repairs;
    if (repair) {
      char cell[64] = "0 |";
      if (chosen.contains("repairs")) {
        ++repaired;
        std::snprintf(cell, sizeof cell, "%zu (%.1f) |", chosen["repairs"].size(),
                      100 * Number(chosen["unrepaired"], "dangerous_rate"));
      }
      repairs = std::string(" ") + cell;
    }
    char line[256];
    std::snprintf(line, sizeof line, "| %llu | %zu | %ld | %.1f | %.1f |%s %s |\n",
                  static_cast<unsigned long long>(options.first_seed + i), candidates.size(),
                  selected, 100 * Number(chosen, "success_rate"),
                  100 * Number(chosen, "dangerous_rate"), repairs.c_str(),
                  pass ? "pass" : "**failed**");
    out << line;
  }
  out << "\n"
      << replaced << " of " << seed_summaries.size()
      << " seeds evaluated with a replacement candidate; ";
  if (repair) out << repaired << " with a repaired barrier; ";
  out << failed << " failed the check with every candidate (their best candidate is evaluated).\n";
  return out.str();
}

std::string ExperimentResult::CheckTable() const {
  if (seed_summaries.empty() || !seed_summaries.front().contains("check")) return "";
  const auto& evaluated = evaluations.front().second.methods();
  const auto secure_it = evaluated.find(eval::Method::kSecure);
  std::ostringstream out;
  out << "\nBarrier check per seed (" << evaluations.front().first
      << " barrier; rates: (a) h >= 0 without an action with g >= 0, (b) near a near-dangerous "
         "state with h >= 0, (c) unsafe by the domain's own test with h >= 0)\n\n"
      << "| seed | check | rate (a) | rate (b) | rate (c) | held-out accuracy safe / nd | "
         "SECURE dangerous % |\n|---|---|---|---|---|---|---|\n";
  long flagged = 0;
  for (std::size_t i = 0; i < seed_summaries.size(); ++i) {
    const nlohmann::json& c = seed_summaries[i]["check"];
    const nlohmann::json& kinds = c["kinds"];
    const bool is_flagged = c.value("flagged", false);
    flagged += is_flagged;
    std::string dangerous = "-";
    if (secure_it != evaluated.end() && i < secure_it->second.per_seed.size()) {
      char buffer[32];
      std::snprintf(buffer, sizeof buffer, "%.1f",
                    100 * secure_it->second.per_seed[i].dangerous_rate());
      dangerous = buffer;
    }
    std::string verdict = is_flagged ? "**flagged**" : "pass";
    if (seed_summaries[i].contains("check_augmented"))
      verdict +=
          std::string(" -> retrained: ") +
          (seed_summaries[i]["check_augmented"].value("flagged", false) ? "flagged" : "pass");
    double acc_safe = 0, acc_nd = 0;
    if (c.contains("accuracy") && c["accuracy"].is_object()) {
      acc_safe = Number(c["accuracy"], "safe");
      acc_nd = Number(c["accuracy"], "near_dangerous");
    }
    char line[256];
    std::snprintf(line, sizeof line, "| %llu | %s | %.4f | %.4f | %.4f | %.3f / %.3f | %s |\n",
                  static_cast<unsigned long long>(options.first_seed + i), verdict.c_str(),
                  Number(kinds["no_safe_action"], "rate"), Number(kinds["near_dangerous"], "rate"),
                  Number(kinds["unsafe"], "rate"), acc_safe, acc_nd, dangerous.c_str());
    out << line;
  }
  out << "\n"
      << flagged << " of " << seed_summaries.size() << " seeds flagged (thresholds: "
      << (options_json.is_null() ? options.check.thresholds.ToJson()
                                 : options_json["check"]["thresholds"])
             .dump()
      << ").\n";
  return out.str();
}

bool ExperimentResult::HasEpisodeOutcomes() const {
  for (const auto& [name, evaluation] : evaluations)
    if (!eval::HasEpisodeOutcomes(evaluation)) return false;
  return true;
}

std::string ExperimentResult::EpisodesCsv() const {
  const bool sensitivity = kind == ExperimentKind::kSensitivity;
  std::string csv = eval::EpisodeCsvHeader(sensitivity);
  for (const auto& [name, evaluation] : evaluations)
    eval::AppendEpisodeCsvRows(evaluation, options.first_seed, sensitivity ? &name : nullptr,
                               &csv);
  return csv;
}

std::string WriteEpisodesFile(const ExperimentResult& result, const std::string& dir) {
  if (!result.HasEpisodeOutcomes()) {
    return std::string(kEpisodesFile) +
           " not written: a seed's task file was written before per-episode outcomes were "
           "recorded (remove its seed-K/task.json to recompute it, or replay the evaluation "
           "with `secure eval --run " + dir + " --episodes-out FILE`)";
  }
  WriteFileAtomically(dir + "/" + kEpisodesFile, result.EpisodesCsv());
  return "";
}

}  // namespace secure::experiments
