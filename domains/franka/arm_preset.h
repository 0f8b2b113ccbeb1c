#pragma once
// The experiment preset the Franka plug-ins share (panda-push, kitchen-cutting, coffee-placing):
// a flat tanh barrier trained at 1e-3 -> 1e-5 for at most 100 epochs, AIRL with 10 iterations of
// 3000 steps on the fixed-horizon episodes and the BC regulariser, the shield with M = 128,
// rho0 = 0.1, one control period ahead, class-K gain 20 (alpha dt = 0.8 < 1, requirement R3)
// and probes over [-1, 1]; 10 seeds x 100 episodes; the pre-deployment barrier check per seed.
// The check's defaults: a 5-point action grid per axis. The quick profile: 2 seeds x 5 episodes,
// short training, two-point sensitivity grids. Each plug-in adds its data seed and its barrier's
// layers and input features.
#include "secure/experiments/experiment.h"

namespace secure::domains::franka {

experiments::ExperimentOptions ArmExperimentPreset(experiments::Profile profile,
                                                   double control_period);

}  // namespace secure::domains::franka
