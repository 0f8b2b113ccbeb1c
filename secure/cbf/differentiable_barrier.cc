#include "secure/cbf/differentiable_barrier.h"

#include <cstdint>
#include <sstream>
#include <vector>

#include "secure/cbf/internal/car_barrier_torch.h"
#include "secure/common/error.h"
#include "secure/nn/torch_mlp.h"

namespace secure::cbf {
namespace {

torch::Tensor VectorTensor(const Eigen::VectorXf& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {v.size()}, torch::kFloat32).clone();
}

// BarrierNet: h(s) = mlp((s - mean) / scale), as BarrierNetEvaluator; an ensemble's is the
// minimum over its members (autograd passes the gradient of the arg-min member), as MinBarrier.
class FlatDifferentiableBarrier final : public DifferentiableBarrier {
 public:
  // rows: the rows of a `state_dim`-row state the net reads (empty: all, state_dim ignored).
  FlatDifferentiableBarrier(const BarrierNet& net, const std::vector<int>& rows, int state_dim)
      : state_dim_(rows.empty() ? net.state_dim() : state_dim) {
    net.Validate();
    for (int k = 0; k < net.members(); ++k) {
      const BarrierMember m = net.Member(k);
      nn::TorchMlp mlp(m.mlp.spec);
      mlp->LoadParams(m.mlp);
      for (auto& p : mlp->parameters()) p.requires_grad_(false);
      members_.push_back({mlp, VectorTensor(m.normalizer.mean), VectorTensor(m.normalizer.scale)});
    }
    std::ostringstream t;
    if (net.members() > 1) t << "min of " << net.members() << " ";
    t << "barrier_mlp";
    const auto widths = net.mlp.spec.Widths();
    for (std::size_t i = 0; i < widths.size(); ++i) t << (i ? "-" : " ") << widths[i];
    t << " " << ToString(nn::kActivationNames, net.mlp.spec.activation) << " (differentiable)";
    if (!rows.empty()) {
      SECURE_CHECK(static_cast<int>(rows.size()) == net.state_dim(),
                   "MakeDifferentiableBarrier: " << rows.size() << " rows for a barrier of "
                                                 << net.state_dim() << " inputs");
      for (int r : rows)
        SECURE_CHECK(r >= 0 && r < state_dim, "MakeDifferentiableBarrier: row "
                                                  << r << " outside [0, " << state_dim << ")");
      rows_ = torch::tensor(std::vector<std::int64_t>(rows.begin(), rows.end()), torch::kInt64);
      t << " on " << rows.size() << " of " << state_dim << " state rows";
    }
    description_ = t.str();
  }
  int state_dim() const override { return state_dim_; }
  std::string Describe() const override { return description_; }

 protected:
  torch::Tensor DoForward(const torch::Tensor& states) const override {
    const torch::Tensor read = rows_.defined() ? states.index_select(1, rows_) : states;
    torch::Tensor h;
    for (Member& m : members_) {
      const torch::Tensor hk = m.mlp->forward((read - m.mean) / m.scale).reshape({-1});
      h = h.defined() ? torch::minimum(h, hk) : hk;
    }
    return h;
  }

 private:
  struct Member {
    nn::TorchMlp mlp;
    torch::Tensor mean, scale;
  };
  int state_dim_;
  torch::Tensor rows_;  // undefined: all rows
  mutable std::vector<Member> members_;  // mutable: a forward pass changes no state
  std::string description_;
};

// CarBarrierNet: the per-car LibTorch forward of internal/car_barrier_torch.h.
class CarDifferentiableBarrier final : public DifferentiableBarrier {
 public:
  explicit CarDifferentiableBarrier(const CarBarrierNet& net)
      : state_dim_(net.state_dim()),
        description_(net.Describe() + " (differentiable)"),
        module_(net) {
    module_->Freeze();
  }
  int state_dim() const override { return state_dim_; }
  std::string Describe() const override { return description_; }

 protected:
  torch::Tensor DoForward(const torch::Tensor& states) const override {
    return module_->forward(states);
  }

 private:
  int state_dim_;
  std::string description_;
  mutable internal::CarBarrierTorch module_;  // mutable: a forward pass changes no state
};

}  // namespace

torch::Tensor DifferentiableBarrier::Forward(const torch::Tensor& states) const {
  SECURE_CHECK(states.dim() == 2 && states.size(1) == state_dim(),
               Describe() << ": states of shape " << states.sizes() << ", expected [N, "
                          << state_dim() << "]");
  SECURE_CHECK(states.scalar_type() == torch::kFloat32,
               Describe() << ": states must be float32, not " << states.scalar_type());
  return DoForward(states);
}

std::unique_ptr<DifferentiableBarrier> MakeDifferentiableBarrier(const BarrierNet& net) {
  return std::make_unique<FlatDifferentiableBarrier>(net, std::vector<int>{}, 0);
}

std::unique_ptr<DifferentiableBarrier> MakeDifferentiableBarrierFor(
    const BarrierNet& net, const std::vector<std::string>& state_features,
    const std::string& source, const std::string& model_name) {
  if (state_features == net.features) return MakeDifferentiableBarrier(net);
  return std::make_unique<FlatDifferentiableBarrier>(
      net, FeatureRows(net.features, state_features, source, model_name),
      static_cast<int>(state_features.size()));
}

std::unique_ptr<DifferentiableBarrier> MakeDifferentiableBarrier(const CarBarrierNet& net) {
  return std::make_unique<CarDifferentiableBarrier>(net);
}

}  // namespace secure::cbf
