#include "secure/cbf/car_barrier.h"
#include "tests/cbf/synthetic_derby_observations.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numeric>
#include <vector>

#include "domains/derby/domain.h"
#include "secure/cbf/barrier.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/model_file.h"

namespace secure::cbf {
namespace {

using secure::test::ErrorOf;

using test::kCars;
using test::kObs;

// The Demolition Derby observation layout (the derby plug-in's): 52 values, 12 blocks of 4 from 4.
ObstacleLayout DerbyLayout() { return domains::derby::ObstacleLayoutOfObservation(); }

// Random Derby-layout observations: cars at distances drawn from [min_dist, max_dist], sorted
// nearest first; random relative velocities, goal and ego velocity.
Eigen::MatrixXf RandomObservations(int n, double min_dist, double max_dist, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::MatrixXf obs(kObs, n);
  for (int i = 0; i < n; ++i) {
    const auto draw_car = [&](int) -> test::SyntheticCar {
      const double d = rng.Uniform(min_dist, max_dist), a = rng.Uniform(0, 2 * M_PI);
      return {static_cast<float>(d * std::cos(a)), static_cast<float>(d * std::sin(a)),
              static_cast<float>(rng.Uniform(-0.5, 0.5)), static_cast<float>(rng.Uniform(-0.5, 0.5))};
    };
    test::WriteSyntheticObservation(rng, draw_car, obs.col(i));
  }
  return obs;
}

CarBarrierNet RandomNet(bool use_velocity, std::uint64_t seed, double cap = 0.05) {
  CarBarrierNet net;
  net.input.layout = DerbyLayout();
  net.input.use_velocity = use_velocity;
  net.cap = cap;
  const int f = net.input.feature_dim();
  net.mlp = nn::RandomMlpParams({f, {16, 8}, 1, nn::Activation::kRelu}, seed);
  Eigen::MatrixXf samples = Eigen::MatrixXf::Random(f, 40);
  net.normalizer = nn::Normalizer::Fit(samples);
  return net;
}

// A tiny net with known weights: h_j = relu(dx) - 2 relu(d - r - 0.1) + 0.05 (identity
// normaliser).
CarBarrierNet HandNet() {
  CarBarrierNet net;
  net.input.layout = DerbyLayout();
  net.cap = 0.02;
  net.mlp.spec = {3, {2}, 1, nn::Activation::kRelu};
  nn::DenseLayer l0, l1;
  l0.weight = Eigen::MatrixXf::Zero(2, 3);
  l0.weight(0, 0) = 1.0f;
  l0.weight(1, 2) = 1.0f;
  l0.bias = Eigen::Vector2f(0.0f, -0.1f);
  l1.weight = Eigen::RowVector2f(1.0f, -2.0f);
  l1.bias = Eigen::VectorXf::Constant(1, 0.05f);
  net.mlp.layers = {l0, l1};
  net.normalizer = nn::Normalizer::Identity(3);
  return net;
}

double HandEntry(double dx, double dy) {
  const double d = std::sqrt(dx * dx + dy * dy + 2e-4);
  return std::max(dx, 0.0) - 2.0 * std::max(d - 0.07 - 0.1, 0.0) + 0.05;
}

Eigen::VectorXf Eval(const CarBarrierNet& net, const Eigen::MatrixXf& obs, int max_states = 256) {
  Eigen::VectorXf h(obs.cols());
  net.MakeEvaluator(max_states)->Evaluate(obs, h);
  return h;
}

std::string TempPath(const std::string& name) {
  const auto dir = std::filesystem::path(::testing::TempDir()) / "secure_car_barrier_test";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

TEST(CarBarrierTest, EvaluatorMatchesHandComputedForward) {
  const CarBarrierNet net = HandNet();
  // All cars in range; in the first 25 states so near that every h_j > cap.
  Eigen::MatrixXf obs(kObs, 50);
  obs << RandomObservations(25, 0.0, 0.18, 1), RandomObservations(25, 0.0, 0.9, 2);
  const Eigen::VectorXf h = Eval(net, obs);
  for (int i = 0; i < obs.cols(); ++i) {
    double expected = 0.02;
    for (int j = 0; j < kCars; ++j)
      expected = std::min(expected, HandEntry(obs(4 + 4 * j, i), obs(5 + 4 * j, i)));
    EXPECT_NEAR(h(i), expected, 1e-6) << "state " << i;
  }
  // The cap binds somewhere and the network elsewhere (the test exercises both).
  EXPECT_EQ((h.head(25).array() == 0.02f).count(), 25);
  EXPECT_GT((h.tail(25).array() < 0.0f).count(), 0);
}

TEST(CarBarrierTest, EntryValuesMatchReferenceForward) {
  const CarBarrierNet net = RandomNet(true, 2);
  const Eigen::MatrixXf obs = RandomObservations(20, 0.0, 1.4, 2);
  const Eigen::MatrixXf entries = net.EntryValues(obs);
  Eigen::MatrixXf features;
  Eigen::Matrix<bool, Eigen::Dynamic, 1> in_range;
  ComputeCarFeatures(net.input, obs, &features, &in_range);
  const Eigen::MatrixXd ref = nn::ReferenceForward(net.mlp, net.normalizer, features);
  for (int i = 0; i < 20; ++i) {
    float expected_h = static_cast<float>(net.cap);
    for (int j = 0; j < kCars; ++j) {
      if (in_range(i * kCars + j)) {
        EXPECT_NEAR(entries(j, i), ref(0, i * kCars + j), 1e-5);
        expected_h = std::min(expected_h, entries(j, i));
      } else {
        EXPECT_TRUE(std::isinf(entries(j, i)));
      }
    }
    EXPECT_NEAR(Eval(net, obs.col(i))(0), expected_h, 1e-6);
  }
}

TEST(CarBarrierTest, PermutationInvariantOverCarBlocks) {
  const CarBarrierNet net = RandomNet(true, 3);
  const Eigen::MatrixXf obs = RandomObservations(30, 0.0, 1.3, 3);
  Eigen::MatrixXf shuffled = obs;
  Rng rng(9);
  for (int i = 0; i < obs.cols(); ++i) {
    std::vector<int> perm(kCars);
    std::iota(perm.begin(), perm.end(), 0);
    Shuffle(perm.begin(), perm.end(), rng);
    for (int j = 0; j < kCars; ++j)
      shuffled.block(4 + 4 * j, i, 4, 1) = obs.block(4 + 4 * perm[j], i, 4, 1);
  }
  ASSERT_NE(shuffled, obs);
  const Eigen::VectorXf a = Eval(net, obs), b = Eval(net, shuffled);
  // Same entries, possibly a different column order inside the one GEMM: equal up to rounding.
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-6f);
}

TEST(CarBarrierTest, FarCarsAreIgnoredAndAllFarGivesTheCap) {
  const CarBarrierNet net = RandomNet(false, 4, /*cap=*/0.123);
  Eigen::MatrixXf obs = RandomObservations(10, 1.01, 3.0, 4);  // every car beyond R = 1
  EXPECT_TRUE((Eval(net, obs).array() == 0.123f).all());

  // One near car: h is its value (or the cap); moving a far car around changes nothing.
  Eigen::MatrixXf one = RandomObservations(10, 0.5, 3.0, 5);
  Eigen::MatrixXf moved = one;
  int changed = 0;
  for (int i = 0; i < one.cols(); ++i) {
    for (int j = 0; j < kCars; ++j) {
      const float dx = one(4 + 4 * j, i), dy = one(5 + 4 * j, i);
      // Clearly out of range only: the evaluator's distance is its own expression (-march=native
      // may fuse it differently), so a car within rounding of R is left alone.
      if (std::sqrt(dx * dx + dy * dy + 2e-4f) > 1.0f + 1e-5f) {
        moved(4 + 4 * j, i) = 5.0f * dx;  // still out of range
        moved(6 + 4 * j, i) += 1.0f;
        ++changed;
      }
    }
  }
  ASSERT_GT(changed, 0);
  EXPECT_EQ(Eval(net, one), Eval(net, moved));
  // Bringing a far car into range does change h in general (the mask is not a no-op).
  CarBarrierNet low_cap = net;
  low_cap.cap = 10.0;  // so that every in-range car's value shows
  Eigen::MatrixXf closer = one;
  closer.block(4 + 4 * (kCars - 1), 0, 2, one.cols()).setConstant(0.3f);
  EXPECT_NE(Eval(low_cap, one), Eval(low_cap, closer));
}

TEST(CarBarrierTest, NonFiniteObservationGivesNaN) {
  const CarBarrierNet net = RandomNet(false, 5);
  Eigen::MatrixXf obs = RandomObservations(3, 1.5, 2.0, 6);  // all far: h = cap
  obs(4 + 4 * 7, 1) = std::numeric_limits<float>::quiet_NaN();
  const Eigen::VectorXf h = Eval(net, obs);
  EXPECT_FLOAT_EQ(h(0), 0.05f);
  EXPECT_TRUE(std::isnan(h(1)));
  EXPECT_FLOAT_EQ(h(2), 0.05f);
}

TEST(CarBarrierTest, BatchChunkedAndSingleEvaluationAgree) {
  const CarBarrierNet net = RandomNet(true, 6);
  const Eigen::MatrixXf obs = RandomObservations(300, 0.0, 1.5, 7);
  const Eigen::VectorXf whole = Eval(net, obs, 512);
  const Eigen::VectorXf chunked = Eval(net, obs, 7);
  auto single = net.MakeEvaluator(1);
  Eigen::VectorXf one(1);
  float max_diff = 0.0f;
  for (int i = 0; i < obs.cols(); ++i) {
    single->Evaluate(obs.col(i), one);
    max_diff = std::max(max_diff, std::abs(one(0) - whole(i)));
  }
  EXPECT_LT(max_diff, 1e-6f);
  EXPECT_LT((whole - chunked).cwiseAbs().maxCoeff(), 1e-6f);
  // Wrong dimensions are rejected by the Barrier interface.
  Eigen::VectorXf h(3);
  EXPECT_THROW(net.MakeEvaluator()->Evaluate(Eigen::MatrixXf::Zero(51, 3), h), Error);
}

// EvaluateDense (the timing reference of `secure eval`) runs the network on every car, in range
// or not, and masks afterwards: the same h as Evaluate, including NaN and the all-far cap, with
// every entry evaluated.
TEST(CarBarrierTest, DenseEvaluationGivesTheSameValuesAndEvaluatesEveryCar) {
  const CarBarrierNet net = RandomNet(true, 8, /*cap=*/0.3);
  Eigen::MatrixXf obs = RandomObservations(40, 0.2, 2.5, 9);             // some cars in range
  obs.col(3) = RandomObservations(1, 1.2, 3.0, 10);                       // every car far: cap
  obs(4 + 4 * 5, 7) = std::numeric_limits<float>::quiet_NaN();            // NaN propagates
  auto evaluator = net.MakeEvaluator(16);  // chunks of 16 states, a partial last chunk
  auto* cars = dynamic_cast<CarBarrierEvaluator*>(evaluator.get());
  ASSERT_NE(cars, nullptr);
  Eigen::VectorXf sparse(obs.cols()), dense(obs.cols());
  evaluator->Evaluate(obs, sparse);
  const long sparse_entries = cars->last_entries();
  evaluator->EvaluateDense(obs, dense);
  EXPECT_EQ(cars->last_entries(), 8L * kCars);  // the last chunk: 40 = 16 + 16 + 8 states
  EXPECT_LT(sparse_entries, 8L * kCars);
  EXPECT_FLOAT_EQ(dense(3), 0.3f);
  EXPECT_TRUE(std::isnan(sparse(7)) && std::isnan(dense(7)));
  for (int i = 0; i < obs.cols(); ++i) {
    if (i == 7) continue;
    EXPECT_NEAR(dense(i), sparse(i), 1e-6f) << "state " << i;
  }
  // Wrong dimensions are rejected as by Evaluate.
  Eigen::VectorXf h(3);
  EXPECT_THROW(evaluator->EvaluateDense(Eigen::MatrixXf::Zero(51, 3), h), Error);

  // A row selection passes the dense evaluation on to the barrier it wraps.
  std::vector<int> rows(kObs);
  for (int r = 0; r < kObs; ++r) rows[static_cast<std::size_t>(r)] = r;
  SelectRows selected(std::move(evaluator), kObs, rows);
  Eigen::VectorXf through(obs.cols());
  selected.EvaluateDense(obs, through);
  EXPECT_EQ(cars->last_entries(), 8L * kCars);
  selected.Evaluate(obs, through);
  EXPECT_EQ(cars->last_entries(), sparse_entries);
}

TEST(CarBarrierTest, NonDefaultLayout) {
  // Blocks of 5 (vx, vy, px, py, pad) from offset 1, 3 cars, obs_dim 17.
  CarBarrierNet net = RandomNet(true, 7);
  net.input.layout = {17, 1, 5, 3, 2, 0};
  Eigen::MatrixXf obs = Eigen::MatrixXf::Random(17, 4) * 0.5f;
  Eigen::MatrixXf derby = Eigen::MatrixXf::Zero(kObs, 4);
  for (int j = 0; j < 3; ++j) {
    derby.block(4 + 4 * j, 0, 2, 4) = obs.block(1 + 5 * j + 2, 0, 2, 4);
    derby.block(6 + 4 * j, 0, 2, 4) = obs.block(1 + 5 * j, 0, 2, 4);
  }
  for (int j = 3; j < kCars; ++j) derby.block(4 + 4 * j, 0, 2, 4).setConstant(9.0f);  // far
  CarBarrierNet derby_net = net;
  derby_net.input.layout = DerbyLayout();
  EXPECT_LT((Eval(net, obs) - Eval(derby_net, derby)).cwiseAbs().maxCoeff(), 1e-6f);
}

TEST(CarBarrierTest, TheLayoutHasNoDefault) {
  // Generic code carries no domain's layout: the default is unset, and rejected by name.
  const ObstacleLayout unset;
  EXPECT_FALSE(unset.IsSet());
  EXPECT_TRUE(DerbyLayout().IsSet());
  const std::string e = ErrorOf([&] { unset.Validate("x"); });
  EXPECT_NE(e.find("x: layout.obs_dim = 0: the obstacle layout is unset and must be given"),
            std::string::npos)
      << e;
  CarBarrierNet net = RandomNet(false, 12);
  net.input.layout = {};
  EXPECT_NE(ErrorOf([&] { net.Validate("m"); }).find("m: layout.obs_dim = 0"), std::string::npos);
  EXPECT_THROW(net.MakeEvaluator(), Error);
  EXPECT_THROW(net.Save(TempPath("unset.model")), Error);
  // Options not bound to an observation accept it; a net's feature spec does not.
  EXPECT_NO_THROW(CarFeatureSpec{}.Validate("spec", /*allow_unset_layout=*/true));
  EXPECT_THROW(CarFeatureSpec{}.Validate("spec"), Error);
  // A layout with some fields set is set, and its other fields are checked.
  ObstacleLayout partial;
  partial.num_obstacles = 12;
  EXPECT_TRUE(partial.IsSet());
  EXPECT_NE(ErrorOf([&] { partial.Validate("x"); }).find("obs_dim = 0, must be > 0"),
            std::string::npos);
}

TEST(CarBarrierTest, LayoutValidationNamesTheField) {
  ObstacleLayout l = DerbyLayout();
  l.num_obstacles = 13;
  EXPECT_NE(ErrorOf([&] { l.Validate("x"); }).find("beyond layout.obs_dim = 52"),
            std::string::npos);
  l = DerbyLayout();
  l.velocity_offset = 1;
  EXPECT_NE(ErrorOf([&] { l.Validate("x"); }).find("velocity_offset = 1"), std::string::npos);
  l = DerbyLayout();
  l.position_offset = 3;
  EXPECT_NE(ErrorOf([&] { l.Validate("x"); }).find("position_offset = 3"), std::string::npos);
  CarBarrierNet net = RandomNet(true, 8);
  net.input.layout.velocity_offset = -1;
  EXPECT_NE(ErrorOf([&] { net.Validate("m"); }).find("use_velocity"), std::string::npos);
  net = RandomNet(false, 8);
  net.input.use_velocity = true;  // 3-input network for 5 features
  EXPECT_NE(ErrorOf([&] { net.Validate("m"); }).find("need 5"), std::string::npos);
  EXPECT_THROW(net.MakeEvaluator(), Error);
  EXPECT_THROW(RandomNet(false, 8).MakeEvaluator(0), Error);
}

TEST(CarBarrierTest, SaveLoadRoundTripIsBitwise) {
  CarBarrierNet net = RandomNet(true, 9, 0.07);
  net.input.layout = {60, 6, 4, 13, 0, 2};
  net.input.collision_radius = 0.05;
  net.input.sensing_radius = 1.25;
  net.input.distance_epsilon = 1e-4;
  net.provenance = {{"note", "round trip"}};
  for (int i = 0; i < 60; ++i) net.features.push_back("o" + std::to_string(i));
  const std::string path = TempPath("roundtrip.model");
  net.Save(path);
  const CarBarrierNet loaded = CarBarrierNet::Load(path);
  EXPECT_TRUE(loaded.input == net.input);
  EXPECT_EQ(loaded.cap, net.cap);
  EXPECT_EQ(loaded.features, net.features);
  nn::test::ExpectSameMlp(loaded.mlp, loaded.normalizer, net.mlp, net.normalizer);
  EXPECT_EQ(loaded.provenance["note"], "round trip");
  EXPECT_EQ(loaded.Describe(), net.Describe());
  const Eigen::MatrixXf obs = Eigen::MatrixXf::Random(60, 40);
  EXPECT_EQ(Eval(net, obs), Eval(loaded, obs));
}

// Rewrites the model file with `edit` applied to its parsed form.
template <typename Edit>
std::string Edited(const CarBarrierNet& net, const std::string& name, Edit edit) {
  const std::string path = TempPath(name);
  net.Save(path);
  nn::ModelFile file = nn::ReadModelFile(path);
  edit(file);
  nn::WriteModelFile(path, file);
  return path;
}

TEST(CarBarrierTest, LoadRejectsCorruptAndMismatchedFiles) {
  const CarBarrierNet net = RandomNet(false, 10);
  // Another model kind.
  std::string path = Edited(net, "kind.model", [](nn::ModelFile& f) { f.kind = "barrier_mlp"; });
  EXPECT_NE(ErrorOf([&] { CarBarrierNet::Load(path); }).find("expected 'car_barrier'"),
            std::string::npos);
  // A bad layout.
  path = Edited(net, "layout.model", [](nn::ModelFile& f) {
    f.metadata["input"]["layout"]["num_obstacles"] = 0;
  });
  std::string e = ErrorOf([&] { CarBarrierNet::Load(path); });
  EXPECT_NE(e.find("layout::num_obstacles = 0, must be > 0"), std::string::npos) << e;
  EXPECT_NE(e.find(path), std::string::npos) << e;
  // A missing field.
  path = Edited(net, "missing.model",
                [](nn::ModelFile& f) { f.metadata["input"].erase("sensing_radius"); });
  EXPECT_NE(ErrorOf([&] { CarBarrierNet::Load(path); }).find("'input.sensing_radius' is missing"),
            std::string::npos);
  // A non-numeric cap and a negative radius.
  path = Edited(net, "cap.model", [](nn::ModelFile& f) { f.metadata["cap"] = "big"; });
  EXPECT_NE(ErrorOf([&] { CarBarrierNet::Load(path); }).find("'cap'"), std::string::npos);
  path = Edited(net, "radius.model",
                [](nn::ModelFile& f) { f.metadata["input"]["collision_radius"] = -1.0; });
  EXPECT_NE(ErrorOf([&] { CarBarrierNet::Load(path); }).find("collision_radius = -1"),
            std::string::npos);
  // Velocity features declared for a 3-input network (shape mismatch).
  path = Edited(net, "vel.model",
                [](nn::ModelFile& f) { f.metadata["input"]["use_velocity"] = true; });
  EXPECT_NE(ErrorOf([&] { CarBarrierNet::Load(path); }).find("need 5"), std::string::npos);
  // A weight tensor of the wrong shape.
  path = Edited(net, "shape.model", [](nn::ModelFile& f) {
    for (auto& t : f.tensors)
      if (t.name == "car.layer0.weight") {
        t.shape = {16, 2};
        t.values.resize(32);
      }
  });
  EXPECT_NE(ErrorOf([&] { CarBarrierNet::Load(path); }).find("car.layer0.weight"),
            std::string::npos);
  // A flipped payload byte (checksum).
  path = TempPath("flip.model");
  net.Save(path);
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(0, std::ios::end);
    const auto size = static_cast<long>(f.tellg());
    f.seekp(size - 30);
    f.put('\x7f');
  }
  EXPECT_THROW(CarBarrierNet::Load(path), Error);
  // A non-finite weight cannot be saved.
  CarBarrierNet bad = net;
  bad.mlp.layers[1].bias(0) = std::numeric_limits<float>::infinity();
  EXPECT_THROW(bad.Save(TempPath("inf.model")), Error);
}

TEST(CarBarrierTest, CheckFeaturesAndDescribe) {
  CarBarrierNet net = RandomNet(false, 11);
  EXPECT_NO_THROW(net.CheckFeatures({"anything"}, "data.csv"));  // no names stored: unchecked
  for (int i = 0; i < kObs; ++i) net.features.push_back("o" + std::to_string(i));
  EXPECT_NO_THROW(net.CheckFeatures(net.features, "data.csv"));
  EXPECT_NE(ErrorOf([&] { net.CheckFeatures({"a", "b"}, "data.csv"); }).find("data.csv has 2"),
            std::string::npos);
  EXPECT_EQ(net.Describe(), "car_barrier 3-16-8-1 relu, 12 cars, r 0.07, R 1, cap 0.05, positions");
}

}  // namespace
}  // namespace secure::cbf
