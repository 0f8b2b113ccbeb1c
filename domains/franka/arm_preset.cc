#include "domains/franka/arm_preset.h"

namespace secure::domains::franka {

experiments::ExperimentOptions ArmExperimentPreset(experiments::Profile profile,
                                                   double control_period) {
  experiments::ExperimentOptions o;
  o.barrier_kind = experiments::BarrierKind::kFlat;
  o.flat_barrier.activation = nn::Activation::kTanh;
  // Table 2's nets are deep (up to 10 layers): a lower step size than the small nets' 3e-3 (at
  // 3e-3 panda-push's best validation epoch was the first).
  o.flat_barrier.learning_rate = 1e-3;
  o.flat_barrier.final_learning_rate = 1e-5;
  o.flat_barrier.max_epochs = 100;
  // AIRL on fixed-horizon episodes, with the BC regulariser as in Derby.
  o.airl.iterations = 10;
  o.airl.steps_per_iteration = 3000;
  o.airl.bc_weight = 1.0;
  // The shield: M = 128 (the paper's Panda setting in its Figure 9 runs), rho0 = 0.1, one control
  // period ahead; alpha dt = 0.8 < 1 (requirement R3; the authors' scripts use alpha dt = 1, the
  // myopic test). alpha dt = 0.2 (k = 5, until 2026-12-01) stalled the knife above the board in
  // kitchen-cutting (success 56.6 -> 91.6 % with k = 20 on the same models, dangerous 5.1 -> 5.3 %)
  // and let more blocks topple in panda-push (20 seeds: 7.5 -> 3.5 %; docs/RESULTS.md).
  o.shield.num_samples = 128;
  o.shield.safe_ratio = 0.1;
  o.shield.dt = control_period;
  o.shield.class_k_gain = 20.0;
  o.shield.probe_extent = 1.0;
  // Statistics: 10 seeds x 100 episodes.
  o.seeds = 10;
  o.episodes = 100;
  // The pre-deployment barrier check runs per seed (check_enabled, the default): each plug-in
  // gives its problem (Domain::MakeCheckProblem, arm_check.h). Its defaults: a 5-point action
  // grid per axis (125 actions for the 3-d actions, 625 for coffee-placing's 4-d ones, + the
  // random ones per max_a g; the default 7 points would be 2401 for 4-d actions).
  o.check.action_grid = 5;
  if (profile == experiments::Profile::kQuick) {
    o.seeds = 2;
    o.episodes = 5;
    o.bc.epochs = 10;
    o.airl.iterations = 2;
    o.airl.steps_per_iteration = 600;
    o.flat_barrier.max_epochs = 5;
    o.data_fractions = {1.0, 0.1};
    o.imbalance_ratios = {1, 4};
    o.label_noise = {0.0, 0.3};
  }
  return o;
}

}  // namespace secure::domains::franka
