#include "domains/derby/derby.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::derby {
namespace {

// Rejection sampling gives up after this many draws per car (the defaults almost never reject).
constexpr int kMaxPlacementDraws = 10000;

// (x, y) farther than sqrt(r2) from (cx, cy).
bool FarFrom(double x, double y, double cx, double cy, double r2) {
  return (x - cx) * (x - cx) + (y - cy) * (y - cy) > r2;
}

// Places cars 0..n-1 one by one by rejection (points[2j], points[2j + 1]): up to
// kMaxPlacementDraws proposals propose(j) -> {x, y}, the first that passes clear(x, y) and lies
// farther than sqrt(sep2) from every car placed before it. Returns the first car that found no
// place (the cars after it are not tried), or -1.
template <typename Propose, typename Clear>
int PlaceCars(int n, double sep2, Propose&& propose, Clear&& clear, double* points) {
  for (int j = 0; j < n; ++j) {
    bool placed = false;
    for (int draw = 0; draw < kMaxPlacementDraws && !placed; ++draw) {
      const std::array<double, 2> p = propose(j);
      const double x = p[0], y = p[1];
      placed = clear(x, y);
      for (int k = 0; k < j && placed; ++k)
        placed = FarFrom(x, y, points[2 * k], points[2 * k + 1], sep2);
      if (placed) {
        points[2 * j] = x;
        points[2 * j + 1] = y;
      }
    }
    if (!placed) return j;
  }
  return -1;
}

bool Finite(double x) { return std::isfinite(x); }

// The cars' acceleration noise: an approximately standard normal draw (Irwin-Hall: the sum of
// four 16-bit uniforms from one 64-bit draw, centred and scaled to variance 1; bounded by
// +-2 sqrt(3)). Reset() draws 2 x 16 x 105 of them; Box-Muller (Rng::Normal, ~25 ns) made Reset
// cost 100 us, 1 us per step of a 100-step episode, this costs ~2 ns.
double CarNoise(Rng& rng) {
  const std::uint64_t bits = rng.NextU64();
  const double sum = static_cast<double>((bits & 0xffff) + ((bits >> 16) & 0xffff) +
                                         ((bits >> 32) & 0xffff) + (bits >> 48)) +
                     2.0;  // each chunk + 0.5, in units of 2^-16
  constexpr double kScale = 1.7320508075688772 / 65536.0;  // sqrt(12 / 4) per unit
  return (sum - 2.0 * 65536.0) * kScale;
}

}  // namespace

const std::vector<std::string>& ObservationFeatures() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n{"goal_dx", "goal_dy", "vx", "vy"};
    for (int i = 0; i < kObservedCars; ++i) {
      const std::string c = "car" + std::to_string(i);
      for (const char* s : {"_dx", "_dy", "_dvx", "_dvy"}) n.push_back(c + s);
    }
    return n;
  }();
  return names;
}

const std::vector<std::string>& ActionFeatures() {
  static const std::vector<std::string> names{"ax", "ay"};
  return names;
}

// ---------------------------------------------------------------------------------------------
// Options

void DerbyOptions::Validate() const {
  SECURE_CHECK_FIELD(num_cars >= kObservedCars && num_cars <= kMaxCars, "DerbyOptions", "num_cars",
                     num_cars, "in [" << kObservedCars << ", " << kMaxCars << "]");
  SECURE_CHECK_FIELD(Finite(dt) && dt > 0, "DerbyOptions", "dt", dt, "> 0");
  SECURE_CHECK_FIELD(max_steps > 0, "DerbyOptions", "max_steps", max_steps, "> 0");
  SECURE_CHECK_FIELD(Finite(arena_side) && arena_side > 0, "DerbyOptions", "arena_side", arena_side,
                     "> 0");
  SECURE_CHECK_FIELD(Finite(start_jitter) && start_jitter >= 0, "DerbyOptions", "start_jitter",
                     start_jitter, ">= 0");
  SECURE_CHECK_FIELD(Finite(goal_jitter) && goal_jitter >= 0, "DerbyOptions", "goal_jitter",
                     goal_jitter, ">= 0");
  SECURE_CHECK_FIELD(Finite(goal_radius) && goal_radius > 0, "DerbyOptions", "goal_radius",
                     goal_radius, "> 0");
  SECURE_CHECK_FIELD(Finite(collision_radius) && collision_radius > 0, "DerbyOptions",
                     "collision_radius", collision_radius, "> 0");
  SECURE_CHECK_FIELD(Finite(accel_bound) && accel_bound > 0, "DerbyOptions", "accel_bound",
                     accel_bound, "> 0");
  SECURE_CHECK_FIELD(Finite(min_separation) && min_separation >= 0, "DerbyOptions",
                     "min_separation", min_separation, ">= 0");
  SECURE_CHECK_FIELD(Finite(ego_clearance) && ego_clearance >= 0, "DerbyOptions", "ego_clearance",
                     ego_clearance, ">= 0");
  SECURE_CHECK_FIELD(Finite(car_goal_offset) && car_goal_offset >= 0, "DerbyOptions",
                     "car_goal_offset", car_goal_offset, ">= 0");
  SECURE_CHECK_FIELD(Finite(car_kp) && car_kp >= 0, "DerbyOptions", "car_kp", car_kp, ">= 0");
  SECURE_CHECK_FIELD(Finite(car_kd) && car_kd >= 0, "DerbyOptions", "car_kd", car_kd, ">= 0");
  SECURE_CHECK_FIELD(Finite(car_noise) && car_noise >= 0, "DerbyOptions", "car_noise", car_noise,
                     ">= 0");
  SECURE_CHECK_FIELD(lookahead_steps >= 1 && lookahead_steps <= kLookaheadFrames, "DerbyOptions",
                     "lookahead_steps", lookahead_steps, "in [1, " << kLookaheadFrames << "]");
}

YamlFields DerbyOptions::Fields() {
  return YamlFields()
      .Named("demolition derby task options")
      .Field("num_cars", &num_cars)
      .Field("dt", &dt)
      .Field("max_steps", &max_steps)
      .Field("arena_side", &arena_side)
      .Field("start_jitter", &start_jitter)
      .Field("goal_jitter", &goal_jitter)
      .Field("goal_radius", &goal_radius)
      .Field("collision_radius", &collision_radius)
      .Field("accel_bound", &accel_bound)
      .Field("min_separation", &min_separation)
      .Field("ego_clearance", &ego_clearance)
      .Field("car_goal_offset", &car_goal_offset)
      .Field("car_kp", &car_kp)
      .Field("car_kd", &car_kd)
      .Field("car_noise", &car_noise)
      .Field("lookahead_steps", &lookahead_steps);
}

SECURE_YAML_JSON_FROM_FIELDS(DerbyOptions)

// ---------------------------------------------------------------------------------------------
// Observation

void BuildObservation(const Eigen::Vector2f& p, const Eigen::Vector2f& v,
                      const Eigen::Vector2f& goal,
                      const Eigen::Ref<const Eigen::Matrix2Xf>& car_positions,
                      const Eigen::Ref<const Eigen::Matrix2Xf>& car_velocities,
                      Eigen::Ref<Eigen::VectorXf> observation,
                      std::array<int, kObservedCars>* observed) {
  const int n = static_cast<int>(car_positions.cols());
  SECURE_CHECK(n >= kObservedCars && n <= kMaxCars && car_velocities.cols() == n,
               "BuildObservation: " << n << " car positions and " << car_velocities.cols()
                                    << " velocities, expected as many, in [" << kObservedCars
                                    << ", " << kMaxCars << "]");
  SECURE_CHECK(observation.size() == kObservationDim, "BuildObservation: observation has "
                                                          << observation.size()
                                                          << " entries, expected "
                                                          << kObservationDim);
  std::array<float, kMaxCars> d2;
  std::array<int, kMaxCars> order;
  for (int j = 0; j < n; ++j) {
    d2[j] = (car_positions.col(j) - p).squaredNorm();
    order[j] = j;
  }
  std::partial_sort(order.begin(), order.begin() + kObservedCars, order.begin() + n,
                    [&d2](int a, int b) { return d2[a] < d2[b] || (d2[a] == d2[b] && a < b); });
  observation.segment<2>(0) = goal - p;
  observation.segment<2>(2) = v;
  for (int i = 0; i < kObservedCars; ++i) {
    const int j = order[i];
    const int o = kFirstCarOffset + kCarStride * i;
    observation.segment<2>(o) = car_positions.col(j) - p;
    observation.segment<2>(o + 2) = car_velocities.col(j) - v;
    if (observed != nullptr) (*observed)[i] = j;
  }
}

// ---------------------------------------------------------------------------------------------
// DerbyShieldModel

DerbyShieldModel::DerbyShieldModel(double dt, double accel_bound, int lookahead_steps)
    : dt_(dt), accel_bound_(accel_bound), lookahead_steps_(lookahead_steps) {
  SECURE_CHECK(std::isfinite(dt) && dt > 0, "DerbyShieldModel: dt = " << dt << ", must be > 0");
  SECURE_CHECK(std::isfinite(accel_bound) && accel_bound > 0,
               "DerbyShieldModel: accel_bound = " << accel_bound << ", must be > 0");
  SECURE_CHECK(lookahead_steps >= 1,
               "DerbyShieldModel: lookahead_steps = " << lookahead_steps << ", must be >= 1");
}

std::string DerbyShieldModel::Describe() const {
  std::ostringstream s;
  s << "demolition derby shield model (ego explicit Euler, |a_i| <= " << accel_bound_
    << " clipped and held " << lookahead_steps_ << " steps of dt " << dt_
    << "; observed cars at constant velocity)";
  return s.str();
}

void DerbyShieldModel::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                              const Eigen::Ref<const Eigen::MatrixXf>& actions,
                              Eigen::Ref<Eigen::MatrixXf> next_states) const {
  const float dt = static_cast<float>(dt_);
  const float bound = static_cast<float>(accel_bound_);
  const float steps = static_cast<float>(lookahead_steps_);
  const float pos_gain = dt * dt * steps * (steps - 1.0f) / 2.0f;  // ego displacement per unit a
  const float vel_gain = steps * dt;
  const Eigen::Vector2f v = state.segment<2>(2);
  for (Eigen::Index m = 0; m < actions.cols(); ++m) {
    const Eigen::Vector2f a = actions.col(m).cwiseMax(-bound).cwiseMin(bound);
    const Eigen::Vector2f ego_dp = vel_gain * v + pos_gain * a;  // ego displacement
    const Eigen::Vector2f ego_dv = vel_gain * a;                 // ego velocity change
    auto out = next_states.col(m);
    out.segment<2>(0) = state.segment<2>(0) - ego_dp;
    out.segment<2>(2) = v + ego_dv;
    for (int i = 0; i < kObservedCars; ++i) {
      const int o = kFirstCarOffset + kCarStride * i;
      const Eigen::Vector2f rel_v = state.segment<2>(o + 2);
      // Car displacement vel_gain (v + rel_v) minus the ego's.
      out.segment<2>(o) = state.segment<2>(o) + vel_gain * rel_v - pos_gain * a;
      out.segment<2>(o + 2) = rel_v - ego_dv;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// DerbyEnv

DerbyEnv::DerbyEnv(const DerbyOptions& options)
    : options_((options.Validate(), options)),
      model_(options.dt, options.accel_bound, options.lookahead_steps),
      num_frames_(options.max_steps + 1 + kLookaheadFrames),
      car_p_(2, static_cast<Eigen::Index>(num_frames_) * options.num_cars),
      car_v_(2, static_cast<Eigen::Index>(num_frames_) * options.num_cars),
      car_goals_(Eigen::Matrix2Xf::Zero(2, options.num_cars)) {
  car_p_.setZero();
  car_v_.setZero();
}

std::vector<std::string> DerbyEnv::ObservationFeatures() const {
  return derby::ObservationFeatures();
}
std::vector<std::string> DerbyEnv::ActionFeatures() const { return derby::ActionFeatures(); }

std::string DerbyEnv::Describe() const {
  const DerbyOptions& o = options_;
  std::ostringstream s;
  s << "demolition derby: " << o.num_cars << " cars in [0, " << o.arena_side
    << "]^2, ego (0, 0) -> (" << o.arena_side << ", " << o.arena_side << ") +-" << o.goal_jitter
    << ", goal radius " << o.goal_radius << ", collision radius " << o.collision_radius
    << ", |a_i| <= " << o.accel_bound << ", dt " << o.dt << ", " << o.max_steps << " steps";
  return s.str();
}

void DerbyEnv::CheckObservation(const Eigen::Ref<Eigen::VectorXf>& observation,
                                const char* where) const {
  SECURE_CHECK(observation.size() == kObservationDim, "DerbyEnv::" << where << ": observation has "
                                                                   << observation.size()
                                                                   << " entries, expected "
                                                                   << kObservationDim);
}

Eigen::Matrix2Xf::ConstColsBlockXpr DerbyEnv::CarPositions(int frame) const {
  SECURE_CHECK(frame >= 0 && frame < num_frames_,
               "DerbyEnv::CarPositions: frame " << frame << " outside [0, " << num_frames_ << ")");
  return car_p_.middleCols(static_cast<Eigen::Index>(frame) * options_.num_cars,
                           options_.num_cars);
}

Eigen::Matrix2Xf::ConstColsBlockXpr DerbyEnv::CarVelocities(int frame) const {
  SECURE_CHECK(frame >= 0 && frame < num_frames_,
               "DerbyEnv::CarVelocities: frame " << frame << " outside [0, " << num_frames_ << ")");
  return car_v_.middleCols(static_cast<Eigen::Index>(frame) * options_.num_cars,
                           options_.num_cars);
}

void DerbyEnv::Observe(Eigen::Ref<Eigen::VectorXf> observation) {
  CheckObservation(observation, "Observe");
  const Eigen::Index n = options_.num_cars;
  const Eigen::Index first = static_cast<Eigen::Index>(step_) * n;
  BuildObservation(p_, v_, goal_, car_p_.middleCols(first, n), car_v_.middleCols(first, n),
                   observation, &observed_);
}

float DerbyEnv::NearestCarDistance() const {
  const Eigen::Index n = options_.num_cars;
  const Eigen::Index first = static_cast<Eigen::Index>(step_) * n;
  float best = std::numeric_limits<float>::infinity();
  for (Eigen::Index j = first; j < first + n; ++j)
    best = std::min(best, (car_p_.col(j) - p_).squaredNorm());
  return std::sqrt(best);
}

void DerbyEnv::Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) {
  CheckObservation(observation, "Reset");
  const DerbyOptions& o = options_;
  const int n = o.num_cars;
  const double side = o.arena_side;
  const double start_x = rng.Uniform(-o.start_jitter, o.start_jitter);
  const double start_y = rng.Uniform(-o.start_jitter, o.start_jitter);
  const double goal_x = side + rng.Uniform(-o.goal_jitter, o.goal_jitter);
  const double goal_y = side + rng.Uniform(-o.goal_jitter, o.goal_jitter);
  p_ = Eigen::Vector2f(static_cast<float>(start_x), static_cast<float>(start_y));
  v_.setZero();
  goal_ = Eigen::Vector2f(static_cast<float>(goal_x), static_cast<float>(goal_y));

  // Placement in double; frame 0 of car_p_ holds the starts, car_goals_ the goals.
  std::array<double, 2 * kMaxCars> start, target;
  const double sep2 = o.min_separation * o.min_separation;
  const double clear2 = o.ego_clearance * o.ego_clearance;
  const int no_start = PlaceCars(
      n, sep2,
      [&](int) {
        const double x = rng.Uniform(0.0, side), y = rng.Uniform(0.0, side);
        return std::array<double, 2>{x, y};
      },
      [&](double x, double y) {
        return FarFrom(x, y, start_x, start_y, clear2) && FarFrom(x, y, goal_x, goal_y, clear2);
      },
      start.data());
  SECURE_CHECK(no_start < 0, "DerbyEnv::Reset: no start for car "
                                 << no_start << " in [0, " << side << "]^2 at least "
                                 << o.min_separation << " from the other cars and "
                                 << o.ego_clearance << " from the ego start and goal ("
                                 << kMaxPlacementDraws << " draws)");
  const int no_goal = PlaceCars(
      n, sep2,
      [&](int j) {
        const double x = start[2 * j] + rng.Uniform(-o.car_goal_offset, o.car_goal_offset);
        const double y = start[2 * j + 1] + rng.Uniform(-o.car_goal_offset, o.car_goal_offset);
        return std::array<double, 2>{x, y};
      },
      [&](double x, double y) { return FarFrom(x, y, goal_x, goal_y, clear2); }, target.data());
  SECURE_CHECK(no_goal < 0, "DerbyEnv::Reset: no goal for car "
                                << no_goal << " within +-" << o.car_goal_offset
                                << " of its start, " << o.min_separation
                                << " from the other goals and " << o.ego_clearance
                                << " from the ego goal (" << kMaxPlacementDraws << " draws)");
  // The trajectories: explicit Euler in double, stored as float. Car by car (the noise stream
  // order is part of the episode's definition: car 0's frames, then car 1's, ...).
  const double dt = o.dt;
  for (int j = 0; j < n; ++j) {
    double px = start[2 * j], py = start[2 * j + 1], vx = 0.0, vy = 0.0;
    const double gx = target[2 * j], gy = target[2 * j + 1];
    car_goals_(0, j) = static_cast<float>(gx);
    car_goals_(1, j) = static_cast<float>(gy);
    for (int f = 0; f < num_frames_; ++f) {
      const Eigen::Index c = static_cast<Eigen::Index>(f) * n + j;
      car_p_(0, c) = static_cast<float>(px);
      car_p_(1, c) = static_cast<float>(py);
      car_v_(0, c) = static_cast<float>(vx);
      car_v_(1, c) = static_cast<float>(vy);
      if (f + 1 == num_frames_) break;
      const double ax = -o.car_kp * (px - gx) - o.car_kd * vx + o.car_noise * CarNoise(rng);
      const double ay = -o.car_kp * (py - gy) - o.car_kd * vy + o.car_noise * CarNoise(rng);
      px += vx * dt;
      py += vy * dt;
      vx += ax * dt;
      vy += ay * dt;
    }
  }
  step_ = 0;
  started_ = true;
  Observe(observation);
  in_contact_ = NearestCarDistance() <= static_cast<float>(o.collision_radius);
}

void DerbyEnv::SetScenario(const Eigen::Vector4f& ego, const Eigen::Vector2f& goal,
                           const Eigen::Ref<const Eigen::Matrix2Xf>& car_positions,
                           const Eigen::Ref<const Eigen::Matrix2Xf>& car_velocities,
                           Eigen::Ref<Eigen::VectorXf> observation) {
  CheckObservation(observation, "SetScenario");
  const int n = options_.num_cars;
  SECURE_CHECK(car_positions.cols() == n && car_velocities.cols() == n,
               "DerbyEnv::SetScenario: " << car_positions.cols() << " car positions and "
                                         << car_velocities.cols() << " velocities, expected "
                                         << n << " (num_cars)");
  SECURE_CHECK(ego.allFinite() && goal.allFinite() && car_positions.allFinite() &&
                   car_velocities.allFinite(),
               "DerbyEnv::SetScenario: non-finite ego state, goal or car state");
  p_ = ego.head<2>();
  v_ = ego.tail<2>();
  goal_ = goal;
  car_goals_.setZero();
  for (int f = 0; f < num_frames_; ++f) {
    for (int j = 0; j < n; ++j) {
      const Eigen::Index c = static_cast<Eigen::Index>(f) * n + j;
      const Eigen::Vector2d q = car_positions.col(j).cast<double>() +
                                (f * options_.dt) * car_velocities.col(j).cast<double>();
      car_p_.col(c) = q.cast<float>();
      car_v_.col(c) = car_velocities.col(j);
    }
  }
  step_ = 0;
  started_ = true;
  Observe(observation);
  in_contact_ = NearestCarDistance() <= static_cast<float>(options_.collision_radius);
}

StepOutcome DerbyEnv::Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                           Eigen::Ref<Eigen::VectorXf> observation) {
  SECURE_CHECK(started_, "DerbyEnv::Step before Reset (no current state)");
  SECURE_CHECK(action.size() == kActionDim, "DerbyEnv::Step: action has "
                                                << action.size()
                                                << " entries, expected 2 (ax, ay)");
  CheckObservation(observation, "Step");
  for (int i = 0; i < kActionDim; ++i)
    SECURE_CHECK(std::isfinite(action[i]), "DerbyEnv::Step: action component "
                                               << derby::ActionFeatures()[static_cast<std::size_t>(i)]
                                               << " = " << action[i] << ", must be finite");
  SECURE_CHECK(step_ + 1 < num_frames_,
               "DerbyEnv::Step: step " << step_ + 1 << " is past the generated car trajectories ("
                                       << num_frames_ - 1 << " steps = max_steps + "
                                       << kLookaheadFrames << "); call Reset()");
  const float bound = static_cast<float>(options_.accel_bound);
  const float dt = static_cast<float>(options_.dt);
  const Eigen::Vector2f a = action.cwiseMax(-bound).cwiseMin(bound);
  p_ += v_ * dt;  // explicit Euler: the old velocity
  v_ += a * dt;
  ++step_;
  Observe(observation);
  StepOutcome out;
  out.reached_goal = (p_ - goal_).norm() < static_cast<float>(options_.goal_radius);
  // Block 0 is the nearest of all cars: its squared distance is NearestCarDistance()^2.
  const float r = static_cast<float>(options_.collision_radius);
  const bool contact = observation.segment<2>(kFirstCarOffset).squaredNorm() <= r * r;
  out.collided = contact;
  out.collisions = contact && !in_contact_ ? 1 : 0;
  in_contact_ = contact;
  return out;
}

bool DerbyEnv::BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                            Eigen::Ref<Eigen::VectorXf> action) const {
  SECURE_CHECK(observation.size() == kObservationDim && action.size() == kActionDim,
               "DerbyEnv::BackupAction: observation/action have "
                   << observation.size() << "/" << action.size() << " entries, expected "
                   << kObservationDim << "/" << kActionDim);
  const double a_max = options_.accel_bound;
  for (int i = 0; i < kActionDim; ++i)
    action[i] = static_cast<float>(
        std::clamp(-static_cast<double>(observation[2 + i]) / options_.dt, -a_max, a_max));
  return true;
}

std::unique_ptr<Environment> DerbyEnv::Clone() const { return std::make_unique<DerbyEnv>(options_); }

}  // namespace secure::domains::derby
