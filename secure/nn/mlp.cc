#include "secure/nn/mlp.h"

#include <cmath>

#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::nn {

void MlpSpec::Validate() const {
  SECURE_CHECK(input_dim > 0, "MlpSpec::input_dim = " << input_dim << ", must be > 0");
  SECURE_CHECK(output_dim > 0, "MlpSpec::output_dim = " << output_dim << ", must be > 0");
  for (std::size_t i = 0; i < hidden.size(); ++i)
    SECURE_CHECK(hidden[i] > 0, "MlpSpec::hidden[" << i << "] = " << hidden[i] << ", must be > 0");
}

std::vector<int> MlpSpec::Widths() const {
  std::vector<int> widths{input_dim};
  widths.insert(widths.end(), hidden.begin(), hidden.end());
  widths.push_back(output_dim);
  return widths;
}

long MlpSpec::MultiplyAddsPerSample() const {
  const auto widths = Widths();
  long total = 0;
  for (std::size_t i = 0; i + 1 < widths.size(); ++i)
    total += static_cast<long>(widths[i]) * widths[i + 1];
  return total;
}

bool MlpSpec::operator==(const MlpSpec& other) const {
  return input_dim == other.input_dim && hidden == other.hidden && output_dim == other.output_dim &&
         activation == other.activation;
}

void MlpParams::Validate(const std::string& what) const {
  spec.Validate();
  const auto widths = spec.Widths();
  SECURE_CHECK(layers.size() + 1 == widths.size(), what << ": has " << layers.size()
                                                        << " layers, the architecture needs "
                                                        << widths.size() - 1);
  for (std::size_t i = 0; i < layers.size(); ++i) {
    const auto& layer = layers[i];
    SECURE_CHECK(layer.weight.rows() == widths[i + 1] && layer.weight.cols() == widths[i],
                 what << ": layer " << i << " weight is " << layer.weight.rows() << " x "
                      << layer.weight.cols() << ", expected " << widths[i + 1] << " x "
                      << widths[i]);
    SECURE_CHECK(layer.bias.size() == widths[i + 1], what << ": layer " << i << " bias has "
                                                          << layer.bias.size()
                                                          << " values, expected " << widths[i + 1]);
    SECURE_CHECK(layer.weight.allFinite() && layer.bias.allFinite(),
                 what << ": layer " << i << " has a non-finite weight or bias");
  }
}

Normalizer Normalizer::Fit(const Eigen::Ref<const Eigen::MatrixXf>& samples) {
  SECURE_CHECK(samples.cols() > 0, "Normalizer::Fit: no samples");
  const Eigen::MatrixXd x = samples.cast<double>();
  const Eigen::VectorXd mean = x.rowwise().mean();
  const Eigen::VectorXd var = (x.colwise() - mean).array().square().rowwise().mean();
  Normalizer n;
  n.mean = mean.cast<float>();
  n.scale = var.array().sqrt().cast<float>();
  for (int i = 0; i < n.scale.size(); ++i)
    if (!(n.scale[i] > 1e-8f)) n.scale[i] = 1.0f;  // constant feature: pass through
  return n;
}

Normalizer Normalizer::Identity(int dim) {
  return {Eigen::VectorXf::Zero(dim), Eigen::VectorXf::Ones(dim)};
}

void Normalizer::Validate(const std::string& what) const {
  SECURE_CHECK(mean.size() == scale.size(),
               what << ": mean has " << mean.size() << " values but scale has " << scale.size());
  SECURE_CHECK(mean.allFinite(), what << ": mean has a non-finite value");
  for (int i = 0; i < scale.size(); ++i)
    SECURE_CHECK(std::isfinite(scale[i]) && scale[i] > 0,
                 what << ": scale[" << i << "] = " << scale[i] << ", must be finite and > 0");
}

Eigen::MatrixXf Normalizer::Apply(const Eigen::Ref<const Eigen::MatrixXf>& samples) const {
  SECURE_CHECK(samples.rows() == dim(),
               "Normalizer::Apply: samples have " << samples.rows() << " rows, expected " << dim());
  return ((samples.colwise() - mean).array().colwise() / scale.array()).matrix();
}

MlpParams RandomMlpParams(const MlpSpec& spec, unsigned long long seed) {
  spec.Validate();
  Rng rng(seed);
  MlpParams params{spec, {}};
  const auto widths = spec.Widths();
  for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
    const double limit = std::sqrt(6.0 / (widths[i] + widths[i + 1]));
    DenseLayer layer{Eigen::MatrixXf(widths[i + 1], widths[i]), Eigen::VectorXf(widths[i + 1])};
    for (int c = 0; c < layer.weight.cols(); ++c)
      for (int r = 0; r < layer.weight.rows(); ++r)
        layer.weight(r, c) = static_cast<float>(rng.Uniform(-limit, limit));
    for (int r = 0; r < layer.bias.size(); ++r)
      layer.bias[r] = static_cast<float>(rng.Uniform(-0.1, 0.1));
    params.layers.push_back(std::move(layer));
  }
  return params;
}

Eigen::MatrixXd ReferenceForward(const MlpParams& params, const Normalizer& normalizer,
                                 const Eigen::Ref<const Eigen::MatrixXf>& inputs) {
  params.Validate();
  Eigen::MatrixXd out(params.spec.output_dim, inputs.cols());
  for (Eigen::Index c = 0; c < inputs.cols(); ++c) {
    Eigen::VectorXd x = ((inputs.col(c).cast<double>() - normalizer.mean.cast<double>()).array() /
                         normalizer.scale.cast<double>().array())
                            .matrix();
    for (std::size_t l = 0; l < params.layers.size(); ++l) {
      x = params.layers[l].weight.cast<double>() * x + params.layers[l].bias.cast<double>();
      if (l + 1 < params.layers.size()) {
        x = params.spec.activation == Activation::kRelu ? x.cwiseMax(0.0).eval()
                                                        : x.array().tanh().matrix().eval();
      }
    }
    out.col(c) = x;
  }
  return out;
}

}  // namespace secure::nn
