#pragma once
// A task environment for learning and evaluating policies: episodes of observations, actions and
// the two outcomes SECURE measures (paper Section 6): reaching the goal (success) and touching
// an obstacle (a dangerous event).
//
// Conventions:
//  - the observation is what the policy sees; for the double integrator it equals the state,
//    other domains may add or rearrange features (Demolition Derby: nearest cars and the goal);
//  - Step() applies the action as the real system would (clipping it to the actuator bounds)
//    and never ends the episode itself: whether an episode stops at the goal, at a collision or
//    only at max_steps() is the caller's choice (evaluation stops at the goal; adversarial IRL
//    runs fixed-horizon episodes, so that no termination bias enters the learned reward);
//  - everything random in an episode comes from the Rng passed to Reset(), so an episode is
//    replayed exactly from the same Rng state.
//
// Implementations must not allocate in Step() and are used from one thread at a time; make one
// environment per thread (Clone()).
#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/domains/dynamics.h"

namespace secure::domains {

/// What happened in one step. Both danger fields describe this step only:
///  - collided: the new state is dangerous (inside an obstacle, touching a car, the box toppled,
///    a threshold violated): true on EVERY step a contact lasts;
///  - collisions: dangerous events that BEGIN in this step: 1 when the state enters danger (the
///    new state is dangerous, the previous one, or the start, was not), 0 while a contact goes on
///    (the released code's collision_num). So collisions > 0 implies collided, not the converse:
///    a step inside a lasting contact has collided = true, collisions = 0. Summed over an
///    episode, collisions counts the separate contacts. Checked for every registered domain by
///    tests/domains/domain_contract_test.cc (CollisionsCountEntriesIntoDanger).
struct StepOutcome {
  bool reached_goal = false;  // the new state is within the goal region
  bool collided = false;      // the new state is dangerous (every step of a contact)
  int collisions = 0;         // contacts that begin in this step (1 on entering danger, else 0)
};

/// An RGB frame, rows top to bottom, 3 bytes per pixel (rgb.size() == 3 * width * height).
struct Frame {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
};

class Environment {
 public:
  virtual ~Environment() = default;

  virtual int observation_dim() const = 0;
  virtual int action_dim() const = 0;
  /// Column names of observations and actions in CSV files and model files.
  virtual std::vector<std::string> ObservationFeatures() const = 0;
  virtual std::vector<std::string> ActionFeatures() const = 0;
  /// The step limit of an episode.
  virtual int max_steps() const = 0;
  /// One line naming the task and its main constants.
  virtual std::string Describe() const = 0;

  /// Starts an episode drawn from `rng`; writes the first observation.
  virtual void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) = 0;
  /// Applies `action` (action_dim; clipped to the actuator bounds) and writes the next
  /// observation. @throws secure::Error on a wrong dimension or a non-finite action.
  virtual StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                           Eigen::Ref<Eigen::VectorXf> observation) = 0;

  /// The model a shield may use to look one step ahead from an observation: T(o, a) without
  /// privileged information (for the double integrator: the exact clipped dynamics).
  virtual const DynamicsModel& ShieldModel() const = 0;

  /// Whether ShieldModel() is the environment's own transition on observations: from any
  /// observation o the environment can be in, ShieldModel() applied to (o, a) gives exactly the
  /// observation Step(a) writes (the shield then sees the next state that will happen). A claim
  /// the domain contract tests check (tests/domains/domain_contract_test.cc); false (the default)
  /// claims nothing (e.g. Derby: a constant-velocity guess of the other cars).
  virtual bool ShieldModelIsExact() const { return false; }

  /// A safe action to fall back on at `observation` (e.g. braking), the shield's backup
  /// competitor when no sampled action is safe. Returns false if the domain has none.
  virtual bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                            Eigen::Ref<Eigen::VectorXf> action) const {
    return false;
  }

  /// The actuator box: Step() clips action component i to [low[i], high[i]] before applying it
  /// (low <= high; `low` and `high` have action_dim entries). The default, for an environment
  /// without one, is unbounded (-inf, +inf). The Python module's action_space, and the box the
  /// shield keeps its decisions in (shield::ShieldOptions::action_bounds), so that g is checked on
  /// the action that is applied; the contract suite checks that an action outside the box steps
  /// exactly as the clipped one, and that a backup action lies inside it.
  virtual void ActionBounds(Eigen::Ref<Eigen::VectorXf> low,
                            Eigen::Ref<Eigen::VectorXf> high) const {
    low.setConstant(-std::numeric_limits<float>::infinity());
    high.setConstant(std::numeric_limits<float>::infinity());
  }
  /// The control period: simulated seconds one Step() lasts, or 0 if the task has no clock (the
  /// Python module's step_seconds, and metadata['render_fps'] = 1 / control_period()). The
  /// experiment driver checks once that the shield looks ahead exactly this long (shield.dt:
  /// experiments::CheckExperimentOptions); every registered domain has one (> 0).
  virtual double control_period() const { return 0.0; }

  /// Whether Render() works (an offscreen renderer exists for this domain). False by default.
  virtual bool CanRender() const { return false; }
  /// Draws the current state (after Reset() or the last Step()) into `frame`, resized to
  /// width x height. Rendering must not change the episode (no random draws, no state change).
  /// Used by `secure render`; not called in Step()'s allocation-free loop.
  /// @throws secure::Error if the domain cannot render (the default) or the size is not positive.
  virtual void Render(int width, int height, Frame* frame) {
    (void)width;
    (void)height;
    (void)frame;
    SECURE_THROW("this environment cannot render (no offscreen renderer): " << Describe());
  }

  /// A fresh environment with the same options (for another thread).
  virtual std::unique_ptr<Environment> Clone() const = 0;
};

}  // namespace secure::domains
