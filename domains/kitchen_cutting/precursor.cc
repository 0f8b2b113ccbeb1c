#include "domains/kitchen_cutting/precursor.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "domains/franka/human_arm.h"

namespace secure::domains::kitchen_cutting {

double ReachPrecursorStep(const KitchenCuttingOptions& task) {
  return 0.25 * task.tracking.control_period;
}

bool ReachPrecursorState(const KitchenCuttingOptions& task,
                         const KitchenNearDangerousOptions& options, Rng& rng,
                         Eigen::Ref<Eigen::VectorXf> o) {
  const HumanArmOptions& h = task.human;
  // A reach into the knife's workspace, as the population draws it; it starts at time 0 here
  // (its start time only shifts the timeline).
  HumanArmOptions into = h;
  into.into_probability = 1.0;
  ReachPath path = DrawReachPath(into, rng);
  path.start = 0.0;
  const double gap = options.reach_gap[0] + (options.reach_gap[1] - options.reach_gap[0]) *
                                                rng.Uniform();
  const double dt = ReachPrecursorStep(task);
  const int ahead = std::max(1, static_cast<int>(std::lround(gap / dt)));
  const int moving = static_cast<int>(std::ceil(path.travel / dt));  // grid points of the reach
  // The arm on the grid, up to the last contact instant considered.
  std::vector<ArmPose> arm(static_cast<std::size_t>(moving + 1));
  for (int k = 0; k <= moving; ++k) arm[static_cast<std::size_t>(k)] =
      ArmPoseForWrist(h, path.Wrist(h, k * dt));
  // The knife continuing its demonstrated motion (the label check's continuation).
  const Eigen::Vector3d edge0(o[kBlade], o[kBlade + 1], o[kBlade + 2]);
  const Eigen::Vector3d v(o[kEeVel], o[kEeVel + 1], o[kEeVel + 2]);
  auto edge_at = [&](double u) {
    Eigen::Vector3d e = edge0 + std::min(u, options.look_ahead) * v;
    e.z() = std::max(e.z(), task.board_top);
    return e;
  };
  auto touches = [&](double u, int k) {
    return EdgeToArmDistance(h, edge_at(u), arm[static_cast<std::size_t>(k)]) <
           task.contact_distance;
  };
  // The earliest state time i * dt (contact while the arm moves, at i + j <= moving) from which
  // the edge reaches the arm within (0, gap].
  for (int i = 0; i < moving; ++i) {
    if (touches(0.0, i)) return false;  // in contact already: the reach went through the knife
    bool reaches = false;
    for (int j = 1; j <= ahead && i + j <= moving && !reaches; ++j) reaches = touches(j * dt, i + j);
    if (!reaches) continue;
    // The observation as KitchenCuttingSim makes it (UpdateHuman: central differences).
    constexpr double kH = 1e-3;
    const double t = i * dt, behind = std::max(0.0, t - kH);
    const ArmPose a = ArmPoseForWrist(h, path.Wrist(h, t + kH));
    const ArmPose b = ArmPoseForWrist(h, path.Wrist(h, behind));
    const double span = t + kH - behind;
    franka::WriteHumanArm(arm[static_cast<std::size_t>(i)], (a.wrist - b.wrist) / span,
                          (a.elbow - b.elbow) / span, kWrist, o);
    return true;
  }
  return false;
}

}  // namespace secure::domains::kitchen_cutting
