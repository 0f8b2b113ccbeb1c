#pragma once
// One evaluation episode, rendered (`secure render`): the episode `secure eval` plays for a
// method, seed and episode index, with a frame of the environment after Reset() and after every
// step.
#include <cstdint>
#include <functional>
#include <optional>

#include "secure/domains/environment.h"
#include "secure/eval/policy_eval.h"

namespace secure::eval {

/// What happened in the rendered episode.
struct RenderedEpisode {
  long frames = 0;  // steps + 1 (the start, then one per step)
  long steps = 0;
  bool success = false;    // reached the goal
  bool dangerous = false;  // at least one collision
  long collision_events = 0;
};

/// What one frame shows, for an overlay (eval::EpisodeOverlay).
struct FrameInfo {
  long step = 0;            // 0: the start state; k: the state after the k-th step
  std::optional<double> h;  // h(s) of the state shown: the method's barrier (SeedModels::
                            // make_barrier), for unshielded methods too; none without a barrier
  const shield::Decision* decision = nullptr;  // the shield's decision for the step that led
                                               // here; null at the start and unshielded
  bool collided = false;      // the step's outcome
  bool reached_goal = false;
};

/// Plays episode `episode` (0-based) of `method` exactly as EvaluateMethods(env, {method}, models,
/// shield_options, N, seed) plays it for any N > episode (the same start state, policy noise and
/// shield samples: the episode's own stream, RunMethod with EpisodeRunnerOptions::first_episode)
/// in `env`, and calls `on_frame` with env.Render(width, height) after Reset() and after every
/// step. `seed` is the evaluation seed (EvaluationSeed(training seed) for `secure eval`'s).
/// @throws secure::Error if the environment cannot render (naming it), a model is missing, or
/// on_frame throws.
RenderedEpisode RenderEpisode(domains::Environment& env, Method method, const SeedModels& models,
                              const shield::ShieldOptions& shield_options, std::uint64_t seed,
                              long episode, int width, int height,
                              const std::function<void(const domains::Frame&)>& on_frame);

/// The same, with what each frame shows; `on_frame` may draw into the frame (an overlay).
RenderedEpisode RenderEpisode(domains::Environment& env, Method method, const SeedModels& models,
                              const shield::ShieldOptions& shield_options, std::uint64_t seed,
                              long episode, int width, int height,
                              const std::function<void(domains::Frame&, const FrameInfo&)>& on_frame);

}  // namespace secure::eval
