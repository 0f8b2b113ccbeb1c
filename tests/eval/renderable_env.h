#pragma once
// A test environment that "renders" (render_test.cc, episode_table_test.cc).
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "secure/domains/environment.h"

namespace secure::test {

// The reach-avoid task with a "renderer": the frame's first bytes are the current observation's
// floats, the rest a constant; so a frame says which state it shows.
class RenderableEnv final : public domains::Environment {
 public:
  explicit RenderableEnv(std::unique_ptr<domains::Environment> inner)
      : inner_(std::move(inner)), observation_(inner_->observation_dim()) {}
  int observation_dim() const override { return inner_->observation_dim(); }
  int action_dim() const override { return inner_->action_dim(); }
  std::vector<std::string> ObservationFeatures() const override {
    return inner_->ObservationFeatures();
  }
  std::vector<std::string> ActionFeatures() const override { return inner_->ActionFeatures(); }
  int max_steps() const override { return inner_->max_steps(); }
  std::string Describe() const override { return "renderable " + inner_->Describe(); }
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    inner_->Reset(rng, observation);
    observation_ = observation;
  }
  domains::StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                            Eigen::Ref<Eigen::VectorXf> observation) override {
    const domains::StepOutcome outcome = inner_->Step(action, observation);
    observation_ = observation;
    return outcome;
  }
  const domains::DynamicsModel& ShieldModel() const override { return inner_->ShieldModel(); }
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low, Eigen::Ref<Eigen::VectorXf> high) const override {
    inner_->ActionBounds(low, high);
  }
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override {
    return inner_->BackupAction(observation, action);
  }
  std::unique_ptr<Environment> Clone() const override {
    return std::make_unique<RenderableEnv>(inner_->Clone());
  }
  bool CanRender() const override { return true; }
  void Render(int width, int height, domains::Frame* frame) override {
    frame->width = width;
    frame->height = height;
    frame->rgb.assign(3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height), 7);
    std::memcpy(frame->rgb.data(), observation_.data(), sizeof(float) * observation_.size());
  }

 private:
  std::unique_ptr<domains::Environment> inner_;
  Eigen::VectorXf observation_;
};

}  // namespace secure::test
