#pragma once
// The Demolition Derby expert demonstrator (with privileged information: the TRUE future of the
// cars, which DerbyEnv generates at Reset) and the generators of SECURE's three data sets from
// it: task demonstrations, safe states and near-dangerous states. Deterministic for given seeds.
//
// The expert. One step, at the env's current frame t:
//  1. nominal goal controller (macbf's LQR baseline a = -(p - g) - sqrt(3) v, stiffer, with a
//     speed limit): a_pd = kd (v_des - v), v_des = sat_{speed_limit}((kp / kd) (g - p)); below
//     the speed limit this is exactly a = -kp (p - g) - kd v (kp = 3, kd = 3). Per episode
//     (BeginEpisode) kp is scaled by U[1 - gain_spread, 1 + gain_spread] (kd by the square root,
//     keeping the damping ratio) and the speed limit by U[1 - speed_spread, 1];
//  2. exploration: a_nom = a_pd + N(0, noise_sigma^2 I), a fresh draw every step;
//  3. safety filter, a CBF-QP over one braking-distance barrier per car (Wang, Ames & Egerstedt
//     2017), for the relative state (dp, dv) = (p - p_j, v - v_j):
//       h(dp, dv) = s(2 A (|dp| - D_s)) + dp.dv / |dp|,   s(x) = sign(x) sqrt(|x|),
//     A = braking_accel, D_s = collision_radius + clearance. h >= 0 says that the ego, braking
//     at A relative to the car, stops approaching before the distance drops to D_s. The
//     condition is imposed in DISCRETE time on the true next state:
//       h(dp', dv') >= (1 - cbf_rate dt) h(dp, dv) + margin,
//     dp' = p + v dt - p_j(t+1) and dv' = v + a dt - v_j(t+1) from the cars' true next frame
//     (privileged). With explicit Euler dp' does not depend on a, so h(dp', dv') is AFFINE in
//     a: the constraint is one half-plane n'.a >= b per car (n' = dp'/|dp'|). The filtered action
//       a = argmin ||a - a_nom||^2  s.t. the half-planes and |a_i| <= accel_bound
//     is solved exactly: the minimiser over the convex polygon is a_nom itself, its projection on
//     one of the lines (constraints and box edges), or a pairwise intersection of two lines;
//     all are enumerated and the closest feasible one is kept. Half-planes that the whole box
//     satisfies are dropped first (almost all far cars). If no action satisfies every
//     constraint, the action in the box maximising the worst constraint value (min_j n'.a - b_j)
//     is used (a 41 x 41 grid over the box, refined twice around the best point), counted in
//     DerbyExpertStats::infeasible, and the episode is discarded should it collide.
//     Why this keeps the distance: with h(t+1) >= 0 the distance two steps ahead is at least
//     D_s - A dt^2 / 2 (= D_s - 0.005), so clearance (0.04) is a margin for that and for the
//     occasional infeasible step (a car may drive into the ego from behind or sandwich it; the
//     ego's bound of 3 is not always enough within one 0.1 s step). use_filter = false skips the
//     filter (a = clip(a_nom)): the unfiltered baseline.
//
// Measured (GenerateDerbyDemonstrations, default options, seed 0, 1000 attempts): 993 kept
// (99.3 %), 2 discarded for a collision (after infeasible steps), 5 for not reaching the goal;
// steps to the goal median 47 (p10 37, p90 66, max 99); closest approach to any car in the
// kept demonstrations 0.088 (> 0.07); 243 infeasible filter steps in 1e5; 0.2-0.3 s in all.
// Without the filter (use_filter = false) 846 of the 1000 attempts collide (median 33 steps
// for the rest): the straight run through the crowd almost always touches a car.
// derby_expert_test checks the same on 200 episodes.
//
// Usage:
//   DerbyOptions task;  DerbyExpertOptions expert;  DerbyDemonstrationOptions demo;
//   DerbyDemonstrations d = GenerateDerbyDemonstrations(task, expert, demo);
//   Rng rng(2);
//   data::StateSet safe = SafeStatesFromDemonstrations(d.trajectories, 1024, rng);
//   data::StateSet nd = GenerateDerbyNearDangerous(task, d, {}, rng);

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/filtering_expert.h"
#include "domains/derby/derby.h"

namespace secure::domains::derby {

struct DerbyExpertOptions {
  // Nominal: the damping ratio of macbf's LQR (kp = 1, kd = sqrt(3): 0.87) with kp = 3,
  // kd = sqrt(3 kp) = 3, and a speed limit (norm) of the desired velocity. Why not kp = 1: the
  // final approach to the 0.05 goal radius is then slow (v_des = 0.58 |g - p|), and measured
  // over 1000 filtered episodes 9.3 % never reached the goal within 100 steps (median 67
  // steps); with kp = 3, 0.5 % (median 47).
  double kp = 3.0;
  double kd = 3.0;
  double speed_limit = 1.0;
  // Per-episode variation (see the header comment) and per-step exploration noise (per axis,
  // 5 % of the bound: visible, yet the action stays mostly a function of the state).
  double gain_spread = 0.2;
  double speed_spread = 0.3;
  double noise_sigma = 0.15;

  // The filter: braking authority A of the barrier (m/s^2; well below the 3 of the bound minus
  // the cars' own accelerations, typically < 1), the extra clearance over collision_radius, the
  // rate k of h(t+1) >= (1 - k dt) h(t) (k dt in (0, 1]; 5: h may halve per step, fewer
  // infeasible steps than 3 and the same safety) and a margin added to every constraint.
  bool use_filter = true;
  double braking_accel = 1.0;
  double clearance = 0.04;
  double cbf_rate = 5.0;
  double filter_margin = 1e-3;

  /// Throws secure::Error naming the field ("DerbyExpertOptions::kp = -1, must be > 0").
  void Validate() const;
  nlohmann::json ToJson() const;
};

/// What the filter did at one state.
struct DerbyFilterInfo {
  int constraints = 0;    // half-planes not satisfied by the whole box
  bool modified = false;  // the result differs from clip(nominal)
  bool feasible = true;   // some action in the box satisfied every constraint
  double min_h = 0.0;     // min over cars of h at the current frame
};

using DerbyExpertStats = domains::ExpertFilterStats;

class DerbyExpert {
 public:
  /// @throws secure::Error if an options struct is invalid or cbf_rate * dt is not in (0, 1].
  explicit DerbyExpert(const DerbyOptions& task, const DerbyExpertOptions& options = {});

  /// Draws this episode's gains and speed limit from `rng`.
  void BeginEpisode(Rng& rng);
  /// The expert's action for the env's current frame (reads its true state and the cars' next
  /// frame): nominal + noise from `rng`, filtered unless use_filter is false, inside the box.
  /// Allocates nothing. @throws secure::Error on a wrong dimension or an env with other options.
  void Act(const DerbyEnv& env, Rng& rng, Eigen::Ref<Eigen::VectorXf> action);

  /// The noise-free nominal action at ego position p, velocity v (not clipped).
  Eigen::Vector2d Nominal(const Eigen::Vector2d& p, const Eigen::Vector2d& v,
                          const Eigen::Vector2d& goal) const;
  /// The safety filter alone at the env's current frame.
  Eigen::Vector2d FilterAction(const DerbyEnv& env, const Eigen::Vector2d& nominal,
                               DerbyFilterInfo* info = nullptr) const;
  /// The braking-distance barrier h(dp, dv) (see the header comment).
  double PairBarrier(const Eigen::Vector2d& dp, const Eigen::Vector2d& dv) const;

  const DerbyExpertOptions& options() const { return options_; }
  const DerbyExpertStats& stats() const { return stats_; }
  void ResetStats() { stats_ = {}; }

 private:
  DerbyOptions task_;
  DerbyExpertOptions options_;
  double kp_, kd_, speed_limit_;
  DerbyExpertStats stats_;
};

// ---------------------------------------------------------------------------------------------
// Task demonstrations

struct DerbyDemonstrationOptions {
  // Kept demonstrations (AIRL uses the first 1000 trajectories in the released code).
  long episodes = 1000;
  // Attempts before giving up (0: 2 x episodes + 10). An attempt is discarded if it collides or
  // never reaches the goal within max_steps.
  long max_attempts = 0;
  // If true, kept < episodes after max_attempts is an error naming the counts.
  bool require_all = true;
  // Attempt i draws its world (Reset), the expert's episode parameters and noise from
  // DerbyAttemptRng(seed, i), in that order.
  std::uint64_t seed = 0;

  void Validate() const;
  nlohmann::json ToJson() const;
};

/// The counts (attempted, discarded_collisions, discarded_no_goal, steps_to_goal: per kept
/// episode, the first step inside the goal radius; expert, seconds): ExpertDemonstrationCounts.
struct DerbyDemonstrations : domains::ExpertDemonstrationCounts {
  // ObservationFeatures(), ActionFeatures(); every episode runs max_steps steps (the expert
  // holds at the goal once reached); the action recorded is the applied (clipped) one.
  data::TrajectorySet trajectories;
  // Per kept episode, its attempt index: DerbyEnv(task).Reset(DerbyAttemptRng(seed, attempt))
  // regenerates its world (goal and car trajectories; the ego position of frame t is
  // goal - observation[0..1]).
  std::vector<long> attempts;
  std::uint64_t seed = 0;
  double min_car_distance = 0.0;  // over all frames of the kept demonstrations

  nlohmann::json ToJson() const;
};

/// The stream of attempt `attempt` of a demonstration run with `seed`.
Rng DerbyAttemptRng(std::uint64_t seed, long attempt);

/// @throws secure::Error on invalid options, or (require_all) fewer kept than demo.episodes.
DerbyDemonstrations GenerateDerbyDemonstrations(const DerbyOptions& task,
                                                const DerbyExpertOptions& expert,
                                                const DerbyDemonstrationOptions& demo);

// ---------------------------------------------------------------------------------------------
// Safety demonstrations

/// `count` demonstration observations drawn at random: without replacement if count <=
/// num_steps() (kept in file order), otherwise every state count / n times plus a random
/// subset for the rest. @throws secure::Error unless count > 0 and the set has states.
data::StateSet SafeStatesFromDemonstrations(const data::TrajectorySet& trajectories, long count,
                                            Rng& rng);

/// Near-dangerous states as in the released code (facts §1.7), in our observation format.
/// Scheme: until `count` states are made, pick a demonstration frame uniformly at random (with
/// replacement), regenerate its world, and for each of the frame's `nearest` nearest cars j
/// (all 16 cars considered): draw rho from `rho` with `probabilities`, then
/// u ~ U(-1, 1)^2 and place the ego at p_j + u rho / sqrt(2) (so ||p - p_j|| <= rho), velocity
/// unchanged; the observation is rebuilt for the placed ego (12 nearest of all cars).
/// CONVENTION: car j must then be the NEAREST car (observation block 0), which the barrier
/// trainer relies on; if it is not, u is redrawn (up to max_redraws times, then this car is
/// skipped).
struct DerbyNearDangerousOptions {
  long count = 1024;
  std::vector<double> rho = {0.01, 0.03, 0.07, 0.10, 0.12, 0.14};
  std::vector<double> probabilities = {0.2, 0.2, 0.2, 0.2, 0.1, 0.1};
  int nearest = 3;
  int max_redraws = 20;

  /// count > 0; rho and probabilities of equal non-zero length, rho > 0, probabilities >= 0
  /// summing to 1 (within 1e-6); nearest in [1, 12]; max_redraws >= 1.
  void Validate() const;
  nlohmann::json ToJson() const;
};

/// @throws secure::Error on invalid options, demonstrations without attempts/steps, or if no
///   state can be made (100 x count frames tried).
data::StateSet GenerateDerbyNearDangerous(const DerbyOptions& task,
                                          const DerbyDemonstrations& demonstrations,
                                          const DerbyNearDangerousOptions& options, Rng& rng);

}  // namespace secure::domains::derby
