#include "secure/cbf/internal/car_barrier_torch.h"

#include <limits>

#include "secure/common/error.h"

namespace secure::cbf::internal {
namespace {

torch::Tensor VectorTensor(const Eigen::VectorXf& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {v.size()}, torch::kFloat32).clone();
}

}  // namespace

CarFeatureTensors CarFeaturesTorch(const CarFeatureSpec& spec, const torch::Tensor& obs) {
  const ObstacleLayout& l = spec.layout;
  SECURE_CHECK(obs.dim() == 2 && obs.size(1) == l.obs_dim,
               "CarFeaturesTorch: observations of shape " << obs.sizes() << ", expected [N, "
                                                          << l.obs_dim << "]");
  SECURE_CHECK(obs.scalar_type() == torch::kFloat32,
               "CarFeaturesTorch: observations must be float32, not " << obs.scalar_type());
  const long n = obs.size(0);
  // [N, K, stride] view of the obstacle blocks.
  const torch::Tensor blocks =
      obs.slice(1, l.first_obstacle_offset,
                l.first_obstacle_offset + static_cast<long>(l.num_obstacles) * l.obstacle_stride)
          .reshape({n, l.num_obstacles, l.obstacle_stride});
  const torch::Tensor pos = blocks.slice(2, l.position_offset, l.position_offset + 2);
  const torch::Tensor dx = pos.select(2, 0), dy = pos.select(2, 1);
  // Same float operation order as the Eigen evaluator: (dx*dx + dy*dy) + eps.
  const torch::Tensor d =
      torch::sqrt(dx * dx + dy * dy + static_cast<float>(spec.distance_epsilon));
  std::vector<torch::Tensor> parts = {dx, dy, d - static_cast<float>(spec.collision_radius)};
  if (spec.use_velocity) {
    const torch::Tensor vel = blocks.slice(2, l.velocity_offset, l.velocity_offset + 2);
    parts.push_back(vel.select(2, 0));
    parts.push_back(vel.select(2, 1));
  }
  CarFeatureTensors out;
  out.features = torch::stack(parts, 2);
  out.in_range = torch::logical_not(d.detach() > static_cast<float>(spec.sensing_radius));
  return out;
}

torch::Tensor CappedMinTorch(const torch::Tensor& entry_h, const torch::Tensor& in_range,
                             double cap) {
  const torch::Tensor masked = torch::where(
      in_range, entry_h, torch::full({}, std::numeric_limits<float>::infinity(), entry_h.options()));
  // min over an empty dimension is an error; K >= 1 always (ObstacleLayout::Validate).
  const torch::Tensor m = std::get<0>(masked.min(1));
  return torch::clamp_max(m, cap);
}

CarBarrierTorchImpl::CarBarrierTorchImpl(const CarBarrierNet& net)
    : CarBarrierTorchImpl(net.input, net.mlp.spec, net.normalizer, net.cap) {
  net.Validate();
  mlp_->LoadParams(net.mlp);
}

CarBarrierTorchImpl::CarBarrierTorchImpl(const CarFeatureSpec& input, const nn::MlpSpec& mlp_spec,
                                         const nn::Normalizer& normalizer, double cap)
    : input_(input), cap_(cap), normalizer_(normalizer) {
  input_.Validate();
  SECURE_CHECK(mlp_spec.input_dim == input_.feature_dim() && mlp_spec.output_dim == 1,
               "CarBarrierTorch: per-car network " << mlp_spec.input_dim << " -> ... -> "
                                                   << mlp_spec.output_dim << ", expected "
                                                   << input_.feature_dim() << " -> ... -> 1");
  normalizer_.Validate("CarBarrierTorch normalizer");
  SECURE_CHECK(normalizer_.dim() == input_.feature_dim(),
               "CarBarrierTorch: normalizer dimension " << normalizer_.dim() << ", expected "
                                                        << input_.feature_dim());
  SECURE_CHECK(std::isfinite(cap), "CarBarrierTorch: cap = " << cap << ", must be finite");
  mlp_ = register_module("mlp", nn::TorchMlp(mlp_spec));
  mean_ = register_buffer("mean", VectorTensor(normalizer_.mean));
  inv_scale_ = register_buffer("inv_scale", 1.0f / VectorTensor(normalizer_.scale));
}

torch::Tensor CarBarrierTorchImpl::EntryValues(const torch::Tensor& features) {
  const auto sizes = features.sizes().vec();
  SECURE_CHECK(!sizes.empty() && sizes.back() == input_.feature_dim(),
               "CarBarrierTorch::EntryValues: features of shape " << features.sizes()
                                                                   << ", last dimension must be "
                                                                   << input_.feature_dim());
  const torch::Tensor x = ((features - mean_) * inv_scale_).reshape({-1, input_.feature_dim()});
  std::vector<std::int64_t> out_sizes(sizes.begin(), sizes.end() - 1);
  return mlp_->forward(x).reshape(out_sizes);
}

CarFeatureTensors CarBarrierTorchImpl::Features(const torch::Tensor& obs) const {
  return CarFeaturesTorch(input_, obs);
}

torch::Tensor CarBarrierTorchImpl::forward(const torch::Tensor& obs) {
  const CarFeatureTensors f = Features(obs);
  return CappedMinTorch(EntryValues(f.features), f.in_range, cap_);
}

void CarBarrierTorchImpl::Freeze() {
  for (auto& p : parameters()) p.requires_grad_(false);
}

CarBarrierNet CarBarrierTorchImpl::ToNet() const {
  CarBarrierNet net;
  net.input = input_;
  net.cap = cap_;
  net.normalizer = normalizer_;
  net.mlp = mlp_->ToParams();
  return net;
}

void CarBarrierTorchImpl::LoadMlpParams(const nn::MlpParams& params) { mlp_->LoadParams(params); }

}  // namespace secure::cbf::internal
