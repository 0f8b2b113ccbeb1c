#pragma once
// Offscreen rendering of the panda-push simulation with MuJoCo's renderer in an OSMesa context
// (software OpenGL: no display, no GPU). Internal to the plug-in (PandaPushEnv::Render).
#include <memory>

#include "secure/domains/environment.h"

namespace secure::domains::panda_push {

class PandaPushSim;

/// One OSMesa context and MuJoCo render context for one simulation; frames up to
/// kMaxRenderWidth x kMaxRenderHeight (the model's offscreen buffer). Not thread-safe; one per
/// environment.
class PandaPushRenderer {
 public:
  explicit PandaPushRenderer(const PandaPushSim& sim);
  ~PandaPushRenderer();
  PandaPushRenderer(const PandaPushRenderer&) = delete;
  PandaPushRenderer& operator=(const PandaPushRenderer&) = delete;

  /// The current state of the simulation, seen from the side (the arm at the left, the target at
  /// the right). @throws secure::Error on a size outside [2, max] or an OpenGL failure.
  void Render(int width, int height, Frame* frame);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

constexpr int kMaxRenderWidth = 1280, kMaxRenderHeight = 720;

}  // namespace secure::domains::panda_push
