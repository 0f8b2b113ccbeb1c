#pragma once
// The part of the Franka plug-ins' Environment that does not depend on the task: the dimensions,
// the [-1, 1] action clip, the episode length and control period from the task options, Reset and
// Step around the plug-in's simulation (with the count of dangerous events, each counted once
// when it begins), and Render with domains/franka/'s offscreen renderer (made on the first call).
// A plug-in's environment derives from ArmEnvironment<its simulation, dims> and adds what is its
// own: the features, Describe, the shield model, the backup action, Clone, and what "reached" and
// "dangerous" mean (Reached, Dangerous). MuJoCo-free, so the plug-ins' public headers may include
// it.
#include <Eigen/Core>
#include <memory>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/domains/environment.h"

namespace secure::domains::franka {

class OffscreenRenderer;

/// Where the free camera looks from: {lookat, distance, azimuth, elevation}.
struct CameraView {
  double lookat[3];  // m
  double distance;   // m
  double azimuth;    // degrees
  double elevation;  // degrees
};

/// Renders the MuJoCo model and data (`model`, `data`: mjModel, mjData) seen from `view` into
/// `frame`, with *renderer, made on the first call (`who` names the plug-in in errors).
void RenderSimulation(std::unique_ptr<OffscreenRenderer>* renderer, const void* model, void* data,
                      const CameraView& view, const char* who, int width, int height, Frame* frame);

/// `Sim`: the plug-in's MuJoCo simulation: Sim(options), options() (with max_steps and
/// tracking.control_period), Reset(rng), Step(a fixed-size action), Observe(observation),
/// model() and data().
template <typename Sim, int kObservationDim, int kActionDim>
class ArmEnvironment : public Environment {
 public:
  int observation_dim() const override { return kObservationDim; }
  int action_dim() const override { return kActionDim; }
  int max_steps() const override { return sim_.options().max_steps; }
  double control_period() const override { return sim_.options().tracking.control_period; }
  /// [-1, 1] per component (the clip of Step()).
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low,
                    Eigen::Ref<Eigen::VectorXf> high) const override {
    low.setConstant(-1.0f);
    high.setConstant(1.0f);
  }

  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    CheckSize("observation", observation.size(), kObservationDim);
    sim_.Reset(rng);
    dangerous_ = false;
    sim_.Observe(observation);
  }
  /// One control period of the simulation; `collisions` counts a dangerous event when it begins.
  StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                   Eigen::Ref<Eigen::VectorXf> observation) override {
    CheckSize("action", action.size(), kActionDim);
    CheckSize("observation", observation.size(), kObservationDim);
    sim_.Step(Eigen::Matrix<float, kActionDim, 1>(action.template head<kActionDim>()));
    sim_.Observe(observation);
    StepOutcome outcome;
    outcome.reached_goal = Reached();
    outcome.collided = Dangerous();
    outcome.collisions = outcome.collided && !dangerous_ ? 1 : 0;
    dangerous_ = outcome.collided;
    return outcome;
  }

  /// domains/franka/'s offscreen renderer (OSMesa), created on the first call; frames up to
  /// 1280 x 720, seen from the plug-in's camera.
  bool CanRender() const override { return true; }
  void Render(int width, int height, Frame* frame) override {
    RenderSimulation(&renderer_, sim_.model(), sim_.data(), view_, who_, width, height, frame);
  }

  Sim& sim() { return sim_; }
  const Sim& sim() const { return sim_; }

 protected:
  /// `who`: the plug-in's name (a string literal), in errors.
  template <typename Options>
  ArmEnvironment(const Options& options, const char* who, const CameraView& view)
      : sim_(options), who_(who), view_(view) {}
  /// Defined where OffscreenRenderer is complete (the plug-in's source, by its destructor).
  ~ArmEnvironment() override = default;

  /// The task's goal reached in the simulation's present state.
  virtual bool Reached() const = 0;
  /// The plug-in's dangerous event in the simulation's present state.
  virtual bool Dangerous() const = 0;

  Sim sim_;

 private:
  void CheckSize(const char* what, Eigen::Index size, int expected) const {
    SECURE_CHECK(size == expected,
                 who_ << ": " << what << " has " << size << " entries, expected " << expected);
  }

  const char* who_;
  CameraView view_;
  bool dangerous_ = false;
  std::unique_ptr<OffscreenRenderer> renderer_;  // made by the first Render
};

}  // namespace secure::domains::franka
