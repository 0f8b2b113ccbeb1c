#pragma once
// What the shield did, drawn into an episode's frames (`secure render`, Python's secure.Overlay):
// a band at the top with the method, the step, h(s) of the state shown and the shield's status
// for the action that led there; a red border on a step where the shield intervened (the
// policy's own draw had g < 0) and a brighter one where no safe action was found; and a panel at
// the bottom plotting h over the episode so far, with h = 0 dashed, interventions as orange ticks
// and collisions as red dots. A person watching a shielded episode sees when the shield acted
// and how close the state came to the boundary.
//
//   eval::EpisodeOverlay overlay({.title = "SECURE, seed 0, episode 3", .max_steps = 150});
//   for (...) { overlay.Draw(step_info, frame); video.Write(frame); }
//
// Drawn with Cairo (Debian libcairo2-dev; text in DejaVu Sans Mono, fonts-dejavu-core, found
// through fontconfig): the same frames and steps give the same pixels on one machine. The frame
// keeps its size; the panel covers the bottom of the picture, semi-transparent.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "secure/domains/environment.h"

namespace secure::eval {

struct OverlayOptions {
  std::string title;      // first words of the top band, e.g. "SECURE, seed 0, episode 3"
  int max_steps = 0;      // the panel's time axis spans [0, max(max_steps, steps so far)]
  bool panel = true;      // the plot of h over time at the bottom
  /// @throws secure::Error naming the field and value.
  void Validate() const;
};

/// One frame's facts: the state shown and the decision that led to it.
struct OverlayStep {
  long step = 0;              // 0: the start state; k: the state after the k-th step
  std::optional<double> h;    // h(s) of the state shown (a method with a barrier)
  std::string status;         // the shield's status for the last action; empty: unshielded
  bool intervened = false;    // the shield replaced the policy's own draw (g < 0)
  bool collided = false;      // the state shown is dangerous
  bool reached_goal = false;  // the state shown is in the goal region
};

class EpisodeOverlay {
 public:
  /// @throws secure::Error if `options` are invalid.
  explicit EpisodeOverlay(OverlayOptions options = {});

  /// Draws `step` into `frame` (3 * width * height RGB bytes) and remembers it for the panel.
  /// Steps are drawn in order; a step <= the last one drawn starts a new episode (the history is
  /// cleared). @throws secure::Error if the frame is inconsistent or smaller than 64 x 48, or h
  /// is not finite.
  void Draw(const OverlayStep& step, domains::Frame& frame);
  /// Forgets the history (a new episode).
  void Reset() { history_.clear(); }

  const OverlayOptions& options() const { return options_; }

 private:
  struct Point {
    long step;
    std::optional<double> h;
    bool intervened, collided;
  };
  OverlayOptions options_;
  std::vector<Point> history_;
  std::vector<std::uint32_t> pixels_;  // Cairo's RGB24 (xRGB) copy of the frame
};

}  // namespace secure::eval
