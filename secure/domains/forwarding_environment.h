#pragma once
// An Environment that forwards every call to a wrapped one: the base of wrappers that change a
// few calls and keep the rest (dynamics::LearnedModelEnvironment swaps the shield model; tests
// record or render the episodes they see). A subclass overrides what it changes and Clone().
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "secure/domains/environment.h"

namespace secure::domains {

class ForwardingEnvironment : public Environment {
 public:
  /// `inner` may not be null (a subclass checks it, naming itself).
  explicit ForwardingEnvironment(std::unique_ptr<Environment> inner) : inner_(std::move(inner)) {}

  int observation_dim() const override { return inner_->observation_dim(); }
  int action_dim() const override { return inner_->action_dim(); }
  std::vector<std::string> ObservationFeatures() const override {
    return inner_->ObservationFeatures();
  }
  std::vector<std::string> ActionFeatures() const override { return inner_->ActionFeatures(); }
  int max_steps() const override { return inner_->max_steps(); }
  std::string Describe() const override { return inner_->Describe(); }
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    inner_->Reset(rng, observation);
  }
  StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                   Eigen::Ref<Eigen::VectorXf> observation) override {
    return inner_->Step(action, observation);
  }
  const DynamicsModel& ShieldModel() const override { return inner_->ShieldModel(); }
  bool ShieldModelIsExact() const override { return inner_->ShieldModelIsExact(); }
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override {
    return inner_->BackupAction(observation, action);
  }
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low,
                    Eigen::Ref<Eigen::VectorXf> high) const override {
    inner_->ActionBounds(low, high);
  }
  double control_period() const override { return inner_->control_period(); }
  bool CanRender() const override { return inner_->CanRender(); }
  void Render(int width, int height, Frame* frame) override {
    inner_->Render(width, height, frame);
  }

  Environment& inner() { return *inner_; }
  const Environment& inner() const { return *inner_; }

 protected:
  std::unique_ptr<Environment> inner_;
};

}  // namespace secure::domains
