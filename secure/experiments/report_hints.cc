// The paper's numbers and the report hints of a domain as JSON (report_hints.h).
#include "secure/experiments/report_hints.h"

#include <cmath>
#include <memory>
#include <optional>

#include "secure/experiments/domain.h"

namespace secure::experiments {
namespace {

nlohmann::json Number(double v) {
  return std::isnan(v) ? nlohmann::json(nullptr) : nlohmann::json(v);
}

}  // namespace

nlohmann::json PaperTable3Json(const PaperTable3& paper) {
  nlohmann::json rows = nlohmann::json::array();
  for (const PaperTable3Row& r : paper.rows) {
    rows.push_back({{"method", r.method},
                    {"success", Number(r.success)},
                    {"success_std", Number(r.success_std)},
                    {"dangerous", Number(r.dangerous)},
                    {"dangerous_std", Number(r.dangerous_std)}});
  }
  return {{"source", paper.source}, {"rows", rows}, {"comparison", paper.comparison}};
}

nlohmann::json PaperReferenceJson(const Domain& domain) {
  nlohmann::json out = nlohmann::json::object();
  if (const std::optional<PaperTable3> t = domain.PaperReference())
    out["table3"] = PaperTable3Json(*t);
  if (const std::optional<PaperGroundTruthStudy> g = domain.PaperGroundTruthReference()) {
    out["ground_truth_study"] = {{"over_conservative", Number(g->over_conservative)},
                                 {"over_conservative_std", Number(g->over_conservative_std)},
                                 {"under_conservative", Number(g->under_conservative)},
                                 {"under_conservative_std", Number(g->under_conservative_std)}};
  }
  if (domain.HasPopulation()) {
    const std::unique_ptr<Population> population = domain.MakePopulation(PopulationOptions{});
    if (const std::optional<PaperUserStudy> u = population->PaperReference()) {
      nlohmann::json rows = nlohmann::json::array();
      for (const auto& [what, values] : u->rows)
        rows.push_back({{"what", what}, {"values", values}});
      out["user_study"] = {{"source", u->source}, {"rows", rows}};
    }
  }
  return out;
}

nlohmann::json ReportHintsJson(const Domain& domain) {
  const std::optional<ReportHints> hints = domain.MakeReportHints();
  return hints ? hints->ToJson() : nlohmann::json(nullptr);
}

}  // namespace secure::experiments
