#include "domains/double_integrator/reach_avoid.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>
#include <type_traits>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/strings.h"
#include "secure/common/yaml_value.h"

namespace secure::domains::double_integrator {
namespace {

// Start states are drawn by rejection; give up after this many draws (the default square never
// rejects).
constexpr int kMaxStartDraws = 10000;


// A two-element list [a, b] of numbers.
void YamlPair(const YAML::Node& node, const std::string& key, const std::string& source, double* a,
              double* b) {
  SECURE_CHECK(node.IsSequence() && node.size() == 2, source << ": field '" << key
                                                             << "' has value '" << YAML::Dump(node)
                                                             << "', must be a list of two numbers");
  *a = YamlValue<double>(node[0], key, source);
  *b = YamlValue<double>(node[1], key, source);
}

}  // namespace

const std::vector<std::string>& ActionFeatures() {
  static const std::vector<std::string> names{"ax", "ay"};
  return names;
}

// ---------------------------------------------------------------------------------------------
void ReachAvoidOptions::Validate() const {
  const GroundTruth& t = truth;
  SECURE_CHECK_FIELD(std::isfinite(t.obstacle_x) && std::isfinite(t.obstacle_y),
                     "ReachAvoidOptions", "truth.obstacle",
                     "(" << t.obstacle_x << ", " << t.obstacle_y << ")", "finite");
  SECURE_CHECK_FIELD(std::isfinite(t.radius) && t.radius > 0, "ReachAvoidOptions", "truth.radius",
                     t.radius, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(t.gamma) && t.gamma > 0, "ReachAvoidOptions", "truth.gamma",
                     t.gamma, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(goal_x) && std::isfinite(goal_y), "ReachAvoidOptions", "goal",
                     "(" << goal_x << ", " << goal_y << ")", "finite");
  SECURE_CHECK_FIELD(std::isfinite(goal_radius) && goal_radius > 0, "ReachAvoidOptions",
                     "goal_radius", goal_radius, "> 0");
  const double goal_distance = std::hypot(goal_x - t.obstacle_x, goal_y - t.obstacle_y);
  SECURE_CHECK_FIELD(goal_distance >= t.radius + goal_radius, "ReachAvoidOptions", "goal",
                     "(" << goal_x << ", " << goal_y << ")",
                     "at least radius + goal_radius = " << t.radius + goal_radius
                                                        << " from the obstacle centre (is "
                                                        << goal_distance << ")");
  SECURE_CHECK_FIELD(std::isfinite(start_lo) && std::isfinite(start_hi) && start_lo < start_hi,
                     "ReachAvoidOptions", "start_lo, start_hi", start_lo << ", " << start_hi,
                     "finite with start_lo < start_hi");
  SECURE_CHECK_FIELD(std::isfinite(start_speed) && start_speed >= 0, "ReachAvoidOptions",
                     "start_speed", start_speed, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(start_clearance) && start_clearance >= 0, "ReachAvoidOptions",
                     "start_clearance", start_clearance, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(dt) && dt > 0, "ReachAvoidOptions", "dt", dt, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(accel_bound) && accel_bound > 0, "ReachAvoidOptions",
                     "accel_bound", accel_bound, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(brake_gain) && brake_gain >= 0, "ReachAvoidOptions",
                     "brake_gain", brake_gain, ">= 0");
  SECURE_CHECK_FIELD(max_steps > 0, "ReachAvoidOptions", "max_steps", max_steps, "> 0");
}

nlohmann::json ReachAvoidOptions::ToJson() const {
  return {{"obstacle", {truth.obstacle_x, truth.obstacle_y}},
          {"radius", truth.radius},
          {"gamma", truth.gamma},
          {"goal", {goal_x, goal_y}},
          {"goal_radius", goal_radius},
          {"start_region", {start_lo, start_hi}},
          {"start_speed", start_speed},
          {"start_clearance", start_clearance},
          {"dt", dt},
          {"accel_bound", accel_bound},
          {"brake_gain", brake_gain},
          {"max_steps", max_steps}};
}

void ReachAvoidOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  static const std::set<std::string> known = {
      "obstacle",    "radius", "gamma",       "goal",       "goal_radius", "start_region",
      "start_speed", "dt",     "accel_bound", "brake_gain", "max_steps",   "start_clearance"};
  const auto apply = [&](const std::string& key, const YAML::Node& v) {
    if (key == "obstacle") {
      YamlPair(v, key, source, &truth.obstacle_x, &truth.obstacle_y);
    } else if (key == "radius") {
      truth.radius = YamlValue<double>(v, key, source);
    } else if (key == "gamma") {
      truth.gamma = YamlValue<double>(v, key, source);
    } else if (key == "goal") {
      YamlPair(v, key, source, &goal_x, &goal_y);
    } else if (key == "goal_radius") {
      goal_radius = YamlValue<double>(v, key, source);
    } else if (key == "start_region") {
      YamlPair(v, key, source, &start_lo, &start_hi);
    } else if (key == "start_speed") {
      start_speed = YamlValue<double>(v, key, source);
    } else if (key == "start_clearance") {
      start_clearance = YamlValue<double>(v, key, source);
    } else if (key == "dt") {
      dt = YamlValue<double>(v, key, source);
    } else if (key == "accel_bound") {
      accel_bound = YamlValue<double>(v, key, source);
    } else if (key == "brake_gain") {
      brake_gain = YamlValue<double>(v, key, source);
    } else if (key == "max_steps") {
      max_steps = YamlValue<int>(v, key, source);
    }
  };
  ForEachYamlField(node, known, "reach-avoid task options", source, apply);
}

Eigen::Vector4f DrawStartState(const ReachAvoidOptions& o, Rng& rng) {
  const GroundTruth& t = o.truth;
  for (int draw = 0; draw < kMaxStartDraws; ++draw) {
    Eigen::Vector4f s;
    s[0] = static_cast<float>(rng.Uniform(o.start_lo, o.start_hi));
    s[1] = static_cast<float>(rng.Uniform(o.start_lo, o.start_hi));
    s[2] = static_cast<float>(rng.Uniform(-o.start_speed, o.start_speed));
    s[3] = static_cast<float>(rng.Uniform(-o.start_speed, o.start_speed));
    const double distance = std::hypot(s[0] - t.obstacle_x, s[1] - t.obstacle_y);
    if (distance >= t.radius + o.start_clearance && t.H(s[0], s[1], s[2], s[3]) >= 0.0) return s;
  }
  SECURE_THROW("ReachAvoidOptions: no start state in ["
               << o.start_lo << ", " << o.start_hi << ")^2 is " << o.start_clearance
               << " clear of the obstacle and safe (" << kMaxStartDraws << " draws)");
}

// ---------------------------------------------------------------------------------------------
ReachAvoidEnv::ReachAvoidEnv(const ReachAvoidOptions& options)
    : options_((options.Validate(), options)), model_(options.dt, options.accel_bound) {}

std::vector<std::string> ReachAvoidEnv::ActionFeatures() const {
  return double_integrator::ActionFeatures();
}

std::string ReachAvoidEnv::Describe() const {
  const ReachAvoidOptions& o = options_;
  std::ostringstream s;
  s << "double-integrator reach-avoid: start [" << o.start_lo << ", " << o.start_hi << ")^2, goal ("
    << o.goal_x << ", " << o.goal_y << ") radius " << o.goal_radius << ", obstacle ("
    << o.truth.obstacle_x << ", " << o.truth.obstacle_y << ") r " << o.truth.radius
    << ", |a_i| <= " << o.accel_bound << ", dt " << o.dt << ", " << o.max_steps << " steps";
  return s.str();
}

void ReachAvoidEnv::Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) {
  SECURE_CHECK(observation.size() == kStateDim, "ReachAvoidEnv::Reset: observation has "
                                                    << observation.size()
                                                    << " entries, expected 4");
  state_ = DrawStartState(options_, rng);
  in_obstacle_ = InObstacle(state_[0], state_[1]);
  started_ = true;
  observation = state_;
}

StepOutcome ReachAvoidEnv::Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                                Eigen::Ref<Eigen::VectorXf> observation) {
  SECURE_CHECK(started_, "ReachAvoidEnv::Step before Reset (no current state)");
  SECURE_CHECK(action.size() == kActionDim, "ReachAvoidEnv::Step: action has "
                                                << action.size()
                                                << " entries, expected 2 (ax, ay)");
  SECURE_CHECK(observation.size() == kStateDim, "ReachAvoidEnv::Step: observation has "
                                                    << observation.size()
                                                    << " entries, expected 4");
  for (int i = 0; i < kActionDim; ++i)
    SECURE_CHECK(std::isfinite(action[i]), "ReachAvoidEnv::Step: action component "
                                               << ActionFeatures()[static_cast<std::size_t>(i)]
                                               << " = " << action[i] << ", must be finite");
  model_.Step(state_, action, next_);  // clips, then the exact step
  state_ = next_;
  observation = state_;
  StepOutcome out;
  out.reached_goal = InGoal(state_[0], state_[1]);
  out.collided = InObstacle(state_[0], state_[1]);
  out.collisions = out.collided && !in_obstacle_ ? 1 : 0;  // entering (environment.h)
  in_obstacle_ = out.collided;
  return out;
}

bool ReachAvoidEnv::BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                                 Eigen::Ref<Eigen::VectorXf> action) const {
  SECURE_CHECK(observation.size() == kStateDim && action.size() == kActionDim,
               "ReachAvoidEnv::BackupAction: observation/action have "
                   << observation.size() << "/" << action.size() << " entries, expected 4/2");
  const double a_max = options_.accel_bound;
  for (int i = 0; i < kActionDim; ++i)
    action[i] = static_cast<float>(
        std::clamp(-options_.brake_gain * static_cast<double>(observation[2 + i]), -a_max, a_max));
  return true;
}

std::unique_ptr<Environment> ReachAvoidEnv::Clone() const {
  return std::make_unique<ReachAvoidEnv>(options_);
}

void ReachAvoidEnv::SetState(const Eigen::Ref<const Eigen::VectorXf>& state) {
  SECURE_CHECK(state.size() == kStateDim,
               "ReachAvoidEnv::SetState: state has " << state.size() << " entries, expected 4");
  for (int i = 0; i < kStateDim; ++i)
    SECURE_CHECK(std::isfinite(state[i]), "ReachAvoidEnv::SetState: state component "
                                              << StateFeatures()[static_cast<std::size_t>(i)]
                                              << " = " << state[i] << ", must be finite");
  state_ = state;
  in_obstacle_ = InObstacle(state_[0], state_[1]);
  started_ = true;
}

bool ReachAvoidEnv::InGoal(double x, double y) const {
  return std::hypot(x - options_.goal_x, y - options_.goal_y) < options_.goal_radius;
}

bool ReachAvoidEnv::InObstacle(double x, double y) const {
  return std::hypot(x - options_.truth.obstacle_x, y - options_.truth.obstacle_y) <
         options_.truth.radius;
}

}  // namespace secure::domains::double_integrator
