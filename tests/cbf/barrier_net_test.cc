#include "secure/cbf/barrier_net.h"
#include "domains/double_integrator/ground_truth_barrier.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "secure/common/error.h"
#include "secure/nn/model_file.h"

namespace secure::cbf {
namespace {

std::string TempPath(const std::string& name) {
  const auto dir = std::filesystem::path(::testing::TempDir()) / "secure_barrier_net_test";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

BarrierNet MakeNet(int dim, std::vector<int> hidden, nn::Activation act, unsigned long long seed) {
  BarrierNet net;
  nn::MlpSpec spec{dim, std::move(hidden), 1, act};
  net.mlp = nn::RandomMlpParams(spec, seed);
  Eigen::MatrixXf samples = Eigen::MatrixXf::Random(dim, 50) * 3.0f;
  samples.array() += 2.0f;
  net.normalizer = nn::Normalizer::Fit(samples);
  for (int i = 0; i < dim; ++i) net.features.push_back("f" + std::to_string(i));
  return net;
}

using secure::test::ErrorOf;

TEST(BarrierNetTest, EvaluatorMatchesDoublePrecisionReference) {
  const BarrierNet net = MakeNet(4, {16, 16}, nn::Activation::kTanh, 3);
  const Eigen::MatrixXf states = Eigen::MatrixXf::Random(4, 300) * 5.0f;
  Eigen::VectorXf h(300);
  net.MakeEvaluator()->Evaluate(states, h);
  const Eigen::MatrixXd ref = nn::ReferenceForward(net.mlp, net.normalizer, states);
  EXPECT_LT((h.cast<double>() - ref.row(0).transpose()).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(BarrierNetTest, ChunkedEvaluationEqualsOneBatch) {
  const BarrierNet net = MakeNet(3, {8}, nn::Activation::kRelu, 4);
  const Eigen::MatrixXf states = Eigen::MatrixXf::Random(3, 1000);
  Eigen::VectorXf whole(1000), chunked(1000);
  net.MakeEvaluator(4096)->Evaluate(states, whole);
  net.MakeEvaluator(7)->Evaluate(states, chunked);  // 142 full chunks and a partial one
  EXPECT_LT((whole - chunked).cwiseAbs().maxCoeff(), 1e-6f);
}

TEST(BarrierNetTest, SaveLoadRoundTripIsExact) {
  BarrierNet net = MakeNet(5, {7, 3}, nn::Activation::kTanh, 5);
  net.provenance = {{"note", "round trip"}};
  const std::string path = TempPath("roundtrip.model");
  net.Save(path);
  const BarrierNet loaded = BarrierNet::Load(path);
  EXPECT_EQ(loaded.features, net.features);
  nn::test::ExpectSameMlp(loaded.mlp, loaded.normalizer, net.mlp, net.normalizer);
  EXPECT_EQ(loaded.provenance["note"], "round trip");
  const Eigen::MatrixXf states = Eigen::MatrixXf::Random(5, 20);
  Eigen::VectorXf a(20), b(20);
  net.MakeEvaluator()->Evaluate(states, a);
  loaded.MakeEvaluator()->Evaluate(states, b);
  EXPECT_EQ(a, b);
}

TEST(BarrierNetTest, LoadRejectsAModelOfAnotherKind) {
  nn::ModelFile file;
  file.kind = "gaussian_policy";
  nn::AddMlp("barrier", nn::RandomMlpParams({2, {3}, 1, nn::Activation::kRelu}, 1), &file);
  const std::string path = TempPath("policy.model");
  nn::WriteModelFile(path, file);
  const std::string msg = ErrorOf([&] { BarrierNet::Load(path); });
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find("gaussian_policy"), std::string::npos) << msg;
}

TEST(BarrierNetTest, LoadRejectsACorruptFileNamingIt) {
  const std::string path = TempPath("corrupt.model");
  MakeNet(2, {4}, nn::Activation::kTanh, 6).Save(path);
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes[bytes.size() - 30] ^= 0x40;  // a payload byte
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << bytes;
  }
  const std::string msg = ErrorOf([&] { BarrierNet::Load(path); });
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find("checksum"), std::string::npos) << msg;
}

TEST(BarrierNetTest, CheckFeaturesNamesBothSides) {
  const BarrierNet net = MakeNet(2, {4}, nn::Activation::kTanh, 7);
  EXPECT_NO_THROW(net.CheckFeatures({"f0", "f1"}, "data.csv"));
  const std::string msg = ErrorOf([&] {
    net.CheckFeatures({"f0", "x", "y"}, "data.csv", "m.bin");
  });
  EXPECT_NE(msg.find("data.csv has 3 features (f0, x, y)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("m.bin expects 2 (f0, f1)"), std::string::npos) << msg;
}

TEST(BarrierNetTest, MakeEvaluatorForEqualFeaturesIsThePlainEvaluator) {
  const BarrierNet net = MakeNet(3, {8}, nn::Activation::kTanh, 12);
  const std::unique_ptr<Barrier> plain = net.MakeEvaluator();
  const std::unique_ptr<Barrier> same = net.MakeEvaluatorFor(net.features, "data.csv");
  EXPECT_NE(dynamic_cast<BarrierNetEvaluator*>(same.get()), nullptr);  // no wrapper
  EXPECT_EQ(same->Describe(), plain->Describe());
  const Eigen::MatrixXf states = Eigen::MatrixXf::Random(3, 100) * 4.0f;
  Eigen::VectorXf a(100), b(100);
  plain->Evaluate(states, a);
  same->Evaluate(states, b);
  EXPECT_EQ(a, b);
}

// A 3-feature model on 6-row states whose rows hold its features in another order, among others.
TEST(BarrierNetTest, MakeEvaluatorForPicksTheModelsFeaturesByName) {
  const BarrierNet net = MakeNet(3, {8, 8}, nn::Activation::kTanh, 13);  // f0, f1, f2
  const std::vector<std::string> wide = {"a", "f2", "b", "f0", "c", "f1"};
  const Eigen::MatrixXf states = Eigen::MatrixXf::Random(6, 1000) * 4.0f;
  Eigen::MatrixXf projected(3, 1000);
  projected.row(0) = states.row(3);
  projected.row(1) = states.row(5);
  projected.row(2) = states.row(1);
  for (int chunk : {4096, 7, 1}) {  // one batch; 142 full chunks and a partial one; one by one
    Eigen::VectorXf expected(1000);
    net.MakeEvaluator(chunk)->Evaluate(projected, expected);
    const std::unique_ptr<Barrier> evaluator = net.MakeEvaluatorFor(wide, "wide.csv", "m", chunk);
    EXPECT_EQ(evaluator->state_dim(), 6);
    EXPECT_NE(evaluator->Describe().find("on 3 of 6 state rows"), std::string::npos)
        << evaluator->Describe();
    Eigen::VectorXf h(1000);
    evaluator->Evaluate(states, h);
    EXPECT_EQ(h, expected) << "chunk " << chunk;
  }
  // The wide evaluator checks the wide dimension.
  Eigen::VectorXf h(10);
  EXPECT_THROW(net.MakeEvaluatorFor(wide, "wide.csv")->Evaluate(Eigen::MatrixXf::Zero(3, 10), h),
               Error);
}

TEST(BarrierNetTest, MakeEvaluatorForNamesTheFirstMissingFeature) {
  const BarrierNet net = MakeNet(3, {4}, nn::Activation::kTanh, 14);  // f0, f1, f2
  const std::string msg = ErrorOf([&] {
    net.MakeEvaluatorFor({"f0", "x", "f2", "y"}, "the toy domain", "m.bin");
  });
  EXPECT_NE(msg.find("the toy domain has 4 features (f0, x, f2, y)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("without 'f1', which m.bin reads (3: f0, f1, f2)"), std::string::npos)
      << msg;
}

TEST(SelectRowsTest, RejectsInconsistentRows) {
  const BarrierNet net = MakeNet(2, {4}, nn::Activation::kTanh, 15);
  EXPECT_NE(ErrorOf([&] { SelectRows(net.MakeEvaluator(), 4, {0}); }).find("1 rows for"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SelectRows(net.MakeEvaluator(), 4, {0, 4}); })
                .find("rows[1] = 4, must be in [0, 4)"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SelectRows(net.MakeEvaluator(), 4, {0, 1}, 0); }).find("chunk = 0"),
            std::string::npos);
}

TEST(BarrierNetTest, ValidateRejectsInconsistentParts) {
  BarrierNet net = MakeNet(3, {4}, nn::Activation::kTanh, 8);
  net.features.pop_back();
  EXPECT_NE(ErrorOf([&] { net.Validate(); }).find("2 feature names for a network input of 3"),
            std::string::npos);
  net = MakeNet(3, {4}, nn::Activation::kTanh, 8);
  net.normalizer = nn::Normalizer::Identity(2);
  EXPECT_NE(ErrorOf([&] { net.Validate(); }).find("normalizer has dimension 2"), std::string::npos);
  net = MakeNet(3, {4}, nn::Activation::kTanh, 8);
  net.mlp = nn::RandomMlpParams({3, {4}, 2, nn::Activation::kTanh}, 1);
  EXPECT_NE(ErrorOf([&] { net.Validate(); }).find("2 outputs, expected 1"), std::string::npos);
}

TEST(BarrierNetTest, EvaluateChecksDimensions) {
  auto barrier = MakeNet(4, {4}, nn::Activation::kTanh, 9).MakeEvaluator();
  Eigen::VectorXf h(10);
  EXPECT_THROW(barrier->Evaluate(Eigen::MatrixXf::Zero(3, 10), h), Error);
  Eigen::VectorXf wrong(9);
  EXPECT_THROW(barrier->Evaluate(Eigen::MatrixXf::Zero(4, 10), wrong), Error);
}

TEST(GroundTruthBarrierTest, MatchesTheDomainFormula) {
  domains::double_integrator::GroundTruth truth;
  truth.obstacle_x = 3;
  truth.obstacle_y = 7;
  truth.radius = 1.2;
  truth.gamma = 0.5;
  domains::double_integrator::GroundTruthBarrier barrier(truth);
  Eigen::MatrixXf states(4, 3);
  states << 3, 0, 5, 7, 1, 8, 0, 1, -1, 0, -1, 1;
  Eigen::VectorXf h(3);
  barrier.Evaluate(states, h);
  for (int i = 0; i < 3; ++i) {
    const double dx = states(0, i) - 3.0, dy = states(1, i) - 7.0;
    const double expected =
        0.5 * (dx * dx + dy * dy - 1.44) + 2.0 * (dx * states(2, i) + dy * states(3, i));
    EXPECT_NEAR(h[i], expected, 1e-5);
  }
  EXPECT_LT(h[0], 0.0f);  // at the obstacle centre
}

}  // namespace
}  // namespace secure::cbf
