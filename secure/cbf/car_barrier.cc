#include "secure/cbf/car_barrier.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/strings.h"
#include "secure/nn/model_file.h"

namespace secure::cbf {
namespace {

using nlohmann::json;

const json& Field(const json& object, const std::string& key, const std::string& path,
                  const std::string& source) {
  SECURE_CHECK(object.is_object(), source << ": metadata field '" << path << "' must be an object");
  const auto it = object.find(key);
  SECURE_CHECK(it != object.end(),
               source << ": metadata field '" << path << (path.empty() ? "" : ".") << key
                      << "' is missing");
  return *it;
}

int IntField(const json& object, const std::string& key, const std::string& path,
             const std::string& source) {
  const json& v = Field(object, key, path, source);
  SECURE_CHECK(v.is_number_integer(), source << ": metadata field '" << path << "." << key
                                             << "' = " << v.dump() << ", must be an integer");
  const auto value = v.get<long long>();
  SECURE_CHECK(value >= std::numeric_limits<int>::min() && value <= std::numeric_limits<int>::max(),
               source << ": metadata field '" << path << "." << key << "' = " << value
                      << " is out of range");
  return static_cast<int>(value);
}

double NumberField(const json& object, const std::string& key, const std::string& source) {
  const json& v = Field(object, key, "", source);
  SECURE_CHECK(v.is_number(),
               source << ": metadata field '" << key << "' = " << v.dump() << ", must be a number");
  const double value = v.get<double>();
  SECURE_CHECK(std::isfinite(value),
               source << ": metadata field '" << key << "' = " << value << ", must be finite");
  return value;
}

std::string Widths(const nn::MlpSpec& spec) {
  std::ostringstream t;
  const auto widths = spec.Widths();
  for (std::size_t i = 0; i < widths.size(); ++i) t << (i ? "-" : "") << widths[i];
  return t.str();
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// ObstacleLayout

void ObstacleLayout::Validate(const std::string& what) const {
  SECURE_CHECK(IsSet(), what << ": layout.obs_dim = 0: the obstacle layout is unset and must be "
                                "given (there is no default: the domain's plug-in provides the "
                                "layout of its observation)");
  SECURE_CHECK_FIELD(obs_dim > 0, what << ": layout", "obs_dim", obs_dim, "> 0");
  SECURE_CHECK_FIELD(num_obstacles > 0, what << ": layout", "num_obstacles", num_obstacles, "> 0");
  SECURE_CHECK_FIELD(first_obstacle_offset >= 0, what << ": layout", "first_obstacle_offset",
                     first_obstacle_offset, ">= 0");
  SECURE_CHECK_FIELD(obstacle_stride >= 2, what << ": layout", "obstacle_stride", obstacle_stride,
                     ">= 2 (a block holds at least a relative position)");
  SECURE_CHECK_FIELD(position_offset >= 0 && position_offset + 2 <= obstacle_stride,
                     what << ": layout", "position_offset", position_offset,
                     "in [0, obstacle_stride - 2 = " << obstacle_stride - 2 << "]");
  if (velocity_offset != -1) {
    SECURE_CHECK_FIELD(velocity_offset >= 0 && velocity_offset + 2 <= obstacle_stride,
                       what << ": layout", "velocity_offset", velocity_offset,
                       "-1 (none) or in [0, obstacle_stride - 2 = " << obstacle_stride - 2 << "]");
    SECURE_CHECK_FIELD(
        velocity_offset + 2 <= position_offset || position_offset + 2 <= velocity_offset,
        what << ": layout", "velocity_offset", velocity_offset,
        "a pair not overlapping the position pair at " << position_offset);
  }
  const long end = static_cast<long>(first_obstacle_offset) +
                   static_cast<long>(num_obstacles) * static_cast<long>(obstacle_stride);
  SECURE_CHECK(end <= obs_dim, what << ": layout puts " << num_obstacles << " obstacle blocks of "
                                    << obstacle_stride << " values from index "
                                    << first_obstacle_offset << " up to index " << end
                                    << ", beyond layout.obs_dim = " << obs_dim);
}

const std::array<ObstacleLayout::Field, 6> ObstacleLayout::kFields = {{
    {"obs_dim", &ObstacleLayout::obs_dim},
    {"first_obstacle_offset", &ObstacleLayout::first_obstacle_offset},
    {"obstacle_stride", &ObstacleLayout::obstacle_stride},
    {"num_obstacles", &ObstacleLayout::num_obstacles},
    {"position_offset", &ObstacleLayout::position_offset},
    {"velocity_offset", &ObstacleLayout::velocity_offset},
}};

nlohmann::json ObstacleLayout::ToJson() const {
  nlohmann::json j = nlohmann::json::object();
  for (const Field& f : kFields) j[f.name] = this->*f.member;
  return j;
}

ObstacleLayout ObstacleLayout::FromJson(const nlohmann::json& j, const std::string& source) {
  SECURE_CHECK(j.is_object(),
               source << ": metadata field 'input.layout' = " << j.dump() << ", must be an object");
  const std::string path = "input.layout";
  ObstacleLayout l;
  for (const Field& f : kFields) l.*f.member = IntField(j, f.name, path, source);
  l.Validate(source);
  return l;
}

bool ObstacleLayout::operator==(const ObstacleLayout& o) const {
  for (const Field& f : kFields)
    if (this->*f.member != o.*f.member) return false;
  return true;
}

// ------------------------------------------------------------------------------------------------
// CarFeatureSpec

std::vector<std::string> CarFeatureSpec::FeatureNames() const {
  std::vector<std::string> names = {"dx", "dy", "d_minus_r"};
  if (use_velocity) {
    names.push_back("dvx");
    names.push_back("dvy");
  }
  return names;
}

void CarFeatureSpec::Validate(const std::string& what, bool allow_unset_layout) const {
  const bool check_layout = !allow_unset_layout || layout.IsSet();
  if (check_layout) layout.Validate(what);
  SECURE_CHECK(std::isfinite(collision_radius) && collision_radius >= 0,
               what << ": collision_radius = " << collision_radius << ", must be >= 0");
  SECURE_CHECK(std::isfinite(sensing_radius) && sensing_radius > 0,
               what << ": sensing_radius = " << sensing_radius << ", must be > 0");
  SECURE_CHECK(std::isfinite(distance_epsilon) && distance_epsilon >= 0,
               what << ": distance_epsilon = " << distance_epsilon << ", must be >= 0");
  SECURE_CHECK(!check_layout || !use_velocity || layout.velocity_offset >= 0,
               what << ": use_velocity = true, but layout.velocity_offset = -1 (the observation "
                       "has no relative velocities)");
}

nlohmann::json CarFeatureSpec::ToJson() const {
  return {{"layout", layout.ToJson()},
          {"collision_radius", collision_radius},
          {"sensing_radius", sensing_radius},
          {"distance_epsilon", distance_epsilon},
          {"use_velocity", use_velocity}};
}

CarFeatureSpec CarFeatureSpec::FromJson(const nlohmann::json& j, const std::string& source) {
  SECURE_CHECK(j.is_object(),
               source << ": metadata field 'input' = " << j.dump() << ", must be an object");
  CarFeatureSpec s;
  s.layout = ObstacleLayout::FromJson(Field(j, "layout", "input", source), source);
  auto number = [&](const char* key) {
    const json& v = Field(j, key, "input", source);
    SECURE_CHECK(v.is_number() && std::isfinite(v.get<double>()),
                 source << ": metadata field 'input." << key << "' = " << v.dump()
                        << ", must be a finite number");
    return v.get<double>();
  };
  s.collision_radius = number("collision_radius");
  s.sensing_radius = number("sensing_radius");
  s.distance_epsilon = number("distance_epsilon");
  const json& v = Field(j, "use_velocity", "input", source);
  SECURE_CHECK(v.is_boolean(), source << ": metadata field 'input.use_velocity' = " << v.dump()
                                      << ", must be true or false");
  s.use_velocity = v.get<bool>();
  s.Validate(source);
  return s;
}

bool CarFeatureSpec::operator==(const CarFeatureSpec& o) const {
  return layout == o.layout && collision_radius == o.collision_radius &&
         sensing_radius == o.sensing_radius && distance_epsilon == o.distance_epsilon &&
         use_velocity == o.use_velocity;
}

void ComputeCarFeatures(const CarFeatureSpec& spec, const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::MatrixXf* features,
                        Eigen::Matrix<bool, Eigen::Dynamic, 1>* in_range) {
  spec.Validate();
  const ObstacleLayout& l = spec.layout;
  SECURE_CHECK(states.rows() == l.obs_dim, "ComputeCarFeatures: observations have "
                                               << states.rows() << " rows, the layout "
                                               << l.obs_dim);
  const Eigen::Index n = states.cols(), k = l.num_obstacles;
  const float r = static_cast<float>(spec.collision_radius);
  const float big_r = static_cast<float>(spec.sensing_radius);
  const float eps = static_cast<float>(spec.distance_epsilon);
  features->resize(spec.feature_dim(), n * k);
  in_range->resize(n * k);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (int j = 0; j < l.num_obstacles; ++j) {
      const Eigen::Index c = i * k + j;
      const float dx = states(l.PositionIndex(j), i), dy = states(l.PositionIndex(j) + 1, i);
      const float d = std::sqrt(dx * dx + dy * dy + eps);
      (*features)(0, c) = dx;
      (*features)(1, c) = dy;
      (*features)(2, c) = d - r;
      if (spec.use_velocity) {
        (*features)(3, c) = states(l.VelocityIndex(j), i);
        (*features)(4, c) = states(l.VelocityIndex(j) + 1, i);
      }
      (*in_range)(c) = !(d > big_r);
    }
  }
}

// ------------------------------------------------------------------------------------------------
// CarBarrierNet

void CarBarrierNet::Validate(const std::string& what) const {
  input.Validate(what);
  SECURE_CHECK(std::isfinite(cap), what << ": cap = " << cap << ", must be finite");
  mlp.Validate(what);
  SECURE_CHECK(mlp.spec.input_dim == input.feature_dim(),
               what << ": per-car network has input dimension " << mlp.spec.input_dim << ", the "
                    << (input.use_velocity ? "position+velocity" : "position-only")
                    << " features need " << input.feature_dim());
  SECURE_CHECK(mlp.spec.output_dim == 1,
               what << ": per-car network has " << mlp.spec.output_dim << " outputs, expected 1");
  normalizer.Validate(what + " normalizer");
  SECURE_CHECK(normalizer.dim() == mlp.spec.input_dim,
               what << ": normalizer has dimension " << normalizer.dim()
                    << ", the per-car network input is " << mlp.spec.input_dim);
  SECURE_CHECK(features.empty() || static_cast<int>(features.size()) == input.layout.obs_dim,
               what << ": " << features.size() << " observation feature names for layout.obs_dim = "
                    << input.layout.obs_dim);
}

void CarBarrierNet::CheckFeatures(const std::vector<std::string>& data_features,
                                  const std::string& source, const std::string& model_name) const {
  if (features.empty() || data_features == features) return;
  SECURE_THROW(source << " has " << data_features.size() << " features (" << Join(data_features)
                      << "); " << model_name << " expects " << features.size() << " ("
                      << Join(features) << ")");
}

std::string CarBarrierNet::Describe() const {
  std::ostringstream t;
  t << "car_barrier " << Widths(mlp.spec) << " " << ToString(nn::kActivationNames, mlp.spec.activation)
    << ", " << input.layout.num_obstacles << " cars, r " << input.collision_radius << ", R "
    << input.sensing_radius << ", cap " << cap
    << (input.use_velocity ? ", positions+velocities" : ", positions");
  return t.str();
}

void CarBarrierNet::Save(const std::string& path) const {
  Validate(path);
  nn::ModelFile file;
  file.kind = kCarBarrierModelKind;
  file.metadata["input"] = input.ToJson();
  file.metadata["cap"] = cap;
  file.metadata["features"] = features;
  file.metadata["provenance"] = provenance;
  nn::AddMlp("car", mlp, &file);
  nn::AddNormalizer("input_norm", normalizer, &file);
  nn::WriteModelFile(path, file);
}

CarBarrierNet CarBarrierNet::Load(const std::string& path) {
  const nn::ModelFile file = nn::ReadModelFileOfKind(path, kCarBarrierModelKind);
  CarBarrierNet net;
  net.input = CarFeatureSpec::FromJson(Field(file.metadata, "input", "", path), path);
  net.cap = NumberField(file.metadata, "cap", path);
  const json& names = Field(file.metadata, "features", "", path);
  SECURE_CHECK(names.is_array(), path << ": metadata field 'features' is not a list");
  for (const auto& f : names) {
    SECURE_CHECK(f.is_string(), path << ": metadata field 'features' holds a non-string");
    net.features.push_back(f.get<std::string>());
  }
  if (file.metadata.contains("provenance")) net.provenance = file.metadata["provenance"];
  net.mlp = nn::GetMlp("car", file, path);
  net.normalizer = nn::GetNormalizer("input_norm", file, path);
  net.Validate(path);
  return net;
}

Eigen::MatrixXf CarBarrierNet::EntryValues(const Eigen::Ref<const Eigen::MatrixXf>& states) const {
  Validate();
  Eigen::MatrixXf features;
  Eigen::Matrix<bool, Eigen::Dynamic, 1> in_range;
  ComputeCarFeatures(input, states, &features, &in_range);
  const nn::InferenceMlp mlp_eval(mlp, normalizer);
  auto workspace = mlp_eval.MakeWorkspace(static_cast<int>(std::max<Eigen::Index>(1, features.cols())));
  Eigen::MatrixXf out(1, features.cols());
  if (features.cols() > 0) mlp_eval.Forward(features, workspace, out);
  const int k = input.layout.num_obstacles;
  Eigen::MatrixXf values(k, states.cols());
  for (Eigen::Index i = 0; i < states.cols(); ++i)
    for (int j = 0; j < k; ++j)
      values(j, i) = in_range(i * k + j) ? out(0, i * k + j)
                                         : std::numeric_limits<float>::infinity();
  return values;
}

std::unique_ptr<Barrier> CarBarrierNet::MakeEvaluator(int max_states) const {
  return std::make_unique<CarBarrierEvaluator>(*this, max_states);
}

// ------------------------------------------------------------------------------------------------
// CarBarrierEvaluator

CarBarrierEvaluator::CarBarrierEvaluator(const CarBarrierNet& net, int max_states)
    : layout_(net.input.layout),
      use_velocity_(net.input.use_velocity),
      r_(static_cast<float>(net.input.collision_radius)),
      big_r_(static_cast<float>(net.input.sensing_radius)),
      eps_(static_cast<float>(net.input.distance_epsilon)),
      cap_(static_cast<float>(net.cap)),
      max_states_(max_states) {
  net.Validate();
  SECURE_CHECK(max_states > 0, "CarBarrierNet::MakeEvaluator: max_states = " << max_states
                                                                              << ", must be > 0");
  const long entries = static_cast<long>(max_states) * layout_.num_obstacles;
  SECURE_CHECK(entries <= std::numeric_limits<int>::max(),
               "CarBarrierNet::MakeEvaluator: max_states = " << max_states << " is too large");
  mlp_ = nn::InferenceMlp(net.mlp, net.normalizer);
  workspace_ = mlp_.MakeWorkspace(static_cast<int>(entries));
  features_.resize(net.input.feature_dim(), entries);
  entry_h_.resize(entries);
  count_.resize(static_cast<std::size_t>(max_states));
  in_range_.resize(static_cast<std::size_t>(entries));
  description_ = net.Describe();
  const int gradient_chunk = std::min(max_states, kGradientChunk);
  gradient_workspace_ = mlp_.MakeGradientWorkspace(gradient_chunk);
  active_.resize(static_cast<std::size_t>(gradient_chunk));
  entry_car_.resize(static_cast<std::size_t>(gradient_chunk) * layout_.num_obstacles);
  active_features_.resize(net.input.feature_dim(), gradient_chunk);
  active_h_.resize(gradient_chunk);
  active_gradients_.resize(net.input.feature_dim(), gradient_chunk);
}

Eigen::Index CarBarrierEvaluator::GatherCars(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                             Eigen::Index first, Eigen::Index m, bool dense,
                                             bool record_cars) {
  const int k = layout_.num_obstacles;
  Eigen::Index c = 0;
  for (Eigen::Index i = 0; i < m; ++i) {
    const float* s = states.col(first + i).data();
    int count = 0;
    for (int j = 0; j < k; ++j) {
      const float* p = s + layout_.PositionIndex(j);
      const float dx = p[0], dy = p[1];
      const float d = std::sqrt(dx * dx + dy * dy + eps_);
      const bool in_range = !(d > big_r_);  // NaN stays in: it must not read as "no car"
      if (!in_range && !dense) continue;
      float* f = features_.col(c).data();
      f[0] = dx;
      f[1] = dy;
      f[2] = d - r_;
      if (use_velocity_) {
        const float* v = s + layout_.VelocityIndex(j);
        f[3] = v[0];
        f[4] = v[1];
      }
      if (dense) in_range_[static_cast<std::size_t>(c)] = in_range ? 1 : 0;
      if (record_cars) entry_car_[static_cast<std::size_t>(c)] = j;
      ++c;
      ++count;
    }
    count_[static_cast<std::size_t>(i)] = count;
  }
  return c;
}

void CarBarrierEvaluator::DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                           Eigen::Ref<Eigen::VectorXf> h, bool dense) {
  const Eigen::Index n = states.cols();
  for (Eigen::Index first = 0; first < n; first += max_states_) {
    const Eigen::Index m = std::min<Eigen::Index>(max_states_, n - first);
    // Gather the in-range cars of every state of the chunk (dense: every car).
    const Eigen::Index c = GatherCars(states, first, m, dense, /*record_cars=*/false);
    last_entries_ = static_cast<long>(c);
    // One forward over all of them.
    if (c > 0) {
      Eigen::Map<Eigen::RowVectorXf> out(entry_h_.data(), c);
      mlp_.Forward(features_.leftCols(c), workspace_, out);
    }
    // Min-reduce the in-range entries per state, capped; NaN propagates. Only a dense chunk
    // holds entries out of range.
    Eigen::Index e = 0;
    for (Eigen::Index i = 0; i < m; ++i) {
      float v = cap_;
      for (int q = 0; q < count_[static_cast<std::size_t>(i)]; ++q, ++e) {
        if (dense && !in_range_[static_cast<std::size_t>(e)]) continue;
        const float x = entry_h_[e];
        if (x < v || std::isnan(x)) v = std::isnan(v) ? v : x;
      }
      h[first + i] = v;
    }
  }
}

void CarBarrierEvaluator::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                             Eigen::Ref<Eigen::VectorXf> h,
                                             Eigen::Ref<Eigen::MatrixXf> gradients) {
  // h(s) = min(cap, min_j h_j(x_j(s))): the gradient of the active entry (the first car of
  // least h_j below the cap), 0 at the cap. Per chunk: the forward over every in-range car
  // (EvaluateChunks' work) picks the active car of each state; one backward pass over those.
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = static_cast<Eigen::Index>(active_.size());
  gradients.setZero();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    const Eigen::Index c = GatherCars(states, first, m, /*dense=*/false, /*record_cars=*/true);
    if (c > 0) {
      Eigen::Map<Eigen::RowVectorXf> out(entry_h_.data(), c);
      mlp_.Forward(features_.leftCols(c), workspace_, out);
    }
    // The active entry of each state (as EvaluateChunks' reduction: NaN propagates).
    Eigen::Index e = 0, active = 0;
    for (Eigen::Index i = 0; i < m; ++i) {
      float v = cap_;
      int arg = -1;
      for (int q = 0; q < count_[static_cast<std::size_t>(i)]; ++q, ++e) {
        const float x = entry_h_[e];
        if ((x < v || std::isnan(x)) && !std::isnan(v)) {
          v = x;
          arg = static_cast<int>(e);
        }
      }
      h[first + i] = v;
      active_[static_cast<std::size_t>(i)] = arg;
      if (arg >= 0) active_features_.col(active++) = features_.col(arg);
    }
    if (active == 0) continue;
    mlp_.ForwardGradient(active_features_.leftCols(active), gradient_workspace_,
                         active_h_.head(active), active_gradients_.leftCols(active));
    // Chain rule through the features: d (d - r) / d (dx, dy) = (dx, dy) / d.
    Eigen::Index a = 0;
    for (Eigen::Index i = 0; i < m; ++i) {
      const int arg = active_[static_cast<std::size_t>(i)];
      if (arg < 0) continue;
      const int j = entry_car_[static_cast<std::size_t>(arg)];
      const float dx = features_(0, arg), dy = features_(1, arg);
      const float d = std::sqrt(dx * dx + dy * dy + eps_);
      const auto g = active_gradients_.col(a++);
      auto out = gradients.col(first + i);
      out[layout_.PositionIndex(j)] = g[0] + g[2] * dx / d;
      out[layout_.PositionIndex(j) + 1] = g[1] + g[2] * dy / d;
      if (use_velocity_) {
        out[layout_.VelocityIndex(j)] = g[3];
        out[layout_.VelocityIndex(j) + 1] = g[4];
      }
    }
  }
}

}  // namespace secure::cbf
