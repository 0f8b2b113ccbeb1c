#pragma once
// What the report (tools/report) needs of a domain, asked through the registry so that no host
// names a domain: the ReportHints capability (how to draw the domain's barrier and trajectories)
// and the paper's numbers as one JSON document (Domain::PaperReference, PaperGroundTruthReference
// and the population's PaperReference).
//
// A hint is plain JSON: the report reads it (tools/report/hints.py checks every field and names
// the bad one); tools/report/README.md, "Report hints", is the schema. Both documents reach Python
// as secure.report_hints(domain, **options) and secure.paper_reference(domain, **options).
#include <nlohmann/json.hpp>

namespace secure::experiments {

class Domain;
struct PaperTable3;

/// How the report draws a domain (Domain::MakeReportHints): each picture is a JSON object
/// (schema: tools/report/README.md, "Report hints"), or null when the domain has none.
///  - barrier: the learned barrier h over two state features, the others fixed (a base state:
///    zeros, pattern fills, or one chosen from a run directory's states file), in one or more
///    panels, with the world's shapes (circles, rectangles, marks) and a caption;
///  - trajectories: episodes of seed 0's AIRL policy with and without the shield, drawn in two
///    position features (or ego-relative to an observed goal), with the world's shapes.
struct ReportHints {
  nlohmann::json barrier;       // null: no barrier picture
  nlohmann::json trajectories;  // null: no trajectory picture
  nlohmann::json ToJson() const { return {{"barrier", barrier}, {"trajectories", trajectories}}; }
};

/// The paper's Table 3 row of a domain as JSON: {source, rows: [{method, success, success_std,
/// dangerous, dangerous_std}] (percent, null where the paper gives none), comparison}.
nlohmann::json PaperTable3Json(const PaperTable3& paper);

/// Every paper number the domain gives, as one object with the keys it has: "table3"
/// (PaperTable3Json), "ground_truth_study" ({over_conservative, over_conservative_std,
/// under_conservative, under_conservative_std}, %), "user_study" ({source, rows: [{what,
/// values}]}, from the population with default options). Empty: the paper has none for it.
nlohmann::json PaperReferenceJson(const Domain& domain);

/// The domain's hints as JSON ({barrier, trajectories}), or null if it has none.
nlohmann::json ReportHintsJson(const Domain& domain);

}  // namespace secure::experiments
