#pragma once
// Kitchen cutting's near-dangerous scenario (d), the person's real reach (issue 30 lever 5; paper
// Eq. 2: near-dangerous states are states a trajectory into danger passes BEFORE it becomes
// dangerous). Scenarios (a)-(c) (data.h) put the arm near the blade by construction; (b) moves it
// in a random direction at a constant 0.2-0.6 m/s. The remaining failure mode of SECURE on this
// task is a FAST reach (the minimum-jerk profile's peak is 1.9x the mean speed, up to 1.1 m/s)
// arriving at the blade, from states the barrier rated safe at ~11 cm (docs/RESULTS.md, "Issue
// 30 on kitchen cutting"). (d) takes such states from the reach itself:
//
//   for a demonstration state, a reach into the knife's workspace is drawn as the population
//   draws it (DrawReachPath with into_probability 1: goal over the cut line, mean speed
//   U(human.speed), minimum jerk); the knife continues its demonstrated motion (the edge at the
//   state's end-effector velocity for look_ahead s, then holding; never below the board: the
//   kinematics of the label check's continuation, CheckKitchenLabels), the arm follows the reach;
//   a gap g ~ U(reach_gap) is drawn, and the state is the earliest instant ts of the reach (a
//   grid of control_period / 4) from which the edge comes within contact_distance of the arm
//   within (0, g]: "contact time minus g", so not yet in contact. The arm's wrist, elbow and hand
//   tip are the reach's at ts, their velocities the reach's (central differences, as
//   KitchenCuttingSim observes them); everything else is the demonstration state's. A reach that
//   does not come within contact_distance of the knife while moving is no draw (the caller
//   retries).
#include <Eigen/Core>

#include "domains/kitchen_cutting/data.h"
#include "secure/common/rng.h"

namespace secure::domains::kitchen_cutting {

/// One draw of scenario (d) from the demonstration state `o` (changed in place only if the
/// draw is accepted). Returns whether it was.
bool ReachPrecursorState(const KitchenCuttingOptions& task,
                         const KitchenNearDangerousOptions& options, Rng& rng,
                         Eigen::Ref<Eigen::VectorXf> o);

/// The grid of ReachPrecursorState's search (s): a quarter of the control period.
double ReachPrecursorStep(const KitchenCuttingOptions& task);

}  // namespace secure::domains::kitchen_cutting
