// AIRL's reward model (secure/policy/airl_reward.h): the file, and Q = g(s) + gamma V(s+) as the
// shield's task value.
#include "secure/policy/airl_reward.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/model_file.h"
#include "tests/test_util.h"

namespace secure::policy {
namespace {

using secure::test::ErrorOf;

// Reads features a, b, c; with `inputs` only those (e.g. {"a", "c"}).
AirlRewardModel MakeModel(std::vector<std::string> inputs = {}) {
  AirlRewardModel m;
  const int in = inputs.empty() ? 3 : static_cast<int>(inputs.size());
  m.reward = nn::RandomMlpParams(nn::MlpSpec{in, {8, 8}, 1, nn::Activation::kRelu}, 1);
  m.shaping = nn::RandomMlpParams(nn::MlpSpec{in, {6}, 1, nn::Activation::kRelu}, 2);
  m.input.mean = Eigen::VectorXf::LinSpaced(in, -0.2f, 0.3f);
  m.input.scale = Eigen::VectorXf::LinSpaced(in, 0.5f, 2.0f);
  m.discount = 0.9;
  m.observation_features = {"a", "b", "c"};
  m.input_features = std::move(inputs);
  m.provenance = {{"trainer", "test"}};
  return m;
}

// Q = g(s) + discount V(s+) in double precision, columns of `next` (every feature, or the rows
// `rows`).
std::vector<double> ReferenceQ(const AirlRewardModel& m, const Eigen::VectorXf& state,
                               const Eigen::MatrixXf& next, const std::vector<int>& rows) {
  const auto pick = [&](const Eigen::MatrixXf& x) {
    if (rows.empty()) return x;
    Eigen::MatrixXf out(static_cast<Eigen::Index>(rows.size()), x.cols());
    for (std::size_t k = 0; k < rows.size(); ++k)
      out.row(static_cast<Eigen::Index>(k)) = x.row(rows[k]);
    return out;
  };
  const double g = nn::ReferenceForward(m.reward, m.input, pick(state))(0, 0);
  const Eigen::MatrixXd v = nn::ReferenceForward(m.shaping, m.input, pick(next));
  std::vector<double> q;
  for (Eigen::Index i = 0; i < next.cols(); ++i) q.push_back(g + m.discount * v(0, i));
  return q;
}

TEST(AirlActionValueTest, IsTheRewardOfTheStatePlusTheDiscountedShapingOfTheNextState) {
  for (const std::vector<std::string>& inputs :
       {std::vector<std::string>{}, std::vector<std::string>{"a", "c"}}) {
    SCOPED_TRACE(inputs.empty() ? "all features" : "features a, c");
    const AirlRewardModel m = MakeModel(inputs);
    AirlActionValue value(m, {"a", "b", "c"}, 64);
    Rng rng(3);
    Eigen::VectorXf state(3);
    Eigen::MatrixXf next(3, 64);
    for (int r = 0; r < 3; ++r) state[r] = static_cast<float>(rng.Uniform(-1, 1));
    for (int c = 0; c < 64; ++c)
      for (int r = 0; r < 3; ++r) next(r, c) = static_cast<float>(rng.Uniform(-1, 1));
    for (int n : {1, 7, 64}) {
      Eigen::VectorXd q(n);
      value.Evaluate(state, next.leftCols(n), q);
      const std::vector<double> expected = ReferenceQ(
          m, state, next.leftCols(n), inputs.empty() ? std::vector<int>{} : std::vector<int>{0, 2});
      for (int i = 0; i < n; ++i) EXPECT_NEAR(q[i], expected[i], 1e-5) << "column " << i;
    }
    // A feature the networks do not read leaves Q unchanged.
    if (!inputs.empty()) {
      Eigen::MatrixXf moved = next.leftCols(4);
      moved.row(1).setConstant(7.0f);
      Eigen::VectorXd q1(4), q2(4);
      value.Evaluate(state, next.leftCols(4), q1);
      value.Evaluate(state, moved, q2);
      EXPECT_EQ(q1, q2);
    }
  }
}

TEST(AirlActionValueTest, RejectsOtherStatesAndTooManyColumns) {
  const AirlRewardModel m = MakeModel();
  EXPECT_HAS(ErrorOf([&] {
               AirlActionValue value(m, {"a", "c", "b"}, 8);
             }),
             "the shield's states are (a, c, b)");
  AirlActionValue value(m, {"a", "b", "c"}, 8);
  Eigen::VectorXd q(9);
  EXPECT_HAS(
      ErrorOf([&] { value.Evaluate(Eigen::VectorXf::Zero(3), Eigen::MatrixXf::Zero(3, 9), q); }),
      "9 next states (at most 8)");
  Eigen::VectorXd q2(2);
  EXPECT_HAS(
      ErrorOf([&] { value.Evaluate(Eigen::VectorXf::Zero(2), Eigen::MatrixXf::Zero(2, 2), q2); }),
      "expected 3");
}

class AirlRewardFileTest : public secure::test::TempDirTest {};

TEST_F(AirlRewardFileTest, SaveLoadRoundTripKeepsEveryByte) {
  for (const std::vector<std::string>& inputs :
       {std::vector<std::string>{}, std::vector<std::string>{"b"}}) {
    const AirlRewardModel m = MakeModel(inputs);
    const std::string path = PathOf("r.model"), again = PathOf("r2.model");
    m.Save(path);
    const AirlRewardModel back = AirlRewardModel::Load(path);
    EXPECT_EQ(back.observation_features, m.observation_features);
    EXPECT_EQ(back.input_features, m.input_features);
    EXPECT_EQ(back.discount, 0.9);
    EXPECT_EQ(back.provenance["trainer"], "test");
    back.Save(again);
    EXPECT_EQ(ReadFile(path), ReadFile(again));
    const nn::ModelFile file = nn::ReadModelFile(path);
    EXPECT_EQ(file.kind, kAirlRewardKind);
    EXPECT_NO_THROW(file.Tensor("reward.layer0.weight"));
    EXPECT_NO_THROW(file.Tensor("shaping.layer1.bias"));
    EXPECT_NO_THROW(file.Tensor("input.scale"));
    EXPECT_EQ(file.metadata.contains("input_features"), !inputs.empty());
  }
}

TEST_F(AirlRewardFileTest, BrokenFilesAreRejectedNamingTheFileAndField) {
  const std::string path = PathOf("r.model");
  MakeModel().Save(path);
  std::string bytes = ReadFile(path);
  bytes[bytes.size() / 2] ^= 0x5a;
  WriteFileAtomically(path, bytes);
  EXPECT_HAS(ErrorOf([&] { AirlRewardModel::Load(path); }), path);

  // Another kind of model.
  nn::ModelFile other;
  other.kind = "gaussian_policy";
  nn::AddMlp("mean", MakeModel().reward, &other);
  nn::WriteModelFile(path, other);
  EXPECT_HAS(ErrorOf([&] { AirlRewardModel::Load(path); }), "expected 'airl_reward'");

  // A discount out of range or missing, and a feature list that does not fit the networks.
  const auto write = [&](const AirlRewardModel& m, const nlohmann::json& discount) {
    nn::ModelFile f;
    f.kind = kAirlRewardKind;
    f.metadata["observation_features"] = m.observation_features;
    if (!discount.is_null()) f.metadata["discount"] = discount;
    nn::AddMlp("reward", m.reward, &f);
    nn::AddMlp("shaping", m.shaping, &f);
    nn::AddNormalizer("input", m.input, &f);
    nn::WriteModelFile(path, f);
  };
  write(MakeModel(), 1.5);
  EXPECT_HAS(ErrorOf([&] { AirlRewardModel::Load(path); }), "discount = 1.5, must be in [0, 1]");
  write(MakeModel(), nlohmann::json());
  EXPECT_HAS(ErrorOf([&] { AirlRewardModel::Load(path); }), "'discount' is missing");
  AirlRewardModel wrong = MakeModel();
  wrong.observation_features = {"a", "b"};
  write(wrong, 0.99);
  EXPECT_HAS(ErrorOf([&] { AirlRewardModel::Load(path); }),
             "2 input feature names for a network input of 3");
  AirlRewardModel unknown = MakeModel({"z"});
  EXPECT_HAS(ErrorOf([&] { unknown.Validate(); }), "input feature 'z' is unknown");
}

}  // namespace
}  // namespace secure::policy
