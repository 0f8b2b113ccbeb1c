#include "examples/toy_domain/toy_cart.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_value.h"

namespace secure::examples::toy_cart {

void ToyCartOptions::Validate() const {
  SECURE_CHECK_FIELD(dt > 0 && dt <= 1, "ToyCartOptions", "dt", dt, "in (0, 1]");
  SECURE_CHECK_FIELD(accel_bound > 0, "ToyCartOptions", "accel_bound", accel_bound, "> 0");
  SECURE_CHECK_FIELD(goal_lo < wall, "ToyCartOptions", "goal_lo", goal_lo, "< wall = " << wall);
  SECURE_CHECK_FIELD(goal_speed > 0, "ToyCartOptions", "goal_speed", goal_speed, "> 0");
  SECURE_CHECK_FIELD(max_steps > 0 && max_steps <= 100000, "ToyCartOptions", "max_steps", max_steps,
                     "in [1, 100000]");
  SECURE_CHECK_FIELD(target >= goal_lo && target < wall, "ToyCartOptions", "target", target,
                     "in [goal_lo, wall)");
  SECURE_CHECK_FIELD(max_speed > 0, "ToyCartOptions", "max_speed", max_speed, "> 0");
  SECURE_CHECK_FIELD(brake_fraction > 0 && brake_fraction <= 1, "ToyCartOptions", "brake_fraction",
                     brake_fraction, "in (0, 1]");
  SECURE_CHECK_FIELD(expert_gain > 0, "ToyCartOptions", "expert_gain", expert_gain, "> 0");
  SECURE_CHECK_FIELD(expert_noise >= 0, "ToyCartOptions", "expert_noise", expert_noise, ">= 0");
  SECURE_CHECK_FIELD(demonstrations > 0 && demonstrations <= 100000, "ToyCartOptions",
                     "demonstrations", demonstrations, "in [1, 100000]");
  SECURE_CHECK_FIELD(safe_states > 0 && safe_states <= kMaxStates, "ToyCartOptions", "safe_states",
                     safe_states, "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(near_dangerous > 0 && near_dangerous <= kMaxStates, "ToyCartOptions",
                     "near_dangerous", near_dangerous, "in [1, " << kMaxStates << "]");
}

nlohmann::json ToyCartOptions::ToJson() const {
  return {{"task",
           {{"dt", dt},
            {"accel_bound", accel_bound},
            {"wall", wall},
            {"goal_lo", goal_lo},
            {"goal_speed", goal_speed},
            {"max_steps", max_steps}}},
          {"target", target},
          {"max_speed", max_speed},
          {"brake_fraction", brake_fraction},
          {"expert_gain", expert_gain},
          {"expert_noise", expert_noise},
          {"demonstrations", demonstrations},
          {"safe_states", safe_states},
          {"near_dangerous", near_dangerous}};
}

// ---------------------------------------------------------------------------------------------
void ToyCartModel::StepOne(float x, float v, float a, float* x_next, float* v_next) const {
  a = std::clamp(a, -bound_, bound_);
  *x_next = x + v * dt_ + 0.5f * a * dt_ * dt_;
  *v_next = v + a * dt_;
}

void ToyCartModel::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                          const Eigen::Ref<const Eigen::MatrixXf>& actions,
                          Eigen::Ref<Eigen::MatrixXf> next_states) const {
  for (Eigen::Index i = 0; i < actions.cols(); ++i)
    StepOne(state[0], state[1], actions(0, i), &next_states(0, i), &next_states(1, i));
}

// ---------------------------------------------------------------------------------------------
ToyCartEnv::ToyCartEnv(const ToyCartOptions& options)
    : options_(options), model_(options.dt, options.accel_bound) {
  options_.Validate();
}

std::string ToyCartEnv::Describe() const {
  std::ostringstream s;
  s << "toy cart: stop in [" << options_.goal_lo << ", " << options_.wall << ") with |v| < "
    << options_.goal_speed << ", wall at " << options_.wall << ", |a| <= " << options_.accel_bound
    << ", dt " << options_.dt << ", " << options_.max_steps << " steps";
  return s.str();
}

void ToyCartEnv::Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) {
  SECURE_CHECK(observation.size() == 2, "ToyCartEnv::Reset: observation has "
                                            << observation.size() << " entries, expected 2");
  x_ = static_cast<float>(rng.Uniform(0.0, 1.0));
  v_ = static_cast<float>(rng.Uniform(0.0, 0.2));
  at_wall_ = x_ >= options_.wall;
  started_ = true;
  observation << x_, v_;
}

domains::StepOutcome ToyCartEnv::Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                                      Eigen::Ref<Eigen::VectorXf> observation) {
  SECURE_CHECK(started_, "ToyCartEnv::Step before Reset");
  SECURE_CHECK(action.size() == 1,
               "ToyCartEnv::Step: action has " << action.size() << " entries, expected 1 (a)");
  SECURE_CHECK(observation.size() == 2, "ToyCartEnv::Step: observation has "
                                            << observation.size() << " entries, expected 2");
  SECURE_CHECK(std::isfinite(action[0]),
               "ToyCartEnv::Step: action component a = " << action[0] << ", must be finite");
  model_.StepOne(x_, v_, action[0], &x_, &v_);
  observation << x_, v_;
  domains::StepOutcome out;
  out.collided = x_ >= options_.wall;
  out.collisions = out.collided && !at_wall_ ? 1 : 0;  // entering (environment.h)
  at_wall_ = out.collided;
  out.reached_goal = !out.collided && x_ >= options_.goal_lo && std::abs(v_) < options_.goal_speed;
  return out;
}

bool ToyCartEnv::BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                              Eigen::Ref<Eigen::VectorXf> action) const {
  SECURE_CHECK(observation.size() == 2 && action.size() == 1,
               "ToyCartEnv::BackupAction: observation/action have "
                   << observation.size() << "/" << action.size() << " entries, expected 2/1");
  const float bound = static_cast<float>(options_.accel_bound);
  action[0] = std::clamp(-observation[1] / static_cast<float>(options_.dt), -bound, bound);
  return true;
}

std::unique_ptr<domains::Environment> ToyCartEnv::Clone() const {
  return std::make_unique<ToyCartEnv>(options_);
}

float ToyCartExpert(const ToyCartOptions& o, float x, float v) {
  const double gap = o.target - x;
  const double brake = o.brake_fraction * o.accel_bound;
  const double v_des =
      std::copysign(std::min(o.max_speed, std::sqrt(2.0 * brake * std::abs(gap))), gap);
  return static_cast<float>(std::clamp(o.expert_gain * (v_des - v), -o.accel_bound, o.accel_bound));
}

void ToyCartGroundTruth::DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                    Eigen::Ref<Eigen::VectorXf> h) {
  for (Eigen::Index i = 0; i < states.cols(); ++i) {
    const double x = states(0, i), v = std::max(0.0f, states(1, i));
    h[i] = static_cast<float>(o_.wall - x - v * v / (2.0 * o_.accel_bound));
  }
}

// ---------------------------------------------------------------------------------------------
ToyCartDomain::ToyCartDomain(experiments::Profile profile) : profile_(profile) {
  if (profile == experiments::Profile::kQuick) {
    options_.demonstrations = 30;
    options_.safe_states = 600;
    options_.near_dangerous = 600;
  }
}

std::string ToyCartDomain::Describe() const { return ToyCartEnv(options_).Describe(); }

void ToyCartDomain::ApplyYaml(const YAML::Node& node, const std::string& source) {
  SECURE_CHECK(node.IsMap(), source << ": the toy-cart domain options must be a mapping");
  for (const auto& entry : node) {
    const std::string key = YamlKey(entry.first, source);
    if (key == "demonstrations") {
      options_.demonstrations = YamlValue<long>(entry.second, key, source);
    } else if (key == "safe_states") {
      options_.safe_states = YamlValue<long>(entry.second, key, source);
    } else if (key == "near_dangerous") {
      options_.near_dangerous = YamlValue<long>(entry.second, key, source);
    } else if (key == "task") {
      ApplyTaskYaml(entry.second, source + " [task]");
    } else if (key == "target") {  // the expert's (ToJson writes every key read here)
      options_.target = YamlValue<double>(entry.second, key, source);
    } else if (key == "max_speed") {
      options_.max_speed = YamlValue<double>(entry.second, key, source);
    } else if (key == "brake_fraction") {
      options_.brake_fraction = YamlValue<double>(entry.second, key, source);
    } else if (key == "expert_gain") {
      options_.expert_gain = YamlValue<double>(entry.second, key, source);
    } else if (key == "expert_noise") {
      options_.expert_noise = YamlValue<double>(entry.second, key, source);
    } else {
      SECURE_THROW(source << ": unknown key '" << key
                          << "' (valid: demonstrations, safe_states, near_dangerous, task, target, "
                             "max_speed, brake_fraction, expert_gain, expert_noise)");
    }
  }
}

// The task's keys (`task:`): the cart, the wall and the goal.
void ToyCartDomain::ApplyTaskYaml(const YAML::Node& node, const std::string& source) {
  SECURE_CHECK(node.IsMap(), source << ": the toy-cart task options must be a mapping");
  ToyCartOptions& o = options_;
  for (const auto& entry : node) {
    const std::string key = YamlKey(entry.first, source);
    if (key == "dt") {
      o.dt = YamlValue<double>(entry.second, key, source);
    } else if (key == "accel_bound") {
      o.accel_bound = YamlValue<double>(entry.second, key, source);
    } else if (key == "wall") {
      o.wall = YamlValue<double>(entry.second, key, source);
    } else if (key == "goal_lo") {
      o.goal_lo = YamlValue<double>(entry.second, key, source);
    } else if (key == "goal_speed") {
      o.goal_speed = YamlValue<double>(entry.second, key, source);
    } else if (key == "max_steps") {
      o.max_steps = YamlValue<int>(entry.second, key, source);
    } else {
      SECURE_THROW(source << ": unknown key '" << key
                          << "' (valid: dt, accel_bound, wall, goal_lo, goal_speed, max_steps)");
    }
  }
}

std::unique_ptr<domains::Environment> ToyCartDomain::MakeEnvironment() const {
  return std::make_unique<ToyCartEnv>(options_);
}

experiments::DomainData ToyCartDomain::GenerateData(std::uint64_t data_seed) const {
  options_.Validate();
  const ToyCartOptions& o = options_;
  ToyCartEnv env(o);
  const int horizon = o.max_steps;
  experiments::DomainData d;
  data::TrajectorySet& demos = d.demonstrations;
  demos.source = "toy-cart expert (data_seed " + std::to_string(data_seed) + ")";
  demos.state_features = env.ObservationFeatures();
  demos.action_features = env.ActionFeatures();
  demos.states.resize(2, o.demonstrations * horizon);
  demos.actions.resize(1, o.demonstrations * horizon);
  Rng rng(data_seed);
  Eigen::VectorXf obs(2), next(2), a(1);
  long c = 0;
  // Full-horizon episodes (the expert parks, then holds in front of the wall); an episode that
  // touched the wall is dropped (at most 10 x the requested number are drawn).
  for (long attempt = 0; demos.num_episodes() < o.demonstrations; ++attempt) {
    SECURE_CHECK(attempt < 10 * o.demonstrations, "toy-cart: too many expert episodes collided ("
                                                      << d.discarded_demonstrations << ")");
    const long begin = c;
    env.Reset(rng, obs);
    bool collided = false;
    for (int t = 0; t < horizon; ++t, ++c) {
      a[0] = ToyCartExpert(o, obs[0], obs[1]) + static_cast<float>(o.expert_noise * rng.Normal());
      demos.states.col(c) = obs;
      demos.actions.col(c) = a;
      collided |= env.Step(a, next).collided;
      obs = next;
    }
    if (collided) {
      c = begin;
      ++d.discarded_demonstrations;
      continue;
    }
    if (demos.episode_begin.empty()) demos.episode_begin.push_back(0);
    demos.episode_begin.push_back(c);
  }

  Rng data_rng(data_seed + 1);
  // Safe: demonstration states at random (with replacement if there are fewer).
  d.safe.source = "toy-cart safe states (demonstrations)";
  d.safe.features = env.ObservationFeatures();
  d.safe.states.resize(2, o.safe_states);
  for (long i = 0; i < o.safe_states; ++i)
    d.safe.states.col(i) =
        demos.states.col(static_cast<long>(data_rng.UniformIndex(std::uint64_t(c))));
  // Near-dangerous: past the stopping curve, up to ~1 m of position or speed from it.
  d.near_dangerous.source = "toy-cart near-dangerous states";
  d.near_dangerous.features = env.ObservationFeatures();
  d.near_dangerous.states.resize(2, o.near_dangerous);
  for (long i = 0; i < o.near_dangerous; ++i) {
    const double x = data_rng.Uniform(o.wall - 1.5, o.wall + 0.1);
    const double v_stop = std::sqrt(2.0 * o.accel_bound * std::max(0.0, o.wall - x));
    d.near_dangerous.states(0, i) = static_cast<float>(x);
    d.near_dangerous.states(1, i) = static_cast<float>(v_stop + data_rng.Uniform(0.0, 1.0));
  }
  return d;
}

experiments::ExperimentOptions ToyCartDomain::Preset() const {
  experiments::ExperimentOptions p;
  p.data_seed = 3000;
  p.barrier_kind = experiments::BarrierKind::kFlat;
  p.flat_barrier.hidden = {32, 32};
  p.flat_barrier.max_epochs = 100;
  p.bc.hidden = {32, 32};
  p.bc.epochs = 40;
  p.airl.iterations = 10;
  p.airl.steps_per_iteration = 1200;  // 20 episodes of 60 steps
  p.shield.dt = options_.dt;
  // The experiments do not run the barrier check (`secure cbf check --domain toy-cart` does):
  // the toy's results stay those of the example as first tuned.
  p.check_enabled = false;
  if (profile_ == experiments::Profile::kQuick) {
    p.seeds = 2;
    p.episodes = 40;
    p.flat_barrier.max_epochs = 60;
    p.bc.epochs = 30;
    p.airl.iterations = 4;
  }
  return p;
}

std::unique_ptr<cbf::Barrier> ToyCartDomain::MakeGroundTruth() const {
  return std::make_unique<ToyCartGroundTruth>(options_);
}

std::optional<cbf::StateSource> ToyCartDomain::ValidationGrid() const {
  // 41 x 41 states: x in [0, wall + 0.5], v in [-1, 3].
  constexpr int kN = 41;
  const double x_hi = options_.wall + 0.5;
  cbf::StateSource s;
  s.state_dim = 2;
  s.size = long(kN) * kN;
  s.fill = [x_hi](long first, long n, Eigen::Ref<Eigen::MatrixXf> out) {
    for (long k = 0; k < n; ++k) {
      const long i = (first + k) / kN, j = (first + k) % kN;
      out(0, k) = static_cast<float>(x_hi * double(i) / (kN - 1));
      out(1, k) = static_cast<float>(-1.0 + 4.0 * double(j) / (kN - 1));
    }
  };
  return s;
}

experiments::GroundTruthSample ToyCartDomain::SampleGroundTruth(long n_safe, long n_unsafe,
                                                                std::uint64_t seed) const {
  SECURE_CHECK(n_safe > 0 && n_unsafe > 0,
               "toy-cart sampler: counts " << n_safe << ", " << n_unsafe << ", must be > 0");
  Rng rng(seed ^ 0x70c7'0000'0000'0000ULL);  // not the trainer's stream for the same seed
  ToyCartGroundTruth truth(options_);
  Eigen::MatrixXf safe(2, n_safe), unsafe(2, n_unsafe);
  long s = 0, u = 0;
  Eigen::VectorXf h(1);
  for (long draw = 0; s < n_safe || u < n_unsafe; ++draw) {
    SECURE_CHECK(draw < 1000 * (n_safe + n_unsafe), "toy-cart sampler: too few states of a class");
    Eigen::Vector2f x(float(rng.Uniform(0.0, options_.wall + 0.5)), float(rng.Uniform(-1.0, 3.0)));
    truth.Evaluate(x, h);
    if (h[0] >= 0 && s < n_safe) safe.col(s++) = x;
    if (h[0] < 0 && u < n_unsafe) unsafe.col(u++) = x;
  }
  const std::string source = "toy-cart sampler (seed " + std::to_string(seed) + ")";
  return {{source + " safe", {"x", "v"}, std::move(safe)},
          {source + " unsafe", {"x", "v"}, std::move(unsafe)}};
}

std::optional<experiments::ReportHints> ToyCartDomain::MakeReportHints() const {
  const double wall = options_.wall;
  const nlohmann::json beyond_wall = {{"kind", "rectangle"}, {"corner", {wall, -1.0}},
                                      {"size", {0.5, 4.0}}, {"color", "gray"}, {"alpha", 0.3}};
  experiments::ReportHints h;
  h.barrier = {{"x", {{"feature", "x"}, {"range", {0.0, wall + 0.5}}}},
               {"y", {{"feature", "v"}, {"range", {-1.0, 3.0}}}},
               {"shapes", {beyond_wall}},
               {"caption", "The toy cart's barrier of <code>{model}</code>; gray: the wall."}};
  h.trajectories = {{"layout", "overlay"},
                    {"position", {{"x", "x"}, {"y", "v"}}},
                    {"labels", {"x", "v"}},
                    {"shapes", {beyond_wall}},
                    {"caption", "Episodes in (x, v) ({shield_note})."}};
  return h;
}

}  // namespace secure::examples::toy_cart

namespace secure::plugins {
// The plug-in's registration (secure_add_domain(toy_cart ...): Register_<name>).
void Register_toy_cart(experiments::DomainRegistry& registry) {
  registry.Add<examples::toy_cart::ToyCartDomain>(
      "toy-cart", "a cart must stop in front of a wall (the example plug-in)");
}
}  // namespace secure::plugins
