#include "secure/policy/gaussian_policy.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <string>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/nn/model_file.h"

namespace secure::policy {
namespace {

using secure::test::ErrorOf;

Eigen::VectorXf Vec(std::initializer_list<float> values) {
  Eigen::VectorXf v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (float x : values) v[i++] = x;
  return v;
}

GaussianPolicy MakePolicy(std::uint64_t seed = 1) {
  GaussianPolicy p;
  nn::MlpSpec spec;
  spec.input_dim = 3;
  spec.hidden = {8, 5};
  spec.output_dim = 2;
  spec.activation = nn::Activation::kTanh;
  p.mean = nn::RandomMlpParams(spec, seed);
  // Dynamic-size vectors throughout the tests: GCC 12 reports false -Warray-bounds positives
  // for Eigen's AVX packets on 2- and 3-float fixed-size vectors.
  p.input.mean = Vec({0.5f, -1.0f, 2.0f});
  p.input.scale = Vec({2.0f, 0.5f, 1.5f});
  p.log_std = Vec({-1.0f, 0.25f});
  p.observation_features = {"a", "b", "c"};
  p.action_features = {"u", "v"};
  p.provenance = {{"trainer", "test"}};
  return p;
}

bool BitEqual(const GaussianPolicy& a, const GaussianPolicy& b) {
  if (!(a.mean.spec == b.mean.spec) || a.mean.layers.size() != b.mean.layers.size()) return false;
  for (std::size_t l = 0; l < a.mean.layers.size(); ++l)
    if (a.mean.layers[l].weight != b.mean.layers[l].weight ||
        a.mean.layers[l].bias != b.mean.layers[l].bias)
      return false;
  return a.input.mean == b.input.mean && a.input.scale == b.input.scale && a.log_std == b.log_std &&
         a.observation_features == b.observation_features && a.action_features == b.action_features;
}

class GaussianPolicyFileTest : public secure::test::TempDirTest {};

TEST_F(GaussianPolicyFileTest, SaveLoadRoundTripIsBitwise) {
  const GaussianPolicy p = MakePolicy();
  const std::string path = PathOf("pi.model");
  p.Save(path);
  const GaussianPolicy q = GaussianPolicy::Load(path);
  EXPECT_TRUE(BitEqual(p, q));
  EXPECT_EQ(q.provenance["trainer"], "test");
  // The file holds the documented tensors and metadata.
  const nn::ModelFile file = nn::ReadModelFile(path);
  EXPECT_EQ(file.kind, kGaussianPolicyKind);
  EXPECT_NO_THROW(file.Tensor("mean.layer0.weight"));
  EXPECT_NO_THROW(file.Tensor("mean.layer2.bias"));
  EXPECT_NO_THROW(file.Tensor("input.mean"));
  EXPECT_NO_THROW(file.Tensor("input.scale"));
  EXPECT_EQ(file.Tensor("log_std").shape, (std::vector<std::int64_t>{2}));
  EXPECT_EQ(file.metadata["observation_features"], nlohmann::json({"a", "b", "c"}));
  EXPECT_EQ(file.metadata["action_features"], nlohmann::json({"u", "v"}));
}

TEST_F(GaussianPolicyFileTest, CorruptFileIsRejectedNamingIt) {
  const std::string path = PathOf("pi.model");
  MakePolicy().Save(path);
  std::string bytes = ReadFile(path);
  bytes[bytes.size() / 2] ^= 0x5a;  // inside the payload: the checksum no longer matches
  WriteFileAtomically(path, bytes);
  EXPECT_HAS(ErrorOf([&] { GaussianPolicy::Load(path); }), path);
  WriteFileAtomically(path, bytes.substr(0, 40));  // truncated
  EXPECT_HAS(ErrorOf([&] { GaussianPolicy::Load(path); }), path);
  EXPECT_HAS(ErrorOf([&] { GaussianPolicy::Load(PathOf("missing.model")); }), "missing.model");
}

TEST_F(GaussianPolicyFileTest, WrongKindIsRejected) {
  const GaussianPolicy p = MakePolicy();
  nn::ModelFile file;
  file.kind = "barrier_mlp";
  file.metadata["features"] = {"a", "b", "c"};
  nn::AddMlp("barrier", p.mean, &file);
  const std::string path = PathOf("barrier.model");
  nn::WriteModelFile(path, file);
  const std::string message = ErrorOf([&] { GaussianPolicy::Load(path); });
  EXPECT_HAS(message, path);
  EXPECT_HAS(message, "'barrier_mlp'");
  EXPECT_HAS(message, "gaussian_policy");
}

// A hand-built file: lets each test break one thing.
nn::ModelFile PolicyFile(const GaussianPolicy& p) {
  nn::ModelFile file;
  file.kind = kGaussianPolicyKind;
  file.metadata["observation_features"] = p.observation_features;
  file.metadata["action_features"] = p.action_features;
  nn::AddMlp("mean", p.mean, &file);
  nn::AddNormalizer("input", p.input, &file);
  file.tensors.push_back(
      {"log_std",
       {p.log_std.size()},
       std::vector<float>(p.log_std.data(), p.log_std.data() + p.log_std.size())});
  return file;
}

TEST_F(GaussianPolicyFileTest, MismatchedDimensionsAreRejected) {
  const GaussianPolicy p = MakePolicy();
  const std::string path = PathOf("bad.model");
  {
    nn::ModelFile file = PolicyFile(p);
    file.tensors.back() = {"log_std", {3}, {0.0f, 0.0f, 0.0f}};
    nn::WriteModelFile(path, file);
    const std::string m = ErrorOf([&] { GaussianPolicy::Load(path); });
    EXPECT_HAS(m, path);
    EXPECT_HAS(m, "log_std");
  }
  {
    nn::ModelFile file = PolicyFile(p);
    file.metadata["action_features"] = {"u"};
    nn::WriteModelFile(path, file);
    const std::string m = ErrorOf([&] { GaussianPolicy::Load(path); });
    EXPECT_HAS(m, path);
    EXPECT_HAS(m, "action feature names");
  }
  {
    GaussianPolicy q = p;
    q.input = nn::Normalizer::Identity(2);
    nn::ModelFile file;
    file.kind = kGaussianPolicyKind;
    file.metadata["observation_features"] = p.observation_features;
    file.metadata["action_features"] = p.action_features;
    nn::AddMlp("mean", p.mean, &file);
    nn::AddNormalizer("input", q.input, &file);
    file.tensors.push_back({"log_std", {2}, {0.0f, 0.0f}});
    nn::WriteModelFile(path, file);
    const std::string m = ErrorOf([&] { GaussianPolicy::Load(path); });
    EXPECT_HAS(m, path);
    EXPECT_HAS(m, "normalizer has dimension 2");
  }
  {
    nn::ModelFile file = PolicyFile(p);
    file.tensors.pop_back();  // no log_std
    nn::WriteModelFile(path, file);
    EXPECT_HAS(ErrorOf([&] { GaussianPolicy::Load(path); }), "log_std");
  }
}

TEST(GaussianPolicyTest, ValidateAndSaveRejectNonFinite) {
  GaussianPolicy p = MakePolicy();
  p.log_std[1] = std::numeric_limits<float>::infinity();
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "log_std[1]");
  EXPECT_HAS(ErrorOf([&] { p.Save(::testing::TempDir() + "/never.model"); }), "never.model");
  p = MakePolicy();
  p.mean.layers[1].weight(0, 0) = std::nanf("");
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "non-finite");
}

TEST(GaussianPolicyTest, CheckFeaturesNamesBothLists) {
  const GaussianPolicy p = MakePolicy();
  EXPECT_NO_THROW(p.CheckFeatures({"a", "b", "c"}, {"u", "v"}, "env"));
  const std::string m = ErrorOf([&] { p.CheckFeatures({"a", "c", "b"}, {"u", "v"}, "env X"); });
  EXPECT_HAS(m, "env X");
  EXPECT_HAS(m, "a, c, b");
  EXPECT_HAS(m, "a, b, c");
}

TEST(PolicyEvaluatorTest, MeanMatchesReferenceForward) {
  const GaussianPolicy p = MakePolicy();
  PolicyEvaluator ev(p, /*chunk=*/4);
  Rng rng(3);
  Eigen::MatrixXf x(3, 11);
  for (int c = 0; c < x.cols(); ++c)
    for (int r = 0; r < 3; ++r) x(r, c) = static_cast<float>(rng.Uniform(-3, 3));
  const Eigen::MatrixXd expected = nn::ReferenceForward(p.mean, p.input, x);
  Eigen::VectorXf mu(2);
  for (int c = 0; c < x.cols(); ++c) {
    ev.Mean(x.col(c), mu);
    EXPECT_NEAR(mu[0], expected(0, c), 1e-5);
    EXPECT_NEAR(mu[1], expected(1, c), 1e-5);
  }
  // Batched, larger than the chunk (evaluated in chunks of 4).
  Eigen::MatrixXf mus(2, x.cols());
  ev.Means(x, mus);
  EXPECT_LT((mus.cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_EQ(ev.observation_dim(), 3);
  EXPECT_EQ(ev.action_dim(), 2);
  EXPECT_FLOAT_EQ(ev.sigma()[0], std::exp(-1.0f));
}

// A policy whose network reads three of four observation features: the evaluator takes whole
// observations and reads the input rows itself.
GaussianPolicy MakeSubsetPolicy() {
  GaussianPolicy p = MakePolicy();
  p.observation_features = {"a", "z", "b", "c"};
  p.input_features = {"a", "b", "c"};
  return p;
}

TEST(PolicyEvaluatorTest, APolicyOnSomeFeaturesReadsThemFromTheWholeObservation) {
  const GaussianPolicy p = MakeSubsetPolicy();
  EXPECT_EQ(p.observation_dim(), 4);
  EXPECT_EQ(p.input_dim(), 3);
  EXPECT_EQ(p.InputRows(), (std::vector<int>{0, 2, 3}));
  PolicyEvaluator ev(p, /*chunk=*/4);
  EXPECT_EQ(ev.observation_dim(), 4);
  Rng rng(5);
  Eigen::MatrixXf x(4, 11);
  for (int c = 0; c < x.cols(); ++c)
    for (int r = 0; r < 4; ++r) x(r, c) = static_cast<float>(rng.Uniform(-3, 3));
  const Eigen::MatrixXf inputs = data::SelectRows(x, {0, 2, 3});
  const Eigen::MatrixXd expected = nn::ReferenceForward(p.mean, p.input, inputs);
  Eigen::VectorXf mu(2), mu_other_z(2);
  for (int c = 0; c < x.cols(); ++c) {
    ev.Mean(x.col(c), mu);
    EXPECT_NEAR(mu[0], expected(0, c), 1e-5);
    EXPECT_NEAR(mu[1], expected(1, c), 1e-5);
    // The feature it does not read changes nothing, bit for bit.
    Eigen::VectorXf other = x.col(c);
    other[1] += 100.0f;
    ev.Mean(other, mu_other_z);
    EXPECT_EQ(mu, mu_other_z);
  }
  // Batched, in chunks of 4.
  Eigen::MatrixXf mus(2, x.cols());
  ev.Means(x, mus);
  EXPECT_LT((mus.cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_HAS(ErrorOf([&] { ev.Mean(Eigen::VectorXf::Zero(3), mu); }), "expected 4");
}

TEST(GaussianPolicyTest, InputFeaturesMustBeKnownDistinctAndInObservationOrder) {
  EXPECT_NO_THROW(MakeSubsetPolicy().Validate("pi"));
  GaussianPolicy p = MakeSubsetPolicy();
  p.input_features = {"a", "q", "c"};
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "input feature 'q' is not an observation");
  p.input_features = {"b", "a", "c"};
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "'a' is repeated or out of the observation's");
  p.input_features = {"a", "a", "c"};
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "'a' is repeated");
  p.input_features = {"a", "b"};
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "2 input feature names for a network input of 3");
  p.input_features.clear();  // all four features: the network reads three
  EXPECT_HAS(ErrorOf([&] { p.Validate("pi"); }), "4 observation feature names");
}

TEST_F(GaussianPolicyFileTest, InputFeaturesRoundTripAndOnlyASubsetIsWritten) {
  const GaussianPolicy p = MakeSubsetPolicy();
  const std::string path = PathOf("subset.model");
  p.Save(path);
  const GaussianPolicy q = GaussianPolicy::Load(path);
  EXPECT_TRUE(BitEqual(p, q));
  EXPECT_EQ(q.input_features, p.input_features);
  EXPECT_EQ(nn::ReadModelFile(path).metadata["input_features"],
            nlohmann::json({"a", "b", "c"}));
  // A policy that reads every feature writes no such field, as before.
  MakePolicy().Save(PathOf("all.model"));
  EXPECT_FALSE(nn::ReadModelFile(PathOf("all.model")).metadata.contains("input_features"));
  EXPECT_TRUE(GaussianPolicy::Load(PathOf("all.model")).input_features.empty());
}

TEST(PolicyEvaluatorTest, WrongDimensionsThrow) {
  PolicyEvaluator ev(MakePolicy());
  Eigen::VectorXf mu(2), bad_mu(3);
  EXPECT_HAS(ErrorOf([&] { ev.Mean(Eigen::VectorXf::Zero(2), mu); }), "expected 3");
  EXPECT_HAS(ErrorOf([&] { ev.Mean(Eigen::VectorXf::Zero(3), bad_mu); }), "expected 2");
  Eigen::MatrixXf mus(2, 4);
  EXPECT_HAS(ErrorOf([&] { ev.Means(Eigen::MatrixXf::Zero(3, 5), mus); }), "expected 2 x 5");
}

TEST(PolicyEvaluatorTest, SampleStatistics) {
  const GaussianPolicy p = MakePolicy();
  PolicyEvaluator ev(p);
  const Eigen::VectorXf o = Vec({0.3f, -0.7f, 1.1f});
  Eigen::VectorXf mu(2), a(2);
  ev.Mean(o, mu);
  Rng rng(11);
  const int n = 200000;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero(), sum2 = Eigen::Vector2d::Zero();
  for (int i = 0; i < n; ++i) {
    ev.Sample(o, rng, a);
    const Eigen::Vector2d d = (a - mu).cast<double>();
    sum += d;
    sum2 += d.cwiseProduct(d);
  }
  const Eigen::Vector2d mean = sum / n;
  const Eigen::Vector2d sd = (sum2 / n - mean.cwiseProduct(mean)).cwiseSqrt();
  for (int i = 0; i < 2; ++i) {
    const double sigma = std::exp(double{p.log_std[i]});
    EXPECT_NEAR(mean[i], 0.0, 5.0 * sigma / std::sqrt(double{n})) << i;
    EXPECT_NEAR(sd[i], sigma, 0.01 * sigma) << i;
  }
  // Same Rng state, same draws.
  Rng r1(5), r2(5);
  Eigen::VectorXf a1(2), a2(2);
  ev.Sample(o, r1, a1);
  ev.Sample(o, r2, a2);
  EXPECT_EQ(a1, a2);
}

TEST(PolicyEvaluatorTest, LogProbIsTheGaussianDensity) {
  const GaussianPolicy p = MakePolicy();
  PolicyEvaluator ev(p);
  const Eigen::VectorXf o = Vec({0.1f, 0.2f, 0.3f});
  Eigen::VectorXf mu(2);
  ev.Mean(o, mu);
  const Eigen::VectorXf a = Vec({mu[0] + 0.5f, mu[1] - 1.0f});
  double expected = 0.0;
  for (int i = 0; i < 2; ++i) {
    const double s = std::exp(double{p.log_std[i]});
    const double z = (a[i] - mu[i]) / s;
    expected += -0.5 * z * z - std::log(s) - 0.5 * std::log(2 * M_PI);
  }
  EXPECT_NEAR(ev.LogProb(o, a), expected, 1e-5);
  EXPECT_NEAR(GaussianLogDensity(a, mu, p.log_std), expected, 1e-6);
}

}  // namespace
}  // namespace secure::policy
