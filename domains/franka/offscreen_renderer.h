#pragma once
// Offscreen frames of a MuJoCo simulation with MuJoCo's renderer in an OSMesa context (software
// OpenGL: no display, no GPU), shared by the Franka plug-ins (their Environment::Render).
// Internal to the plug-ins' sources: it includes MuJoCo's headers.
#include <mujoco/mujoco.h>

#include <memory>
#include <string>

#include "domains/franka/arm_environment.h"  // CameraView
#include "secure/domains/environment.h"

namespace secure::domains::franka {

constexpr int kMaxRenderWidth = 1280, kMaxRenderHeight = 720;

/// One OSMesa context and MuJoCo render context for one model; frames up to kMaxRenderWidth x
/// kMaxRenderHeight (the model's offscreen buffer must be at least that). Not thread-safe; one
/// per environment. `who` names the plug-in in messages.
class OffscreenRenderer {
 public:
  OffscreenRenderer(const mjModel* model, const CameraView& view, const std::string& who);
  ~OffscreenRenderer();
  OffscreenRenderer(const OffscreenRenderer&) = delete;
  OffscreenRenderer& operator=(const OffscreenRenderer&) = delete;

  /// The state in `data` (of the model given at construction), without changing it.
  /// @throws secure::Error on a size outside [2, max] or an OpenGL failure.
  void Render(const mjModel* model, mjData* data, int width, int height, Frame* frame);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace secure::domains::franka
