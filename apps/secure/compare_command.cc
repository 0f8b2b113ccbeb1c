// secure compare A.json B.json: are two settings equivalent on the same episodes? A and B are
// `secure eval --json` results of one domain on the same seeds and episodes (common random
// numbers: the k-th episode of seed s starts the same in both), differing in anything else (the
// shield's sampler or M, the class-K gain, the models). Per method in both and per rate, the
// seeds are the pairs: the mean difference A - B, its 90 % confidence interval, and the paired
// TOST (stats::TostPaired) with bound --tost-bound; and the decisions' latency in each file (the
// median over seeds of each seed's p50 and p99).
#include <algorithm>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/stats/statistics.h"

namespace secure::cli {
namespace {

// One `secure eval --json` result and the file it came from (for the error messages).
struct EvalFile {
  std::string path;
  nlohmann::json j;

  const nlohmann::json& At(const nlohmann::json& node, const std::string& key,
                           const std::string& where) const {
    SECURE_CHECK(node.is_object() && node.contains(key),
                 path << ": no field '" << where << key
                      << "' (not a `secure eval --json` result of this version?)");
    return node.at(key);
  }
  const nlohmann::json& At(const std::string& key) const { return At(j, key, ""); }
};

EvalFile ReadEvalFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  SECURE_CHECK(fs::exists(st), path << ": no such file");
  SECURE_CHECK(fs::is_regular_file(st), path << ": not a regular file");
  EvalFile f{path, {}};
  const std::string text = ReadFile(path);
  try {
    f.j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    SECURE_THROW(path << ": malformed JSON: " << e.what());
  }
  SECURE_CHECK(f.j.is_object() && f.j.value("command", "") == "eval",
               path << ": not a `secure eval --json` result (field 'command' is not \"eval\")");
  for (const char* key : {"domain", "first_seed", "seeds_evaluated", "episodes", "methods"})
    f.At(key);
  SECURE_CHECK(f.At("methods").is_object(), path << ": field 'methods' is not an object");
  SECURE_CHECK(f.At("seeds_evaluated").is_number_unsigned(), path << ": field 'seeds_evaluated' is "
                                                                  << f.At("seeds_evaluated").dump()
                                                                  << ", must be a count");
  return f;
}

// The per-seed values of methods.<method>.<metric>.per_seed, checked to be `n` finite numbers.
std::vector<double> PerSeed(const EvalFile& f, const std::string& method, const std::string& metric,
                            std::size_t n) {
  const std::string where = "methods." + method + "." + metric + ".";
  const nlohmann::json& m = f.At(f.At("methods"), method, "methods.");
  const nlohmann::json& values =
      f.At(f.At(m, metric, "methods." + method + "."), "per_seed", where);
  SECURE_CHECK(values.is_array() && values.size() == n,
               f.path << ": field '" << where << "per_seed' has " << values.size()
                      << " values, must have one per seed (" << n << ")");
  std::vector<double> out;
  for (const nlohmann::json& v : values) {
    SECURE_CHECK(v.is_number() && std::isfinite(v.get<double>()),
                 f.path << ": field '" << where << "per_seed' holds " << v.dump()
                        << ", must be a finite number");
    // A rate (issue 34: per-seed rates of 7.0 and -3.0 gave "200.0 %").
    SECURE_CHECK(metric.size() < 5 || metric.compare(metric.size() - 5, 5, "_rate") != 0 ||
                     (v.get<double>() >= 0.0 && v.get<double>() <= 1.0),
                 f.path << ": field '" << where << "per_seed' holds " << v.dump()
                        << ", must be a rate in [0, 1]");
    out.push_back(v.get<double>());
  }
  return out;
}

double Median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The median over seeds of seeds[k].<group>.<key> (seeds[k].<key> if group is empty): the
// latency of the shield's decision or of an unshielded method's policy query, or the reference
// forward (NaN if the file has none).
double MedianOverSeeds(const EvalFile& f, const std::string& method, const char* group,
                       const char* key) {
  std::vector<double> v;
  const nlohmann::json& m = f.j["methods"][method];
  if (!m.contains("seeds") || !m["seeds"].is_array()) return std::nan("");
  for (const nlohmann::json& s : m["seeds"]) {
    const nlohmann::json* node = &s;
    if (*group != '\0') {
      if (!s.contains(group)) continue;
      node = &s[group];
    }
    if (node->contains(key) && (*node)[key].is_number() && (*node)[key].get<double>() > 0)
      v.push_back((*node)[key].get<double>());
  }
  return Median(v);
}

// "key: a vs b" for every top-level key of a[field] / b[field] whose values differ.
std::vector<std::string> Differences(const EvalFile& a, const EvalFile& b, const char* field) {
  std::vector<std::string> out;
  const nlohmann::json& x = a.j.contains(field) ? a.j[field] : nlohmann::json::object();
  const nlohmann::json& y = b.j.contains(field) ? b.j[field] : nlohmann::json::object();
  if (!x.is_object() || !y.is_object()) {
    if (x != y) out.push_back(std::string(field) + ": " + x.dump() + " vs " + y.dump());
    return out;
  }
  std::vector<std::string> keys;
  for (auto it = x.begin(); it != x.end(); ++it) keys.push_back(it.key());
  for (auto it = y.begin(); it != y.end(); ++it)
    if (!x.contains(it.key())) keys.push_back(it.key());
  for (const std::string& k : keys) {
    const nlohmann::json vx = x.value(k, nlohmann::json()), vy = y.value(k, nlohmann::json());
    if (vx != vy)
      out.push_back(std::string(field) + "." + k + ": " + vx.dump() + " vs " + vy.dump());
  }
  return out;
}

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

struct CompareCommand {
  std::string a_path, b_path;
  double tost_bound = 0.02;
  double alpha = 0.05;
  bool json = false;

  void Register(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand(
        "compare",
        "Are two settings equivalent on the same episodes? A and B are `secure eval --json` "
        "results of the same domain, seeds and episodes (e.g. two shield samplers or sample "
        "counts): per method and rate, the difference A - B over the seeds, its 90 % interval "
        "and the paired TOST; and each file's decision latency");
    cmd->add_option("A", a_path, "a `secure eval --json` result")->required();
    cmd->add_option("B", b_path, "the reference: a `secure eval --json` result")->required();
    cmd->add_option("--tost-bound", tost_bound,
                    "equivalence bound on a rate, as a fraction (0.02: two points)")
        ->capture_default_str();
    cmd->add_option("--alpha", alpha, "significance level of the TOST verdict")
        ->capture_default_str();
    cmd->add_flag("--json", json, "print every number as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() const {
    SECURE_CHECK(std::isfinite(tost_bound) && tost_bound > 0 && tost_bound < 1,
                 "--tost-bound = " << tost_bound << ", must be in (0, 1)");
    SECURE_CHECK(std::isfinite(alpha) && alpha > 0 && alpha < 1,
                 "--alpha = " << alpha << ", must be in (0, 1)");
    const EvalFile a = ReadEvalFile(a_path), b = ReadEvalFile(b_path);
    // The same episodes: one domain, the same seeds, the same number of episodes per seed.
    for (const char* key : {"domain", "first_seed", "seeds_evaluated", "episodes"})
      SECURE_CHECK(a.At(key) == b.At(key),
                   a.path << " and " << b.path << " are not of the same episodes: field '" << key
                          << "' is " << a.At(key).dump() << " and " << b.At(key).dump());
    const auto seeds = a.At("seeds_evaluated").get<std::size_t>();
    SECURE_CHECK(seeds >= 2, a.path << ": field 'seeds_evaluated' is " << seeds
                                    << ", the paired test needs at least 2 seeds");
    std::vector<std::string> methods;
    for (auto it = a.At("methods").begin(); it != a.At("methods").end(); ++it)
      if (b.At("methods").contains(it.key())) methods.push_back(it.key());
    SECURE_CHECK(!methods.empty(),
                 a.path << " and " << b.path << " have no method in common (field 'methods')");

    std::vector<std::string> differs = Differences(a, b, "shield");
    for (const std::string& d : Differences(a, b, "models")) differs.push_back(d);
    for (const char* key : {"run", "config"})
      if (a.j.value(key, nlohmann::json()) != b.j.value(key, nlohmann::json()))
        differs.push_back(std::string(key) + ": " + a.j.value(key, nlohmann::json()).dump() +
                          " vs " + b.j.value(key, nlohmann::json()).dump());

    const boost::math::students_t_distribution<double> t(static_cast<double>(seeds - 1));
    const double t90 = boost::math::quantile(t, 0.95);  // two-sided 90 % interval
    nlohmann::json out = {{"command", "compare"},
                          {"a", a.path},
                          {"b", b.path},
                          {"domain", a.At("domain")},
                          {"first_seed", a.At("first_seed")},
                          {"seeds", seeds},
                          {"episodes", a.At("episodes")},
                          {"differences", differs},
                          {"tost_bound", tost_bound},
                          {"alpha", alpha},
                          {"methods", nlohmann::json::object()}};
    std::ostringstream table;
    table << "A = " << a.path << "\nB = " << b.path << "\n"
          << a.At("domain").get<std::string>() << ", seeds " << a.At("first_seed").dump() << " + "
          << seeds << ", " << a.At("episodes").dump() << " episodes per seed; A differs in: "
          << (differs.empty() ? std::string("nothing recorded") : "") << "\n";
    for (const std::string& d : differs) table << "  " << d << "\n";
    table << "\n| method | rate | A % | B % | A - B (points) | 90 % interval | TOST p (±"
          << Fixed(100 * tost_bound, 1)
          << ") | equivalent |\n|---|---|---:|---:|---:|---|---:|---|\n";
    for (const std::string& m : methods) {
      nlohmann::json mj = nlohmann::json::object();
      for (const char* metric : {"success_rate", "dangerous_rate"}) {
        const std::vector<double> va = PerSeed(a, m, metric, seeds),
                                  vb = PerSeed(b, m, metric, seeds);
        const stats::TostResult r = stats::TostPaired(va, vb, tost_bound);
        const double lo = r.difference - t90 * r.se, hi = r.difference + t90 * r.se;
        const double mean_a = stats::Summarize(va).mean, mean_b = stats::Summarize(vb).mean;
        const bool equivalent = r.equivalent(alpha);
        mj[metric] = {{"a_mean", mean_a}, {"b_mean", mean_b},   {"difference", r.difference},
                      {"ci90", {lo, hi}}, {"tost", r.ToJson()}, {"equivalent", equivalent}};
        table << "| " << m << " | "
              << (std::string(metric) == "success_rate" ? "success" : "dangerous") << " | "
              << Fixed(100 * mean_a, 1) << " | " << Fixed(100 * mean_b, 1) << " | "
              << Fixed(100 * r.difference, 1) << " | [" << Fixed(100 * lo, 1) << ", "
              << Fixed(100 * hi, 1) << "] | " << Fixed(r.p_value, 3) << " | "
              << (equivalent ? "yes" : "no")
              << (r.se > 0 ? ""
                  : r.difference == 0 ? " (identical on every seed)"
                                      : " (the same difference on every seed)")
              << " |\n";
      }
      const auto finite = [](double v) {
        return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
      };
      nlohmann::json latency = nlohmann::json::object();
      for (const auto& [file, tag] : {std::pair{&a, "a"}, std::pair{&b, "b"}}) {
        latency[std::string(tag) + "_p50"] = finite(MedianOverSeeds(*file, m, "latency_us", "p50"));
        latency[std::string(tag) + "_p99"] = finite(MedianOverSeeds(*file, m, "latency_us", "p99"));
        latency[std::string(tag) + "_reference_forward"] =
            finite(MedianOverSeeds(*file, m, "", "reference_forward_latency_us"));
      }
      mj["latency_us"] = latency;
      out["methods"][m] = mj;
    }
    table << "\n| method | p50 A / B (µs) | p99 A / B (µs) | forward of 128 A / B (µs) | p50 A / B "
             "÷ forward | p99 A / B ÷ forward |\n|---|---|---|---|---|---|\n";
    const auto num = [](const nlohmann::json& v) {
      return v.is_null() ? std::nan("") : v.get<double>();
    };
    for (const std::string& m : methods) {
      const nlohmann::json& l = out["methods"][m]["latency_us"];
      const double a_ref = num(l["a_reference_forward"]), b_ref = num(l["b_reference_forward"]);
      table << "| " << m << " | " << Fixed(num(l["a_p50"]), 0) << " / " << Fixed(num(l["b_p50"]), 0)
            << " | " << Fixed(num(l["a_p99"]), 0) << " / " << Fixed(num(l["b_p99"]), 0) << " | "
            << Fixed(a_ref, 0) << " / " << Fixed(b_ref, 0) << " | "
            << Fixed(num(l["a_p50"]) / a_ref, 2) << " / " << Fixed(num(l["b_p50"]) / b_ref, 2)
            << " | " << Fixed(num(l["a_p99"]) / a_ref, 2) << " / "
            << Fixed(num(l["b_p99"]) / b_ref, 2) << " |\n";
    }
    table << "\nLatency: the median over seeds of each seed's p50 and p99 (a shielded method's "
             "decision, else the policy query); forward: one forward of 128 states through the "
             "seed's barrier, timed by `secure eval` just before the episodes. Compare "
             "microseconds only between runs on one machine under the same load; the ratios "
             "travel better.\n";
    if (json) {
      PrintJson(out);
    } else {
      std::cout << table.str();
    }
  }
};

}  // namespace

void RegisterCompareCommand(CLI::App& app) {
  static CompareCommand compare;
  compare.Register(app);
}

}  // namespace secure::cli
