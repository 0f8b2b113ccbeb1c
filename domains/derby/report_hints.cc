// What the report shows of Demolition Derby: the paper's Table 3 row and the picture hints
// (experiments::ReportHints; the schema is tools/report/README.md, "Report hints").
#include <algorithm>
#include <cstdio>
#include <string>

#include "domains/derby/domain.h"

namespace secure::domains::derby {

std::optional<experiments::PaperTable3> DerbyDomain::PaperReference() const {
  // Table 3 (Section 6.1): mean (std) over ten seeds of 100 episodes; the paper's tests.
  return experiments::PaperTable3{
      "Table 3 (Section 6.1), Demolition Derby, mean (std) over ten seeds, 100 episodes",
      {{"bc", 17.9, 3.6, 65.7, 4.1},
       {"airl", 46.8, 4.7, 75.4, 4.9},
       {"secure", 49.2, 5.6, 4.2, 1.2}},
      "success +2.4% (TOST p < .01 with bound=10); dangerous -71.2% (Mann-Whitney U = 0, "
      "p < .001)"};
}

std::optional<experiments::ReportHints> DerbyDomain::MakeReportHints() const {
  const DerbyOptions& task = options_.task;
  // The barrier's window: a few collision radii r about the ego, inside the sensing radius R.
  const cbf::CarFeatureSpec& input = Preset().per_obstacle_barrier.input;
  const double extent =
      std::min(input.sensing_radius * 1.05, std::max(5.0 * input.collision_radius, 0.2));
  experiments::ReportHints h;
  h.barrier = {
      {"x",
       {{"feature", "car0_dx"},
        {"range", {-extent, extent}},
        {"label", "car0_dx (other car - ego)"}}},
      {"y", {{"feature", "car0_dy"}, {"range", {-extent, extent}}, {"label", "car0_dy"}}},
      {"grid", 161},
      // Ego at rest, car 0 (the nearest) on the grid with zero relative velocity, every other
      // car far out of sensing range.
      {"base", {{"fill", {{{"match", "^car[0-9]+_d[xy]$"}, {"value", 1.0e3}}}}}},
      {"zero_level", "if_crossing"},
      {"marks", {{{"at", {0.0, 0.0}}, {"marker", "+"}, {"color", "black"}}}},
      {"shapes",
       {{{"kind", "circle"},
         {"center", {0.0, 0.0}},
         {"radius", input.collision_radius},
         {"fill", false},
         {"color", "gray"},
         {"linewidth", 1},
         {"linestyle", ":"}}}},
      {"aspect", "equal"},
      {"caption",
       "The learned per-car barrier of <code>{model}</code> around the ego car (+) as a "
       "function of one other car's relative position (relative velocity 0, ego at rest, every "
       "other car out of range). Black: h = 0; dotted gray: the collision radius."}};
  const double side = task.arena_side;
  char arena[64];
  std::snprintf(arena, sizeof arena, "%.2f", side);
  h.trajectories = {
      {"layout", "grid"},
      {"episodes", 3},
      // The observation is ego-relative (goal - p, v, car - p, ...).
      {"position", {{"goal_offset", {"goal_dx", "goal_dy"}}}},
      {"others", {{"dx", "car{i}_dx"}, {"dy", "car{i}_dy"}}},
      {"shapes",
       {{{"kind", "rectangle"},
         {"corner", {0.0, 0.0}},
         {"size", {side, side}},
         {"fill", false},
         {"color", "#999999"},
         {"linestyle", "--"},
         {"linewidth", 0.8}}}},
      {"goal", {{"at", "observed"}, {"radius", task.goal_radius}}},
      {"contact_radius", task.collision_radius},
      {"limits",
       {{"at_least", {-0.25, side + 0.25}}, {"at_most", {-1.0 - side, 2.0 * side + 1.0}}}},
      {"caption",
       std::string("Episodes 0&ndash;{last_episode} of seed 0's evaluation stream, played with "
                   "seed 0's AIRL policy without (top) and with (bottom) the shield over its "
                   "per-car barrier ({shield_note}), the same episodes in each column. The ego "
                   "car's path: green reached the goal (star, circle: the goal radius), red "
                   "touched a car, blue neither; red crosses (circle: the collision radius): the "
                   "steps it was in contact; orange dots: the steps where the shield intervened "
                   "(changed the policy's action; counted in the titles). Faint gray dots: the "
                   "{others} nearest (observed) cars' positions at every step, which trace their "
                   "paths (the observation does not name the cars). Dashed: the arena [0, ") +
           arena +
           "]&sup2; of the starts. The observation is ego-relative, so positions are drawn "
           "relative to the ego's start placed at (0, 0) (its start jitter is not observed). "
           "Played with the Python module's environment and shield."}};
  return h;
}

}  // namespace secure::domains::derby
