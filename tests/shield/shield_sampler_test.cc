// ShieldOptions::sampler: how each round's M standard-normal vectors are drawn (iid, antithetic
// pairs, randomised QMC). The samples are observed through a dynamics model that records every
// batch the shield evaluates.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::FunctionBarrier;
using test::Vec;

/// x' = x + a * dt in `dim` dimensions; keeps a copy of every batch of actions it steps.
class RecordingDynamics final : public domains::DynamicsModel {
 public:
  RecordingDynamics(int dim, double dt) : dim_(dim), dt_(static_cast<float>(dt)) {}
  int state_dim() const override { return dim_; }
  int action_dim() const override { return dim_; }
  std::string Describe() const override { return "recording integrator"; }
  /// The recorded batches with `cols` columns, in order.
  std::vector<Eigen::MatrixXf> Batches(Eigen::Index cols) const {
    std::vector<Eigen::MatrixXf> out;
    for (const Eigen::MatrixXf& b : batches_)
      if (b.cols() == cols) out.push_back(b);
    return out;
  }
  void Clear() { batches_.clear(); }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override {
    batches_.emplace_back(actions);
    for (Eigen::Index i = 0; i < actions.cols(); ++i)
      next_states.col(i) = state + dt_ * actions.col(i);
  }

 private:
  int dim_;
  float dt_;
  mutable std::vector<Eigen::MatrixXf> batches_;
};

/// h = 1 everywhere: every sample is safe (g = alpha(1) = 1), so a decision is one round of M.
FunctionBarrier AlwaysSafe(int dim) {
  return FunctionBarrier(dim, "1", [](const Eigen::Ref<const Eigen::VectorXf>&) { return 1.0; });
}

/// The sample rounds of `rounds` decisions at `state`, one M-column matrix per round.
std::vector<Eigen::MatrixXf> Rounds(Sampler sampler, int m, const Eigen::VectorXf& mu,
                                    const Eigen::VectorXf& sigma, int rounds,
                                    std::uint64_t seed = 1) {
  const int dim = static_cast<int>(mu.size());
  RecordingDynamics dynamics(dim, 0.1);
  FunctionBarrier barrier = AlwaysSafe(dim);
  ShieldOptions options;
  options.sampler = sampler;
  options.num_samples = m;
  options.num_probes = m == 64 ? 63 : 64;  // never a probe batch of M columns
  options.seed = seed;
  Shield shield(options, barrier, dynamics);
  const Eigen::VectorXf state = Eigen::VectorXf::Zero(dim);
  for (int i = 0; i < rounds; ++i) {
    const Decision& d = shield.Decide(state, mu, sigma);
    EXPECT_EQ(d.iterations, 1);
  }
  std::vector<Eigen::MatrixXf> out = dynamics.Batches(m);
  EXPECT_EQ(static_cast<int>(out.size()), rounds);
  return out;
}

double NormalCdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

/// Kolmogorov–Smirnov distance between the empirical CDF of `u` and U(0, 1).
double KsDistance(std::vector<double> u) {
  std::sort(u.begin(), u.end());
  const double n = static_cast<double>(u.size());
  double d = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i)
    d = std::max({d, (static_cast<double>(i) + 1.0) / n - u[i], u[i] - static_cast<double>(i) / n});
  return d;
}

/// The largest KS distance, over rounds and dimensions, of Phi((x - mu) / sigma).
double MaxKsDistance(const std::vector<Eigen::MatrixXf>& rounds, const Eigen::VectorXf& mu,
                     const Eigen::VectorXf& sigma) {
  double worst = 0.0;
  for (const Eigen::MatrixXf& round : rounds) {
    for (Eigen::Index r = 0; r < round.rows(); ++r) {
      std::vector<double> u;
      for (Eigen::Index c = 0; c < round.cols(); ++c)
        u.push_back(NormalCdf((static_cast<double>(round(r, c)) - mu[r]) / sigma[r]));
      worst = std::max(worst, KsDistance(u));
    }
  }
  return worst;
}

/// Mean over rounds of ||round mean - mu||^2 / sum(sigma^2) (i.i.d.: about 1 / M).
double MeanSquaredErrorOfRoundMean(const std::vector<Eigen::MatrixXf>& rounds,
                                   const Eigen::VectorXf& mu, const Eigen::VectorXf& sigma) {
  double sum = 0.0;
  for (const Eigen::MatrixXf& round : rounds) {
    const Eigen::VectorXd mean = round.cast<double>().rowwise().mean();
    sum += (mean - mu.cast<double>()).squaredNorm() / sigma.cast<double>().squaredNorm();
  }
  return sum / static_cast<double>(rounds.size());
}

/// Per-dimension standard deviation over all samples of all rounds, divided by sigma.
Eigen::VectorXd RelativeSpread(const std::vector<Eigen::MatrixXf>& rounds,
                               const Eigen::VectorXf& mu, const Eigen::VectorXf& sigma) {
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(mu.size());
  double n = 0;
  for (const Eigen::MatrixXf& round : rounds) {
    for (Eigen::Index c = 0; c < round.cols(); ++c)
      sum += (round.col(c).cast<double>() - mu.cast<double>()).array().square().matrix();
    n += static_cast<double>(round.cols());
  }
  return (sum / n).cwiseSqrt().cwiseQuotient(sigma.cast<double>());
}

/// Expects a recorded sample to be mu + step (step = sigma z) as this test computes it. The shield
/// and the test evaluate mu + sigma z in different code, and with -march=native either may fuse
/// it into one FMA or round the product first (the antithetic sampler's product feeds mu + step
/// and, in a branch, mu - step), so they agree only to the rounding of the product and the sum:
/// 2 float eps of |mu| + |step|. Unlike a relative ulps comparison (FLOAT_EQ) this also holds
/// when the sample is near 0 (mu and step cancel).
void ExpectDraw(float sample, float mu, float step) {
  EXPECT_NEAR(sample, mu + step,
              2 * std::numeric_limits<float>::epsilon() * (std::abs(mu) + std::abs(step)));
}

const Eigen::VectorXf kMu3 = Vec({0.3f, -1.2f, 2.0f});
const Eigen::VectorXf kSigma3 = Vec({0.5f, 0.1f, 2.0f});

// ------------------------------------------------------------------------------------------------
// Names, options.

TEST(ShieldSamplerTest, NamesDefaultAndJson) {
  EXPECT_EQ(ShieldOptions{}.sampler, Sampler::kIid);
  EXPECT_EQ(ToString(kSamplerNames, Sampler::kIid), "iid");
  EXPECT_EQ(ToString(kSamplerNames, Sampler::kAntithetic), "antithetic");
  EXPECT_EQ(ToString(kSamplerNames, Sampler::kQmc), "qmc");
  ShieldOptions options;
  EXPECT_EQ(options.ToJson()["sampler"], "iid");
  options.sampler = Sampler::kQmc;
  EXPECT_EQ(options.ToJson()["sampler"], "qmc");
}

TEST(ShieldSamplerTest, YamlSetsTheSamplerAndNamesABadValue) {
  ShieldOptions options;
  options.ApplyYaml(YAML::Load("{sampler: antithetic, num_samples: 32}"), "s.yaml");
  EXPECT_EQ(options.sampler, Sampler::kAntithetic);
  EXPECT_EQ(options.num_samples, 32);
  options.ApplyYaml(YAML::Load("{sampler: qmc}"), "s.yaml");
  EXPECT_EQ(options.sampler, Sampler::kQmc);
  const std::string message =
      ErrorOf([&] { options.ApplyYaml(YAML::Load("{sampler: sobol}"), "s.yaml"); });
  EXPECT_HAS(message, "s.yaml");
  EXPECT_HAS(message, "'sobol'");
  EXPECT_HAS(message, "iid, antithetic, qmc");
  EXPECT_EQ(options.sampler, Sampler::kQmc);  // unchanged
}

TEST(ShieldSamplerTest, QmcRejectsMoreActionDimensionsThanSobolSupports) {
  const int too_many = MaxQmcDimension() + 1;
  EXPECT_EQ(MaxQmcDimension(), 3667);  // Boost 1.74's Sobol tables
  ShieldOptions options;
  options.sampler = Sampler::kQmc;
  options.Validate(MaxQmcDimension());  // the limit itself is allowed
  const std::string message = ErrorOf([&] { options.Validate(too_many); });
  EXPECT_HAS(message, "ShieldOptions::sampler = qmc supports action dimensions up to 3667");
  EXPECT_HAS(message, "the action dimension is 3668");
  // The constructor checks it.
  test::IntegratorDynamics dynamics(too_many, 0.1);
  FunctionBarrier barrier = AlwaysSafe(too_many);
  EXPECT_HAS(ErrorOf([&] { Shield shield(options, barrier, dynamics); }),
             "sampler = qmc supports action dimensions up to 3667");
  options.sampler = Sampler::kAntithetic;  // the others have no limit
  Shield fine(options, barrier, dynamics);
}

TEST(ShieldSamplerTest, QmcUniformNeverReachesZeroOrOne) {
  EXPECT_GT(detail::QmcUniform(0), 0.0);
  EXPECT_LT(detail::QmcUniform(~std::uint64_t{0}), 1.0);
  EXPECT_EQ(detail::QmcUniform(std::uint64_t{1} << 63), 0.5 + 0x1.0p-53);
  EXPECT_TRUE(std::isfinite(detail::QmcNormal(0)));
  EXPECT_TRUE(std::isfinite(detail::QmcNormal(~std::uint64_t{0})));
  EXPECT_LT(detail::QmcNormal(0), -8.0);
  EXPECT_GT(detail::QmcNormal(~std::uint64_t{0}), 8.0);
  EXPECT_NEAR(detail::QmcNormal(std::uint64_t{1} << 63), 0.0, 1e-15);
  // Phi^-1 of 0.975 (the top bits of 0.975 * 2^64).
  EXPECT_NEAR(detail::QmcNormal(static_cast<std::uint64_t>(0.975 * 0x1.0p64)), 1.959963985, 1e-8);
}

// ------------------------------------------------------------------------------------------------
// i.i.d.: the shield's own stream, column by column (the golden decisions are in shield_test.cc).

TEST(ShieldSamplerTest, IidDrawsTheStreamColumnByColumn) {
  const std::vector<Eigen::MatrixXf> rounds = Rounds(Sampler::kIid, 5, kMu3, kSigma3, 2, 7);
  Rng rng(7);
  for (const Eigen::MatrixXf& round : rounds)
    for (Eigen::Index c = 0; c < round.cols(); ++c)
      for (Eigen::Index r = 0; r < round.rows(); ++r)
        ExpectDraw(round(r, c), kMu3[r], kSigma3[r] * static_cast<float>(rng.Normal()));
}

// ------------------------------------------------------------------------------------------------
// Antithetic pairs.

TEST(ShieldSamplerTest, AntitheticPairsAreExactMirrorsFromHalfTheNormals) {
  for (int m : {64, 7}) {
    SCOPED_TRACE("M = " + std::to_string(m));
    const std::vector<Eigen::MatrixXf> rounds =
        Rounds(Sampler::kAntithetic, m, kMu3, kSigma3, 3, 5);
    Rng rng(5);  // the shield's stream: ceil(M / 2) normal vectors per round, nothing else
    for (const Eigen::MatrixXf& round : rounds) {
      for (int c = 0; c < m; c += 2) {
        for (Eigen::Index r = 0; r < round.rows(); ++r) {
          const float step = kSigma3[r] * static_cast<float>(rng.Normal());
          // (not bit for bit: the compiler may fuse mu + sigma z into one FMA or not)
          ExpectDraw(round(r, c), kMu3[r], step);
          if (c + 1 < m) {
            ExpectDraw(round(r, c + 1), kMu3[r], -step);
            // Mirrors about mu: the two offsets are equal and opposite.
            EXPECT_NEAR(round(r, c) - kMu3[r], -(round(r, c + 1) - kMu3[r]),
                        1e-6f * (std::abs(kMu3[r]) + kSigma3[r]));
          }
        }
      }
      if (m % 2 == 1) {  // the unpaired last column is a plain draw, not mu
        EXPECT_GT((round.col(m - 1) - kMu3).norm(), 0.0f);
      }
    }
  }
}

TEST(ShieldSamplerTest, AntitheticRoundsAreCentredWithTheRightSpread) {
  const std::vector<Eigen::MatrixXf> anti = Rounds(Sampler::kAntithetic, 64, kMu3, kSigma3, 300);
  const std::vector<Eigen::MatrixXf> iid = Rounds(Sampler::kIid, 64, kMu3, kSigma3, 300);
  // Even M: the round mean is mu up to float rounding; i.i.d. misses by about sigma / sqrt(M).
  EXPECT_LT(MeanSquaredErrorOfRoundMean(anti, kMu3, kSigma3), 1e-10);
  EXPECT_GT(MeanSquaredErrorOfRoundMean(iid, kMu3, kSigma3), 0.5 / 64);
  // The spread is sigma (19,200 draws per dimension: the relative s.e. of the s.d. is ~0.7 %;
  // the pairs are dependent, so 9,600 independent values: ~1 %).
  const Eigen::VectorXd spread = RelativeSpread(anti, kMu3, kSigma3);
  for (Eigen::Index r = 0; r < spread.size(); ++r) EXPECT_NEAR(spread[r], 1.0, 0.05) << r;
}

// ------------------------------------------------------------------------------------------------
// Randomised QMC.

TEST(ShieldSamplerTest, QmcMarginalsAreFarCloserToNormalThanIid) {
  const int m = 128, rounds = 200;
  const std::vector<Eigen::MatrixXf> qmc = Rounds(Sampler::kQmc, m, kMu3, kSigma3, rounds);
  const std::vector<Eigen::MatrixXf> iid = Rounds(Sampler::kIid, m, kMu3, kSigma3, rounds);
  // A shifted Sobol net of 2^7 points has one point in each [j / 128, (j + 1) / 128) per
  // dimension, so its KS distance is below 1/128 (+ float rounding of the samples); i.i.d.
  // draws have D ~ 0.87 / sqrt(128) = 0.077 typically and below 2/128 with probability < 1e-9.
  const double d_qmc = MaxKsDistance(qmc, kMu3, kSigma3);
  const double d_iid = MaxKsDistance(iid, kMu3, kSigma3);
  EXPECT_LT(d_qmc, 1.05 / m);
  EXPECT_GT(d_iid, 2.0 / m);
  // Each dimension: exactly one point per stratum (the net property, checked directly).
  for (const Eigen::MatrixXf& round : qmc) {
    for (Eigen::Index r = 0; r < round.rows(); ++r) {
      std::vector<int> count(m, 0);
      for (Eigen::Index c = 0; c < m; ++c) {
        const double u = NormalCdf((static_cast<double>(round(r, c)) - kMu3[r]) / kSigma3[r]);
        ++count[std::clamp(static_cast<int>(u * m), 0, m - 1)];
      }
      // Float rounding can move a point sitting on a stratum edge: allow two strata off.
      int empty = 0;
      for (int k : count) empty += k == 0;
      EXPECT_LE(empty, 2);
    }
  }
  const Eigen::VectorXd spread = RelativeSpread(qmc, kMu3, kSigma3);
  for (Eigen::Index r = 0; r < spread.size(); ++r) EXPECT_NEAR(spread[r], 1.0, 0.02) << r;
}

TEST(ShieldSamplerTest, QmcRoundMeanIsMuchCloserToMuThanIid) {
  const int m = 128, rounds = 400;
  const double mse_qmc =
      MeanSquaredErrorOfRoundMean(Rounds(Sampler::kQmc, m, kMu3, kSigma3, rounds), kMu3, kSigma3);
  const double mse_iid =
      MeanSquaredErrorOfRoundMean(Rounds(Sampler::kIid, m, kMu3, kSigma3, rounds), kMu3, kSigma3);
  // i.i.d.: E = 1 / M (sigma-normalised); over 400 rounds within ~7 % of it.
  EXPECT_NEAR(mse_iid, 1.0 / m, 0.25 / m);
  // Measured: 2.3e-4 against 8.0e-3 (35x smaller).
  EXPECT_LT(mse_qmc, mse_iid / 10) << mse_qmc << " vs " << mse_iid;
}

TEST(ShieldSamplerTest, QmcShiftsEachRoundAfreshAndEveryPointIsAnUnbiasedDraw) {
  // Consecutive rounds differ (a fresh shift) ...
  const std::vector<Eigen::MatrixXf> rounds = Rounds(Sampler::kQmc, 16, kMu3, kSigma3, 2000);
  EXPECT_GT((rounds[0] - rounds[1]).norm(), 0.0f);
  // ... and the first column (the "policy's own draw" behind Decision::intervened) is N(mu, sigma)
  // over rounds: its mean and spread across 2000 rounds.
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(3), sq = Eigen::VectorXd::Zero(3);
  for (const Eigen::MatrixXf& round : rounds) {
    const Eigen::VectorXd z = (round.col(0) - kMu3).cwiseQuotient(kSigma3).cast<double>();
    sum += z;
    sq += z.cwiseProduct(z);
  }
  const double n = static_cast<double>(rounds.size());
  for (int r = 0; r < 3; ++r) {
    EXPECT_NEAR(sum[r] / n, 0.0, 0.1) << r;  // s.e. 0.022
    EXPECT_NEAR(std::sqrt(sq[r] / n), 1.0, 0.1) << r;
  }
}

// ------------------------------------------------------------------------------------------------
// Every sampler in the decision loop.

struct Braking {
  // 1-D: x' = x + 0.1 a, h(x) = 1 - x at x = 0.95: g(a) = -a + 0.05, safe iff a <= 0.05. mu = 1
  // with sigma 0.01 is unsafe, so Algorithm 2 widens sigma until some samples are safe.
  RecordingDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; }};
};

TEST(ShieldSamplerTest, ResamplingRoundsUseTheSamplerWithTheWidenedSigmaAndProbesStayUniform) {
  for (Sampler sampler : {Sampler::kAntithetic, Sampler::kQmc}) {
    SCOPED_TRACE(ToString(kSamplerNames, sampler));
    Braking sys;
    ShieldOptions options;
    options.sampler = sampler;
    options.num_samples = 32;
    options.num_probes = 20;
    options.max_iterations = 10;
    Shield shield(options, sys.barrier, sys.dynamics);
    const Eigen::VectorXf state = Vec({0.95f}), mu = Vec({1.0f}), sigma = Vec({0.01f});
    const Decision& d = shield.Decide(state, mu, sigma);
    ASSERT_GT(d.iterations, 1);
    ASSERT_TRUE(d.safe());
    const std::vector<Eigen::MatrixXf> samples = sys.dynamics.Batches(32);
    const std::vector<Eigen::MatrixXf> probes = sys.dynamics.Batches(20);
    ASSERT_EQ(static_cast<int>(samples.size()), d.iterations);
    ASSERT_EQ(static_cast<int>(probes.size()), d.iterations - 1);
    // Rounds spread wider and wider (sigma grows by sigma_step per adaptive step).
    for (std::size_t i = 1; i < samples.size(); ++i) {
      const float spread_before = (samples[i - 1].array() - 1.0f).abs().maxCoeff();
      const float spread = (samples[i].array() - 1.0f).abs().maxCoeff();
      EXPECT_GT(spread, spread_before) << "round " << i + 1;
    }
    for (const Eigen::MatrixXf& round : samples) {
      if (sampler == Sampler::kAntithetic) {
        for (int c = 0; c < 32; c += 2) EXPECT_NEAR(round(0, c) + round(0, c + 1), 2.0f, 1e-5f);
      } else {
        // (the widened sigma is not observable here: the round mean is ~mu)
        EXPECT_NEAR(round.mean(), 1.0f, 0.05f * (round.array() - 1.0f).abs().maxCoeff());
      }
    }
    // Probes: uniform in mu + [-1, 1], not mirrored pairs.
    for (const Eigen::MatrixXf& p : probes) {
      EXPECT_LE((p.array() - 1.0f).abs().maxCoeff(), 1.0f);
      int mirrored = 0;
      for (int c = 0; c < 20; c += 2) mirrored += std::abs(p(0, c) + p(0, c + 1) - 2.0f) < 1e-5f;
      EXPECT_LT(mirrored, 3);
    }
  }
}

TEST(ShieldSamplerTest, EverySamplerIsDeterministicPerSeed) {
  for (Sampler sampler : {Sampler::kIid, Sampler::kAntithetic, Sampler::kQmc}) {
    SCOPED_TRACE(ToString(kSamplerNames, sampler));
    const auto decide = [&](std::uint64_t seed) {
      Braking sys;
      ShieldOptions options;
      options.sampler = sampler;
      options.num_samples = 16;
      options.seed = seed;
      Shield shield(options, sys.barrier, sys.dynamics);
      std::vector<float> actions;
      for (int i = 0; i < 4; ++i)
        actions.push_back(shield.Decide(Vec({0.95f}), Vec({1.0f}), Vec({0.01f})).action[0]);
      // Seed() restarts the stream.
      shield.Seed(seed);
      EXPECT_EQ(shield.Decide(Vec({0.95f}), Vec({1.0f}), Vec({0.01f})).action[0], actions[0]);
      return actions;
    };
    const std::vector<float> a = decide(3), b = decide(3), c = decide(4);
    EXPECT_EQ(std::memcmp(a.data(), b.data(), sizeof(float) * a.size()), 0);
    EXPECT_NE(a, c);
    EXPECT_NE(a[0], a[1]);  // consecutive decisions continue the stream
  }
}

TEST(ShieldSamplerTest, SamplersDrawDifferentActionsFromOneSeed) {
  const auto first = [](Sampler sampler) {
    return Rounds(sampler, 8, kMu3, kSigma3, 1, 11).front();
  };
  const Eigen::MatrixXf iid = first(Sampler::kIid), anti = first(Sampler::kAntithetic),
                        qmc = first(Sampler::kQmc);
  EXPECT_TRUE(iid.col(0).isApprox(anti.col(0), 1e-6f));  // the same first normal vector
  EXPECT_FALSE(iid.col(1) == anti.col(1));
  EXPECT_FALSE(iid.col(0) == qmc.col(0));
}

}  // namespace
}  // namespace secure::shield
