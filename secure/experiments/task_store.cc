// The experiment driver's task files (internal/task_store.h): seed-K/task.json, one per
// finished seed, written after its models; reused by a rerun of the same experiment, checked
// (identity, checksum, counts in range) and merged across the shards of a run.
#include "secure/experiments/internal/task_store.h"

#include <boost/crc.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "secure/common/atomic_file.h"
#include "secure/common/build_info.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/experiments/internal/numbers.h"

namespace secure::experiments::internal {
namespace {

// The per-episode outcomes as columns (episode i of the seed's evaluation is entry i).
constexpr const char* kEpisodeColumns[] = {"success",          "dangerous",
                                           "steps",            "first_dangerous_step",
                                           "collision_events", "interventions",
                                           "no_safe_action_decisions"};

long EpisodeColumn(const eval::EpisodeOutcome& e, int column) {
  switch (column) {
    case 0: return e.success ? 1 : 0;
    case 1: return e.dangerous ? 1 : 0;
    case 2: return e.steps;
    case 3: return e.first_dangerous_step;
    case 4: return e.collision_events;
    case 5: return e.interventions;
    default: return e.no_safe_action_decisions;
  }
}

nlohmann::json SeedResultJson(const eval::SeedResult& r) {
  nlohmann::json j = r.ToJson();
  if (!r.has_episode_outcomes()) return j;
  nlohmann::json columns = nlohmann::json::object();
  for (int c = 0; c < 7; ++c) {
    std::vector<long> values;
    values.reserve(r.episode_outcomes.size());
    for (const eval::EpisodeOutcome& e : r.episode_outcomes) values.push_back(EpisodeColumn(e, c));
    columns[kEpisodeColumns[c]] = std::move(values);
  }
  j["episode_outcomes"] = std::move(columns);
  return j;
}

// The per-episode outcomes of a task file's record (none in a task file written before they were
// recorded); each column must have one value per episode, and sum to the seed's count.
void EpisodeOutcomesFromJson(const nlohmann::json& j, eval::SeedResult* r) {
  if (!j.contains("episode_outcomes")) return;
  const nlohmann::json& columns = j.at("episode_outcomes");
  const std::size_t n = static_cast<std::size_t>(std::max(0L, r->episodes));
  r->episode_outcomes.resize(n);
  for (int c = 0; c < 7; ++c) {
    const std::vector<long> values = columns.at(kEpisodeColumns[c]).get<std::vector<long>>();
    SECURE_CHECK(values.size() == n, "episode_outcomes." << kEpisodeColumns[c] << " has "
                                                         << values.size() << " values, expected "
                                                         << n << " (episodes)");
    for (std::size_t i = 0; i < n; ++i) {
      eval::EpisodeOutcome& e = r->episode_outcomes[i];
      e.episode = static_cast<long>(i);
      const long v = values[i];
      switch (c) {
        case 0: e.success = v != 0; break;
        case 1: e.dangerous = v != 0; break;
        case 2: e.steps = static_cast<int>(v); break;
        case 3: e.first_dangerous_step = static_cast<int>(v); break;
        case 4: e.collision_events = v; break;
        case 5: e.interventions = v; break;
        default: e.no_safe_action_decisions = v; break;
      }
    }
  }
}

// The per-episode outcomes (if any) sum to the seed's counts; `where` names the record.
void CheckEpisodeSums(const eval::SeedResult& r, const std::string& where) {
  long sums[7] = {0, 0, 0, 0, 0, 0, 0};
  for (const eval::EpisodeOutcome& e : r.episode_outcomes)
    for (int c = 0; c < 7; ++c) sums[c] += c == 3 ? 0 : EpisodeColumn(e, c);
  const long want[7] = {r.successes,       r.dangerous,     r.steps, 0,
                        r.collision_events, r.interventions, r.no_safe_action_decisions};
  for (int c = 0; c < 7; ++c)
    SECURE_CHECK(sums[c] == want[c] || r.episode_outcomes.empty(),
                 where << ": episode_outcomes." << kEpisodeColumns[c] << " sum to " << sums[c]
                       << ", the seed's count is " << want[c]);
}

}  // namespace

eval::SeedResult SeedResultFromJson(const nlohmann::json& j) {
  eval::SeedResult r;
  r.episodes = j.at("episodes").get<long>();
  r.successes = j.at("successes").get<long>();
  r.dangerous = j.at("dangerous").get<long>();
  r.collision_events = j.at("collision_events").get<long>();
  r.steps = j.at("steps").get<long>();
  r.mean_steps_to_goal = Number(j, "mean_steps_to_goal");
  r.decisions = j.at("decisions").get<long>();
  r.interventions = j.at("interventions").get<long>();
  r.resampled_decisions = j.at("resampled_decisions").get<long>();
  r.no_safe_action_decisions = j.at("no_safe_action_decisions").get<long>();
  r.invalid_input_decisions = j.at("invalid_input_decisions").get<long>();
  r.mean_iterations = Number(j, "mean_iterations");
  r.qp_tried = static_cast<long>(Number(j, "qp_tried"));
  r.qp_decisions = static_cast<long>(Number(j, "qp_decisions"));
  r.qp_rejected = static_cast<long>(Number(j, "qp_rejected"));
  const nlohmann::json& l = j.at("latency_us");
  r.latency_us.count = l.at("count").get<long>();
  r.latency_us.p50 = Number(l, "p50");
  r.latency_us.p90 = Number(l, "p90");
  r.latency_us.p99 = Number(l, "p99");
  r.latency_us.max = Number(l, "max");
  r.latency_us.mean = Number(l, "mean");
  r.seconds = Number(j, "seconds");
  EpisodeOutcomesFromJson(j, &r);
  return r;
}

namespace {

// A JSON value for a message: its dump, cut at 80 characters.
std::string Quote(const nlohmann::json& j) {
  std::string text = j.dump();
  if (text.size() > 80) text = text.substr(0, 77) + "...";
  return text;
}

// The first difference between `a` and `b` as "path: A vs B" ("" if they are equal).
std::string FirstDifference(const nlohmann::json& a, const nlohmann::json& b,
                            const std::string& path) {
  if (a == b) return "";
  const std::string where = path.empty() ? "(the whole document)" : path;
  if (a.is_object() && b.is_object()) {
    for (const auto& [key, value] : a.items()) {
      const std::string sub = path.empty() ? key : path + "." + key;
      if (!b.contains(key)) return sub + ": " + Quote(value) + " vs (missing)";
      std::string d = FirstDifference(value, b.at(key), sub);
      if (!d.empty()) return d;
    }
    for (const auto& [key, value] : b.items())
      if (!a.contains(key))
        return (path.empty() ? key : path + "." + key) + ": (missing) vs " + Quote(value);
  }
  if (a.is_array() && b.is_array() && a.size() == b.size()) {
    for (std::size_t i = 0; i < a.size(); ++i) {
      std::string d = FirstDifference(a[i], b[i], path + "[" + std::to_string(i) + "]");
      if (!d.empty()) return d;
    }
  }
  return where + ": " + Quote(a) + " vs " + Quote(b);
}

// A task file's checksum (issue 34: an edited successes = 99 of 3 episodes gave "841.7 %"):
// "crc32:" + the CRC-32 of the compact JSON of every other field. It catches edits and damage,
// not a forger who recomputes it.
std::string TaskChecksum(const nlohmann::json& task) {
  nlohmann::json content = task;
  content.erase("checksum");
  boost::crc_32_type crc;
  const std::string text = content.dump();
  crc.process_bytes(text.data(), text.size());
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", static_cast<unsigned>(crc.checksum()));
  return std::string("crc32:") + hex;
}

// A task file's content (parsed); an error naming the file if it is not one.
nlohmann::json ReadTaskFile(const std::string& path) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(ReadFile(path));
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW(path << ": not a task file (" << e.what() << "); remove it to recompute the seed");
  }
  SECURE_CHECK(j.is_object() && j.contains("experiment") && j.contains("seed") &&
                   j.contains("results") && j.contains("summary") &&
                   j["seed"].is_number_unsigned() && j["results"].is_array(),
               path << ": not a task file (expected an object with experiment, seed, results and "
                       "summary); remove it to recompute the seed");
  SECURE_CHECK(j.contains("checksum") && j["checksum"].is_string(),
               path << ": no checksum (a task file of an older version, or edited); remove it to "
                       "recompute the seed");
  const std::string want = TaskChecksum(j);
  SECURE_CHECK(j["checksum"].get<std::string>() == want,
               path << ": checksum " << j["checksum"].get<std::string>() << " does not match its "
                    << "content (" << want << "): the file was edited or damaged; remove it to "
                    << "recompute the seed");
  return j;
}

}  // namespace

std::string SeedDir(const std::string& run_dir, std::uint64_t seed) {
  return run_dir + "/seed-" + std::to_string(seed);
}

nlohmann::json ExperimentIdentity(const ExperimentResult& r) {
  nlohmann::json options = r.options_json;
  options.erase("threads");
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : r.methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json variants = nlohmann::json::array();
  for (const BarrierDataVariant& v : r.variants) variants.push_back(v.ToJson());
  return {
      {"format", kTaskFormat},
      {"version", Version()},
      {"kind", ToString(kExperimentKindNames, r.kind)},
      {"domain", r.domain},
      {"domain_title", r.domain_title},
      {"domain_options", r.domain_options},
      {"methods", method_names},
      {"variants", variants},
      {"options", options},
      // Not in options.ToJson() (so not in result.json), but the tests across seeds use it.
      {"evaluation",
       {{"tost_bound", r.options.evaluation.tost_bound}, {"alpha", r.options.evaluation.alpha}}},
      {"data",
       {{"demonstrations", r.demonstrations},
        {"discarded_demonstrations", r.discarded_demonstrations},
        {"demonstration_steps", r.demonstration_steps},
        {"safe_states", r.safe_states},
        {"near_dangerous_states", r.near_dangerous_states}}}};
}

nlohmann::json TaskJson(const nlohmann::json& identity, std::uint64_t seed, int threads,
                        double data_seconds, const SeedOutcome& outcome) {
  nlohmann::json results = nlohmann::json::array();
  for (const auto& per_variant : outcome.results) {
    nlohmann::json methods = nlohmann::json::object();
    for (const auto& [method, r] : per_variant)
      methods[ToString(eval::kMethodNames, method)] = SeedResultJson(r);
    results.push_back(std::move(methods));
  }
  nlohmann::json task = {{"experiment", identity},
                         {"seed", seed},
                         {"threads", threads},
                         {"data_seconds", data_seconds},
                         {"results", std::move(results)},
                         {"summary", outcome.summary}};
  task["checksum"] = TaskChecksum(task);
  return task;
}

SeedOutcome OutcomeFromTask(const nlohmann::json& task, const std::string& path,
                            std::size_t variants) {
  SECURE_CHECK(task["results"].size() == variants, path << ": " << task["results"].size()
                                                        << " variants of results, expected "
                                                        << variants);
  SeedOutcome outcome;
  try {
    for (const nlohmann::json& per_variant : task["results"]) {
      std::map<eval::Method, eval::SeedResult> methods;
      for (const auto& [name, r] : per_variant.items()) {
        try {
          methods[FromString(eval::kMethodNames, name, "method")] = SeedResultFromJson(r);
        } catch (const Error& e) {
          SECURE_THROW(path << ": results[" << outcome.results.size() << "]." << name << ": "
                            << e.what());
        }
      }
      outcome.results.push_back(std::move(methods));
    }
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW(path << ": malformed results (" << e.what() << ")");
  }
  // Counts in range: a rate is a count of episodes (or decisions) over episodes (decisions).
  for (std::size_t v = 0; v < outcome.results.size(); ++v) {
    for (const auto& [method, r] : outcome.results[v]) {
      const std::string where = path + ": results[" + std::to_string(v) + "]." +
                                std::string(ToString(eval::kMethodNames, method));
      SECURE_CHECK(r.episodes >= 0, where << ".episodes = " << r.episodes << ", must be >= 0");
      for (const auto& [name, count] : {std::pair<const char*, long>{"successes", r.successes},
                                        {"dangerous", r.dangerous}})
        SECURE_CHECK(count >= 0 && count <= r.episodes,
                     where << "." << name << " = " << count << ", must be in [0, episodes = "
                           << r.episodes << "]");
      for (const auto& [name, count] :
           {std::pair<const char*, long>{"interventions", r.interventions},
            {"resampled_decisions", r.resampled_decisions},
            {"no_safe_action_decisions", r.no_safe_action_decisions},
            {"invalid_input_decisions", r.invalid_input_decisions}})
        SECURE_CHECK(count >= 0 && count <= r.decisions,
                     where << "." << name << " = " << count << ", must be in [0, decisions = "
                           << r.decisions << "]");
      SECURE_CHECK(r.steps >= 0 && r.decisions >= 0 && r.collision_events >= 0,
                   where << ": negative steps, decisions or collision events");
      CheckEpisodeSums(r, where);
    }
  }
  outcome.summary = task["summary"];
  return outcome;
}

std::optional<SeedOutcome> ReusableTask(const std::string& run_dir, std::uint64_t seed,
                                        const nlohmann::json& identity, std::size_t variants) {
  if (run_dir.empty()) return std::nullopt;
  const std::string path = SeedDir(run_dir, seed) + "/" + kTaskFile;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return std::nullopt;
  const nlohmann::json task = ReadTaskFile(path);
  SECURE_CHECK(task["seed"].get<std::uint64_t>() == seed, path << ": the task of seed "
                                                               << task["seed"].get<std::uint64_t>()
                                                               << ", expected seed " << seed);
  const std::string difference = FirstDifference(task["experiment"], identity, "");
  SECURE_CHECK(difference.empty(),
               path << ": the task of a different experiment (" << difference
                    << "; the file's vs this run's): remove it (or the run directory) to "
                       "recompute, or write to another --out");
  return OutcomeFromTask(task, path, variants);
}

TaskSet ReadTaskFiles(const std::vector<std::string>& run_dirs) {
  SECURE_CHECK(!run_dirs.empty(), "merge: no run directory given");
  // Every task file, by seed (a directory given twice counts once).
  std::vector<std::string> dirs;
  std::vector<std::filesystem::path> seen;
  for (const std::string& dir : run_dirs) {
    std::error_code ec;
    SECURE_CHECK(std::filesystem::is_directory(dir, ec),
                 "merge: '" << dir << "' is not a directory (a run directory of a shard)");
    const std::filesystem::path canonical = std::filesystem::canonical(dir, ec);
    if (std::find(seen.begin(), seen.end(), canonical) != seen.end()) continue;
    seen.push_back(canonical);
    dirs.push_back(dir);
  }
  TaskSet set;
  for (const std::string& dir : dirs) {
    std::vector<std::string> paths;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      if (entry.is_directory() && name.rfind("seed-", 0) == 0 &&
          std::filesystem::exists(entry.path() / kTaskFile))
        paths.push_back((entry.path() / kTaskFile).string());
    }
    std::sort(paths.begin(), paths.end());
    for (const std::string& path : paths) {
      nlohmann::json task = ReadTaskFile(path);
      if (set.first_path.empty()) {
        set.first_path = path;
        set.identity = task["experiment"];
      } else {
        const std::string difference = FirstDifference(task["experiment"], set.identity, "");
        SECURE_CHECK(difference.empty(), "merge: " << path << " and " << set.first_path
                                                   << " are tasks of different experiments ("
                                                   << difference << ")");
      }
      const std::uint64_t seed = task["seed"].get<std::uint64_t>();
      const auto [it, inserted] = set.tasks.emplace(seed, std::make_pair(path, std::move(task)));
      // One file reached twice (a merged directory's seed-K links to a shard's) counts once.
      std::error_code ec;
      SECURE_CHECK(inserted || std::filesystem::equivalent(it->second.first, path, ec),
                   "merge: seed " << seed << " is there twice: " << it->second.first << " and "
                                  << path);
    }
  }
  SECURE_CHECK(!set.first_path.empty(), "merge: no task file (seed-K/"
                                            << kTaskFile << ") in " << dirs.front()
                                            << (dirs.size() > 1 ? " and the others" : "")
                                            << ": run the experiment's shards with --out first");
  const nlohmann::json& identity = set.identity;
  SECURE_CHECK(identity.value("format", 0) == kTaskFormat,
               "merge: " << set.first_path << ": task format " << identity.value("format", 0)
                         << ", this version reads " << kTaskFormat);
  SECURE_CHECK(identity.value("version", std::string()) == Version(),
               "merge: " << set.first_path << " was written by secure "
                         << identity.value("version", std::string("?")) << ", this is "
                         << Version());
  return set;
}

ExperimentResult ResultFromTasks(const TaskSet& set) {
  const nlohmann::json& identity = set.identity;
  ExperimentResult result;
  try {
    result.kind = FromString(kExperimentKindNames, identity.at("kind").get<std::string>(), "kind");
    result.domain = identity.at("domain").get<std::string>();
    result.domain_title = identity.at("domain_title").get<std::string>();
    result.domain_options = identity.at("domain_options");
    for (const nlohmann::json& m : identity.at("methods"))
      result.methods.push_back(FromString(eval::kMethodNames, m.get<std::string>(), "method"));
    for (const nlohmann::json& v : identity.at("variants"))
      result.variants.push_back({v.at("name").get<std::string>(),
                                 v.at("data_fraction").get<double>(), v.at("imbalance").get<int>(),
                                 v.at("label_noise").get<double>()});
    const nlohmann::json& data = identity.at("data");
    result.demonstrations = data.at("demonstrations").get<long>();
    result.discarded_demonstrations = data.at("discarded_demonstrations").get<long>();
    result.demonstration_steps = data.at("demonstration_steps").get<long>();
    result.safe_states = data.at("safe_states").get<long>();
    result.near_dangerous_states = data.at("near_dangerous_states").get<long>();
    const nlohmann::json& options = identity.at("options");
    result.options.barrier_kind = FromString(
        kBarrierKindNames, options.at("barrier_kind").get<std::string>(), "barrier_kind");
    result.options.seeds = options.at("seeds").get<int>();
    result.options.episodes = options.at("episodes").get<long>();
    result.options.first_seed = options.at("first_seed").get<std::uint64_t>();
    const nlohmann::json& evaluation = identity.at("evaluation");
    result.options.evaluation.tost_bound = evaluation.at("tost_bound").get<double>();
    result.options.evaluation.alpha = evaluation.at("alpha").get<double>();
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW("merge: " << set.first_path << ": malformed experiment record (" << e.what()
                           << ")");
  }
  const std::pair<std::string, nlohmann::json>& first = set.tasks.begin()->second;
  result.options.threads = first.second.value("threads", 1);
  // options.ToJson()'s key order: `threads` is its last key.
  result.options_json = identity["options"];
  result.options_json["threads"] = result.options.threads;

  // Every seed exactly once.
  const std::uint64_t first_seed = result.options.first_seed;
  std::vector<std::uint64_t> missing;
  for (int i = 0; i < result.options.seeds; ++i)
    if (set.tasks.count(first_seed + static_cast<std::uint64_t>(i)) == 0)
      missing.push_back(first_seed + static_cast<std::uint64_t>(i));
  if (!missing.empty()) {
    std::ostringstream list;
    for (std::size_t i = 0; i < missing.size() && i < 20; ++i)
      list << (i ? ", " : "") << missing[i];
    if (missing.size() > 20) list << ", ...";
    SECURE_THROW("merge: " << missing.size() << " of " << result.options.seeds
                           << " seeds have no task file (seed " << list.str()
                           << "): rerun the shard(s) that own them");
  }
  for (const auto& [seed, entry] : set.tasks)
    SECURE_CHECK(
        seed >= first_seed && seed < first_seed + static_cast<std::uint64_t>(result.options.seeds),
        "merge: " << entry.first << " is the task of seed " << seed
                  << ", outside the experiment's seeds " << first_seed << " to "
                  << first_seed + static_cast<std::uint64_t>(result.options.seeds) - 1);
  return result;
}

}  // namespace secure::experiments::internal
