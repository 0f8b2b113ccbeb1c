#pragma once
// The example plug-in (examples/toy_domain/, outside domains/): the proof that a domain is one
// folder. It plugs into the generic experiments through experiments::Domain alone (it includes
// only secure/... headers, never domains/...), registers through secure_add_domain like the
// built-ins, and is added to the build by one add_subdirectory line (the top-level
// CMakeLists.txt). See docs/ADDING_A_DOMAIN.md and README.md here.
//
// The task, "toy-cart": a cart on a rail must stop in front of a wall.
//  - state = observation = (x, v); action = (a), clipped to [-accel_bound, accel_bound] [2];
//  - exact zero-order-hold step, dt [0.1]: x' = x + v dt + a dt^2 / 2, v' = v + a dt
//    (ToyCartModel; the environment steps with the same function, so the shield model is exact);
//  - start x ~ U[0, 1), v ~ U[0, 0.2);
//  - goal: goal_lo [3.4] <= x < wall and |v| < goal_speed [0.3] (park in front of the wall);
//  - collision (dangerous): x >= wall [4];
//  - max_steps [60] (the expert parks after ~30);
//  - backup action: braking, a = clip(-v / dt);
//  - expert: follows the braking curve v_des = sqrt(2 brake_fraction accel_bound (target - x)),
//    capped at max_speed [2.5], to target [3.75]; brake_fraction [0.7] is tempting: it approaches
//    fast and brakes late, so an imprecise imitation overshoots into the wall;
//  - ground truth (continuous braking at the bound stops before the wall):
//    h(x, v) = wall - x - max(v, 0)^2 / (2 accel_bound);
//  - near-dangerous states: x in [wall - 1.5, wall + 0.1), v above the stopping speed
//    sqrt(2 accel_bound max(wall - x, 0)) by U[0, 1) (h < 0, up to ~1 m from the boundary).
//
//  - barrier check: the region is the safe and near-dangerous states perturbed (sd 0.05), the
//    unsafe test the ground truth h < 0.
//
// Registration: secure::plugins::Register_toy_cart (toy_cart.cc), called by the generated
// secure::plugins::RegisterBuiltinDomains like every plug-in's.
#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::examples::toy_cart {

struct ToyCartOptions {
  double dt = 0.1;
  double accel_bound = 2.0;
  double wall = 4.0;
  double goal_lo = 3.4;
  double goal_speed = 0.3;
  int max_steps = 60;
  // The expert.
  double target = 3.75;
  double max_speed = 2.5;
  double brake_fraction = 0.7;
  double expert_gain = 5.0;   // a = gain (v_des - v), clipped
  double expert_noise = 0.3;  // N(0, noise^2) added to the expert's action in demonstrations
  // The data.
  long demonstrations = 40;    // expert episodes (full horizon: it parks, then holds)
  long safe_states = 1000;     // demonstration states used as the safe class (at random)
  long near_dangerous = 1000;  // near-dangerous states

  void Validate() const;
  nlohmann::json ToJson() const;
};

/// The exact clipped step, shared by the environment and the shield.
class ToyCartModel final : public domains::DynamicsModel {
 public:
  ToyCartModel(double dt, double accel_bound) : dt_(float(dt)), bound_(float(accel_bound)) {}
  int state_dim() const override { return 2; }
  int action_dim() const override { return 1; }
  std::string Describe() const override { return "toy cart (exact)"; }
  /// One state, one action; no allocation.
  void StepOne(float x, float v, float a, float* x_next, float* v_next) const;

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  float dt_, bound_;
};

class ToyCartEnv final : public domains::Environment {
 public:
  explicit ToyCartEnv(const ToyCartOptions& options = {});
  int observation_dim() const override { return 2; }
  int action_dim() const override { return 1; }
  std::vector<std::string> ObservationFeatures() const override { return {"x", "v"}; }
  std::vector<std::string> ActionFeatures() const override { return {"a"}; }
  int max_steps() const override { return options_.max_steps; }
  std::string Describe() const override;
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override;
  domains::StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                            Eigen::Ref<Eigen::VectorXf> observation) override;
  const domains::DynamicsModel& ShieldModel() const override { return model_; }
  bool ShieldModelIsExact() const override { return true; }
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override;
  std::unique_ptr<domains::Environment> Clone() const override;
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low,
                    Eigen::Ref<Eigen::VectorXf> high) const override {
    low.setConstant(-static_cast<float>(options_.accel_bound));
    high.setConstant(static_cast<float>(options_.accel_bound));
  }
  double control_period() const override { return options_.dt; }

 private:
  ToyCartOptions options_;
  ToyCartModel model_;
  float x_ = 0.0f, v_ = 0.0f;
  bool at_wall_ = false;  // the current state is at or past the wall (StepOutcome.collisions)
  bool started_ = false;
};

/// The expert's action (without noise) at (x, v).
float ToyCartExpert(const ToyCartOptions& o, float x, float v);

/// h(x, v) = wall - x - max(v, 0)^2 / (2 accel_bound).
class ToyCartGroundTruth final : public cbf::Barrier {
 public:
  explicit ToyCartGroundTruth(const ToyCartOptions& o) : o_(o) {}
  int state_dim() const override { return 2; }
  std::string Describe() const override { return "toy cart ground truth"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override;

 private:
  ToyCartOptions o_;
};

class ToyCartDomain final : public experiments::Domain {
 public:
  explicit ToyCartDomain(experiments::Profile profile = experiments::Profile::kFull);
  std::string name() const override { return "toy-cart"; }
  std::string Describe() const override;
  std::string Title() const override { return "the toy cart (an example plug-in)"; }
  std::string ConfigSection() const override { return "toy_cart"; }
  /// Keys: demonstrations, safe_states, near_dangerous (counts), task (dt, accel_bound, wall,
  /// goal_lo, goal_speed, max_steps), and the expert's target, max_speed, brake_fraction,
  /// expert_gain, expert_noise: every key OptionsJson writes, so that it reads back.
  void ApplyYaml(const YAML::Node& node, const std::string& source) override;
  void Validate() const override { options_.Validate(); }
  nlohmann::json OptionsJson() const override { return options_.ToJson(); }
  std::unique_ptr<domains::Environment> MakeEnvironment() const override;
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override;
  experiments::ExperimentOptions Preset() const override;
  std::unique_ptr<cbf::Barrier> MakeGroundTruth() const override;
  std::optional<cbf::StateSource> ValidationGrid() const override;
  /// Uniform in the grid's box (x in [0, wall + 0.5), v in [-1, 3)), labelled by the ground truth.
  experiments::GroundTruthSample SampleGroundTruth(long n_safe, long n_unsafe,
                                                   std::uint64_t seed) const override;
  /// The barrier check (check.cc): held-out states from GenerateData's generators on another
  /// stream; the exact model; the region around the labelled states; the ground truth as the
  /// unsafe test.
  bool HasCheck() const override { return true; }
  void CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                    data::StateSet* near_dangerous) const override;
  cbf::BarrierCheckProblem MakeCheckProblem(
      const shield::ShieldOptions& shield, const data::StateSet& safe,
      const data::StateSet& near_dangerous,
      std::unique_ptr<domains::DynamicsModel>* dynamics) const override;

  /// The report's pictures: the barrier over (x, v) with the wall, the episodes in (x, v).
  std::optional<experiments::ReportHints> MakeReportHints() const override;

  ToyCartOptions& mutable_options() { return options_; }

 private:
  void ApplyTaskYaml(const YAML::Node& node, const std::string& source);

  experiments::Profile profile_;
  ToyCartOptions options_;
};

}  // namespace secure::examples::toy_cart
