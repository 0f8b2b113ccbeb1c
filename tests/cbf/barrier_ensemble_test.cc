// MinBarrier (min_barrier.h) and the barrier ensemble's model file (BarrierNet::more_members,
// kind "barrier_ensemble").
#include "secure/cbf/min_barrier.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "secure/cbf/barrier_net.h"
#include "secure/common/error.h"
#include "secure/nn/model_file.h"

namespace secure::cbf {
namespace {

using secure::test::ErrorOf;

std::string TempPath(const std::string& name) {
  const auto dir = std::filesystem::path(::testing::TempDir()) / "secure_barrier_ensemble_test";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

// h(s) = w . s + b with an analytic gradient w.
class Affine final : public Barrier {
 public:
  Affine(Eigen::Vector2f w, float b) : w_(w), b_(b) {}
  int state_dim() const override { return 2; }
  std::string Describe() const override { return "affine"; }
  bool analytic_gradient() const override { return true; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& s,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    h = (w_.transpose() * s).transpose().array() + b_;
  }
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& s,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> g) override {
    DoEvaluate(s, h);
    g.colwise() = w_;
  }

 private:
  Eigen::Vector2f w_;
  float b_;
};

// h(s) = s0 without an analytic gradient (Barrier's finite differences).
class FirstRow final : public Barrier {
 public:
  int state_dim() const override { return 2; }
  std::string Describe() const override { return "first row"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& s,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    h = s.row(0).transpose();
  }
};

std::vector<std::unique_ptr<Barrier>> TwoAffine() {
  std::vector<std::unique_ptr<Barrier>> m;
  m.push_back(std::make_unique<Affine>(Eigen::Vector2f(1, 0), 0.0f));   // h0 = x
  m.push_back(std::make_unique<Affine>(Eigen::Vector2f(0, 2), -1.0f));  // h1 = 2 y - 1
  return m;
}

TEST(MinBarrierTest, MinimumAndTheArgMinMembersGradient) {
  MinBarrier b(TwoAffine(), /*chunk=*/2);  // 3 states: two chunks
  EXPECT_TRUE(b.analytic_gradient());
  EXPECT_EQ(b.Describe(), "min of 2 affine");
  Eigen::MatrixXf s(2, 3);
  s << 0.5f, 3.0f, 1.0f,  //
      2.0f, 0.0f, 1.0f;   // h0 = 0.5, 3, 1; h1 = 3, -1, 1 (a tie)
  Eigen::VectorXf h(3);
  b.Evaluate(s, h);
  EXPECT_EQ(h, Eigen::Vector3f(0.5f, -1.0f, 1.0f));
  Eigen::MatrixXf g(2, 3);
  Eigen::VectorXf hg(3);
  b.EvaluateGradient(s, hg, g);
  EXPECT_EQ(hg, h);
  EXPECT_EQ(g.col(0), Eigen::Vector2f(1, 0));  // member 0 is the least
  EXPECT_EQ(g.col(1), Eigen::Vector2f(0, 2));  // member 1 is the least
  EXPECT_EQ(g.col(2), Eigen::Vector2f(1, 0));  // a tie: the first member
  Eigen::VectorXf dense(3);
  b.EvaluateDense(s, dense);
  EXPECT_EQ(dense, h);
}

TEST(MinBarrierTest, ANonAnalyticMemberGivesFiniteDifferencesOfTheMinimum) {
  std::vector<std::unique_ptr<Barrier>> m = TwoAffine();
  m.push_back(std::make_unique<FirstRow>());
  MinBarrier b(std::move(m));
  EXPECT_FALSE(b.analytic_gradient());
  EXPECT_EQ(b.Describe(), "min of 3 barriers (affine; affine; first row)");
  Eigen::MatrixXf s(2, 1);
  s << 4.0f, 0.25f;  // h = min(4, -0.5, 4) = -0.5 from member 1: gradient (0, 2)
  Eigen::VectorXf h(1);
  Eigen::MatrixXf g(2, 1);
  b.EvaluateGradient(s, h, g);
  EXPECT_FLOAT_EQ(h[0], -0.5f);
  EXPECT_NEAR(g(0, 0), 0.0f, 1e-3f);
  EXPECT_NEAR(g(1, 0), 2.0f, 1e-3f);
}

TEST(MinBarrierTest, RejectsMembersOfDifferentWidths) {
  std::vector<std::unique_ptr<Barrier>> m = TwoAffine();
  BarrierNet net;
  net.mlp = nn::RandomMlpParams({3, {4}, 1, nn::Activation::kTanh}, 1);
  net.normalizer = nn::Normalizer::Identity(3);
  net.features = {"a", "b", "c"};
  m.push_back(net.MakeEvaluator());
  const std::string msg = ErrorOf([&] { MinBarrier b(std::move(m)); });
  EXPECT_NE(msg.find("member 2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("reads 3 state rows, member 0 2"), std::string::npos) << msg;
  EXPECT_NE(ErrorOf([] { MinBarrier b({}); }).find("no member"), std::string::npos);
}

BarrierMember RandomMember(int dim, std::vector<int> hidden, unsigned long long seed) {
  BarrierMember m;
  m.mlp = nn::RandomMlpParams({dim, std::move(hidden), 1, nn::Activation::kTanh}, seed);
  Eigen::MatrixXf samples = Eigen::MatrixXf::Random(dim, 40) * 2.0f;
  m.normalizer = nn::Normalizer::Fit(samples);
  return m;
}

BarrierNet Ensemble(int k, int dim = 3) {
  BarrierNet net;
  const BarrierMember first = RandomMember(dim, {8, 8}, 1);
  net.mlp = first.mlp;
  net.normalizer = first.normalizer;
  for (int i = 1; i < k; ++i) net.more_members.push_back(RandomMember(dim, {8, 8}, 1 + i));
  for (int i = 0; i < dim; ++i) net.features.push_back("f" + std::to_string(i));
  net.provenance = {{"note", "ensemble"}};
  return net;
}

std::string Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

TEST(BarrierEnsembleTest, EvaluatorIsTheMinimumOverTheMembers) {
  const BarrierNet net = Ensemble(3);
  const std::unique_ptr<Barrier> b = net.MakeEvaluator(/*chunk=*/16);
  EXPECT_EQ(b->Describe(), "min of 3 barrier_mlp 3-8-8-1 tanh");
  EXPECT_TRUE(b->analytic_gradient());
  const Eigen::MatrixXf s = Eigen::MatrixXf::Random(3, 50) * 3.0f;
  Eigen::VectorXf h(50), hk(50), least = Eigen::VectorXf::Constant(50, 1e30f);
  b->Evaluate(s, h);
  for (int k = 0; k < 3; ++k) {
    BarrierNetEvaluator(net.Member(k), 16).Evaluate(s, hk);
    least = least.cwiseMin(hk);
  }
  EXPECT_EQ(h, least);  // the same member forwards, chunked alike: the same floats
  // On wider states by feature name, as every command evaluates it.
  Eigen::MatrixXf wide(4, 50);
  wide << Eigen::RowVectorXf::Zero(50), s.row(2), s.row(0), s.row(1);
  Eigen::VectorXf h_wide(50);
  net.MakeEvaluatorFor({"x", "f2", "f0", "f1"}, "wide", "m", 16)->Evaluate(wide, h_wide);
  EXPECT_EQ(h_wide, h);
}

TEST(BarrierEnsembleTest, FileRoundTripIsExactAndDeterministic) {
  const BarrierNet net = Ensemble(3);
  const std::string path = TempPath("ensemble.model"), again = TempPath("again.model");
  net.Save(path);
  EXPECT_EQ(nn::ReadModelFile(path).kind, kBarrierEnsembleModelKind);
  const BarrierNet loaded = BarrierNet::Load(path);
  ASSERT_EQ(loaded.members(), 3);
  EXPECT_EQ(loaded.features, net.features);
  EXPECT_EQ(loaded.provenance["note"], "ensemble");
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(loaded.Member(k).mlp.layers[1].weight, net.Member(k).mlp.layers[1].weight);
    EXPECT_EQ(loaded.Member(k).normalizer.scale, net.Member(k).normalizer.scale);
  }
  loaded.Save(again);
  EXPECT_EQ(Bytes(again), Bytes(path));
  // One member is today's file kind.
  const std::string single = TempPath("single.model");
  Ensemble(1).Save(single);
  EXPECT_EQ(nn::ReadModelFile(single).kind, kBarrierModelKind);
  EXPECT_EQ(BarrierNet::Load(single).members(), 1);
}

// `edit` applied to a saved 3-member ensemble's file; Load's message must name the file and
// contain `expected`.
void ExpectLoadError(const std::string& name, const std::function<void(nn::ModelFile&)>& edit,
                     const std::string& expected) {
  const std::string path = TempPath(name);
  Ensemble(3).Save(path);
  nn::ModelFile file = nn::ReadModelFile(path);
  edit(file);
  nn::WriteModelFile(path, file);
  const std::string msg = ErrorOf([&] { BarrierNet::Load(path); });
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find(expected), std::string::npos) << msg;
}

TEST(BarrierEnsembleTest, MalformedFilesNameTheFileAndField) {
  ExpectLoadError("no_members.model", [](nn::ModelFile& f) { f.metadata.erase("members"); },
                  "metadata field 'members' is missing or not an integer");
  ExpectLoadError("one_member.model", [](nn::ModelFile& f) { f.metadata["members"] = 1; },
                  "metadata field 'members' = 1, must be in [2, 64]");
  ExpectLoadError("text_members.model", [](nn::ModelFile& f) { f.metadata["members"] = "3"; },
                  "'members' is missing or not an integer");
  // Says 4 members, holds 3: member 3's tensors are missing.
  ExpectLoadError("four.model", [](nn::ModelFile& f) { f.metadata["members"] = 4; }, "barrier3");
  // Says 2, holds 3: tensors no reader uses.
  ExpectLoadError("two.model", [](nn::ModelFile& f) { f.metadata["members"] = 2; },
                  "holds 24 tensors, but its 2 member(s) have 16");
  // Member 2 reads 4 inputs where the features (and member 0) are 3.
  ExpectLoadError(
      "wide_member.model",
      [](nn::ModelFile& f) {
        std::vector<nn::NamedTensor> kept;
        for (nn::NamedTensor& t : f.tensors)
          if (t.name.rfind("barrier2.", 0) != 0 && t.name.rfind("input2.", 0) != 0)
            kept.push_back(std::move(t));
        f.tensors = std::move(kept);
        f.metadata.erase("barrier2");
        const BarrierMember wide = RandomMember(4, {8, 8}, 9);
        nn::AddMlp("barrier2", wide.mlp, &f);
        nn::AddNormalizer("input2", wide.normalizer, &f);
      },
      "member 2: network input is 4, member 0's is 3");
}

TEST(BarrierEnsembleTest, ValidateNamesTheMember) {
  BarrierNet net = Ensemble(2);
  net.more_members[0].normalizer = nn::Normalizer::Identity(2);
  const std::string msg = ErrorOf([&] { net.Validate("m.model"); });
  EXPECT_NE(msg.find("m.model member 1"), std::string::npos) << msg;
  EXPECT_NE(ErrorOf([&] { net.Save(TempPath("bad.model")); }).find("member 1"),
            std::string::npos);
}

}  // namespace
}  // namespace secure::cbf
