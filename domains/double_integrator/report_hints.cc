// How the report draws the double integrator (experiments::ReportHints; the schema is
// tools/report/README.md, "Report hints"): the learned barrier over the position at three
// velocities with the obstacle, and the episodes in the box [0, 10]^2 with the obstacle and the
// goal, all from the domain's task options.
#include "domains/double_integrator/domain.h"

namespace secure::domains::double_integrator {

std::optional<experiments::ReportHints> DoubleIntegratorDomain::MakeReportHints() const {
  const ReachAvoidOptions& task = options_.task;
  const nlohmann::json obstacle = {task.truth.obstacle_x, task.truth.obstacle_y};
  experiments::ReportHints h;
  h.barrier = {
      {"x", {{"feature", "x"}, {"range", {0.0, 10.0}}, {"label", "x"}}},
      {"y", {{"feature", "y"}, {"range", {0.0, 10.0}}, {"label", "y"}}},
      {"grid", 121},
      {"default_features", {"x", "y", "vx", "vy"}},  // a model that records no feature names
      {"panels",
       {{{"title", "v = (0, 0)"}, {"set", {{"vx", 0.0}, {"vy", 0.0}}}},
        {{"title", "v = (1.5, 1.5)"}, {"set", {{"vx", 1.5}, {"vy", 1.5}}}},
        {{"title", "v = (-1.5, 0)"}, {"set", {{"vx", -1.5}, {"vy", 0.0}}}}}},
      {"zero_level", "always"},
      {"ground_truth", true},
      {"shapes",
       {{{"kind", "circle"},
         {"center", obstacle},
         {"radius", task.truth.radius},
         {"fill", false},
         {"color", "gray"},
         {"linewidth", 1}}}},
      {"aspect", "equal"},
      {"caption",
       "The learned barrier h(x, y, v<sub>x</sub>, v<sub>y</sub>) of <code>{model}</code> over "
       "the position at three velocities (blue: h &gt; 0, safe). Black: its zero level set; "
       "dashed gold: the ground-truth barrier's zero level set{ground_truth}; gray: the "
       "obstacle."}};
  h.trajectories = {
      {"layout", "overlay"},
      {"episodes", 5},
      {"position", {{"x", "x"}, {"y", "y"}}},
      {"demos", {{"file", "demos.csv"}, {"x", "x"}, {"y", "y"}, {"max", 20}}},
      {"shapes",
       {{{"kind", "circle"},
         {"center", obstacle},
         {"radius", task.truth.radius},
         {"color", "gray"},
         {"alpha", 0.3}}}},
      {"goal", {{"at", {task.goal_x, task.goal_y}}}},
      {"limits", {0.0, 10.0}},
      {"caption",
       "Left: the expert demonstrations (<code>demos.csv</code>). Middle and right: five "
       "episodes of seed 0's AIRL policy without and with the shield over its barrier "
       "({shield_note}), start states drawn from the seed's evaluation stream; green: reached "
       "the goal (star), red: entered the obstacle (gray), blue: neither. Orange dots: the "
       "steps where the shield intervened (changed the policy's action; their number is in the "
       "panel's title). Played with the Python module's environment and shield."}};
  return h;
}

}  // namespace secure::domains::double_integrator
