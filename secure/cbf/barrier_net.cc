#include "secure/cbf/barrier_net.h"

#include <algorithm>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/strings.h"
#include "secure/nn/model_file.h"

namespace secure::cbf {
namespace {

std::string DescribeSpec(const nn::MlpSpec& spec) {
  std::ostringstream t;
  t << "barrier_mlp ";
  const auto widths = spec.Widths();
  for (std::size_t i = 0; i < widths.size(); ++i) t << (i ? "-" : "") << widths[i];
  t << " " << ToString(nn::kActivationNames, spec.activation);
  return t.str();
}

}  // namespace

void BarrierNet::Validate(const std::string& what) const {
  mlp.Validate(what);
  SECURE_CHECK(mlp.spec.output_dim == 1,
               what << ": barrier network has " << mlp.spec.output_dim << " outputs, expected 1");
  normalizer.Validate(what + " normalizer");
  SECURE_CHECK(normalizer.dim() == mlp.spec.input_dim,
               what << ": normalizer has dimension " << normalizer.dim() << ", network input is "
                    << mlp.spec.input_dim);
  SECURE_CHECK(static_cast<int>(features.size()) == mlp.spec.input_dim,
               what << ": " << features.size() << " feature names for a network input of "
                    << mlp.spec.input_dim);
}

void BarrierNet::CheckFeatures(const std::vector<std::string>& data_features,
                               const std::string& source, const std::string& model_name) const {
  if (data_features == features) return;
  SECURE_THROW(source << " has " << data_features.size() << " features (" << Join(data_features)
                      << "); " << model_name << " expects " << features.size() << " ("
                      << Join(features) << ")");
}

void BarrierNet::Save(const std::string& path) const {
  Validate(path);
  nn::ModelFile file;
  file.kind = kBarrierModelKind;
  file.metadata["features"] = features;
  file.metadata["provenance"] = provenance;
  nn::AddMlp("barrier", mlp, &file);
  nn::AddNormalizer("input", normalizer, &file);
  nn::WriteModelFile(path, file);
}

BarrierNet BarrierNet::Load(const std::string& path) {
  const nn::ModelFile file = nn::ReadModelFile(path);
  SECURE_CHECK(file.kind == kBarrierModelKind, path << ": holds a '" << file.kind
                                                    << "' model, expected '" << kBarrierModelKind
                                                    << "'");
  BarrierNet net;
  SECURE_CHECK(file.metadata.contains("features") && file.metadata["features"].is_array(),
               path << ": metadata field 'features' is missing or not a list");
  for (const auto& f : file.metadata["features"]) {
    SECURE_CHECK(f.is_string(), path << ": metadata field 'features' holds a non-string");
    net.features.push_back(f.get<std::string>());
  }
  if (file.metadata.contains("provenance")) net.provenance = file.metadata["provenance"];
  net.mlp = nn::GetMlp("barrier", file, path);
  net.normalizer = nn::GetNormalizer("input", file, path);
  net.Validate(path);
  return net;
}

std::unique_ptr<Barrier> BarrierNet::MakeEvaluator(int chunk) const {
  return std::make_unique<BarrierNetEvaluator>(*this, chunk);
}

std::unique_ptr<Barrier> BarrierNet::MakeEvaluatorFor(
    const std::vector<std::string>& state_features, const std::string& source,
    const std::string& model_name, int chunk) const {
  if (state_features == features) return MakeEvaluator(chunk);
  std::vector<int> rows = FeatureRows(features, state_features, source, model_name);
  return std::make_unique<SelectRows>(MakeEvaluator(chunk),
                                      static_cast<int>(state_features.size()), std::move(rows),
                                      chunk);
}

BarrierNetEvaluator::BarrierNetEvaluator(const BarrierNet& net, int chunk)
    : mlp_(net.mlp, net.normalizer),
      workspace_(mlp_.MakeWorkspace(chunk)),
      gradient_workspace_(mlp_.MakeGradientWorkspace(std::min(chunk, kGradientChunk))),
      description_(DescribeSpec(net.mlp.spec)) {
  net.Validate();
}

void BarrierNetEvaluator::DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                     Eigen::Ref<Eigen::VectorXf> h) {
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = workspace_.max_batch();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    // h is a column vector; the MLP writes a (1 x m) row: map the same memory as a row.
    Eigen::Map<Eigen::RowVectorXf> row(h.data() + first, m);
    mlp_.Forward(states.middleCols(first, m), workspace_, row);
  }
}

void BarrierNetEvaluator::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                             Eigen::Ref<Eigen::VectorXf> h,
                                             Eigen::Ref<Eigen::MatrixXf> gradients) {
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = gradient_workspace_.max_batch();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    mlp_.ForwardGradient(states.middleCols(first, m), gradient_workspace_, h.segment(first, m),
                         gradients.middleCols(first, m));
  }
}

}  // namespace secure::cbf
