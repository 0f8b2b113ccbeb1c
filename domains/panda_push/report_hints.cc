// What the report shows of Panda Arm Push: the paper's Table 3 row and the picture hints
// (experiments::ReportHints; the schema is tools/report/README.md, "Report hints").
#include "domains/panda_push/domain.h"

namespace secure::domains::panda_push {

std::optional<experiments::PaperTable3> PandaPushDomain::PaperReference() const {
  experiments::PaperTable3 t;
  t.source = "Table 3 (Section 6.1), Panda Arm Push, mean (std) over ten seeds, 100 episodes";
  t.rows = {{"bc", 22.7, 3.2, 72.3, 3.5},
            {"airl", 52.9, 22.6, 31.3, 17.9},
            {"secure", 96.6, 5.3, 0.0, 0.0}};
  t.comparison =
      "success +43.7% (Mann-Whitney U = 99.5, p < .001); dangerous -31.3% (Mann-Whitney U = 0, "
      "p < .001)";
  return t;
}

std::optional<experiments::ReportHints> PandaPushDomain::MakeReportHints() const {
  experiments::ReportHints h;
  h.barrier = {
      {"x", {{"feature", "ee_z"}, {"range", {0.0, 0.15}}, {"label", "ee_z (m)"}}},
      // Up to the near-dangerous pushes' speeds (their 95th percentile, at least 0.5 m/s).
      {"y",
       {{"feature", "ee_vx"},
        {"range", {0.0, 1.0}},
        {"label", "ee_vx (m/s)"},
        {"upper_from",
         {{"file", "near_dangerous.csv"},
          {"percentile", 95},
          {"scale", 1.05},
          {"at_least", 0.5}}}}},
      {"grid", 101},
      // A pushing state: among the safe states moving along +x, the one with the end effector
      // nearest the block (if the barrier reads the block's position), else the median-speed one.
      {"base",
       {{"from_file", "safe.csv"},
        {"above", {{"feature", "ee_vx"}, {"value", 0.02}}},
        {"nearest", {"block_x", "ee_x"}},
        {"median", "ee_vx"}}},
      {"zero_level", "if_crossing"},
      {"marks", {{{"at", "base"}, {"marker", "o"}, {"color", "black"}}}},
      {"caption",
       "The learned barrier of <code>{model}</code> over the end-effector height and pushing "
       "speed (x), the other features those of a pushing safe state (moving along +x, nearest "
       "the block). Black: h = 0; dot: that state."}};
  return h;  // no trajectories: a MuJoCo episode is shown by `secure render` (a video)
}

}  // namespace secure::domains::panda_push
