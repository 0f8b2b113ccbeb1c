// AIRL's files (the policy_train_test program): checkpoints and resume, corrupt or old
// checkpoints, identical model files, the reward model, the learning curve.
#include "tests/policy/trainers_test_util.h"

namespace secure::policy {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the trainer tests' helpers

// Every test trains on the same 10 expert episodes (seed 2) of the point mass.
class AirlFileTest : public secure::test::TempDirTest {
 protected:
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
};

TEST_F(AirlFileTest, ResumeFromACheckpointGivesTheSamePolicyBitwise) {
  const GaussianPolicy uninterrupted = TrainAirl(SmallAirl(), demos, env, nullptr, nullptr);

  // Stop after 3 iterations with the option, resume to the end.
  AirlOptions o = SmallAirl();
  o.checkpoint_path = PathOf("run/airl.ckpt");
  o.checkpoint_every = 2;
  o.curve_path = PathOf("run/curve.csv");
  o.stop_after_iterations = 3;
  o.resume = true;  // no checkpoint yet: starts afresh
  AirlSummary s;
  TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_FALSE(s.resumed);
  EXPECT_EQ(s.iterations, 3);
  EXPECT_EQ(s.stop_reason, "stop_after_iterations");
  EXPECT_EQ(s.checkpoints_written, 2);  // at 2 and at the stop
  EXPECT_TRUE(std::filesystem::exists(o.checkpoint_path));
  EXPECT_EQ(Lines(ReadFile(o.curve_path)).size(), 4u);

  o.stop_after_iterations = 0;
  const GaussianPolicy resumed = TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_TRUE(s.resumed);
  EXPECT_EQ(s.start_iteration, 3);
  EXPECT_EQ(s.iterations, 6);
  EXPECT_EQ(s.env_steps, 6 * 500);
  EXPECT_TRUE(BitEqual(uninterrupted, resumed));
  // The curve holds every iteration once, in order.
  const auto lines = Lines(ReadFile(o.curve_path));
  ASSERT_EQ(lines.size(), 7u);
  EXPECT_EQ(lines[0], Join(AirlIterationStats::Columns(), ","));
  for (int i = 1; i <= 6; ++i) EXPECT_EQ(lines[i].substr(0, lines[i].find(',')), std::to_string(i));

  // Resuming a finished run returns the same policy without training.
  const GaussianPolicy again = TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_EQ(s.start_iteration, 6);
  EXPECT_TRUE(BitEqual(uninterrupted, again));

  // A callback stop (after iteration 4, between checkpoints) also resumes exactly.
  std::filesystem::remove(o.checkpoint_path);
  TrainAirl(o, demos, env, nullptr, &s,
            [](const AirlIterationStats& stats) { return stats.iteration < 4; });
  EXPECT_EQ(s.stop_reason, "callback");
  EXPECT_EQ(s.iterations, 4);
  EXPECT_TRUE(BitEqual(uninterrupted, TrainAirl(o, demos, env, nullptr, &s)));
  EXPECT_EQ(s.start_iteration, 4);
}

TEST_F(AirlFileTest, IncompatibleOrBrokenCheckpointsAreRejected) {
  AirlOptions o = SmallAirl();
  o.iterations = 1;
  o.checkpoint_path = PathOf("airl.ckpt");
  TrainAirl(o, demos, env, nullptr, nullptr);
  o.resume = true;
  o.iterations = 2;
  o.gamma = 0.95;
  std::string m = ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  EXPECT_HAS(m, o.checkpoint_path);
  EXPECT_HAS(m, "AirlOptions::gamma");
  o.gamma = 0.99;
  m = ErrorOf([&] { TrainAirl(o, ExpertDemos(10, 3), env, nullptr, nullptr); });
  EXPECT_HAS(m, "demonstrations_fingerprint");
  m = ErrorOf([&] { TrainAirl(o, demos, PointMassEnv(40), nullptr, nullptr); });
  EXPECT_HAS(m, "environment");
  // A corrupt file names the path.
  std::string bytes = ReadFile(o.checkpoint_path);
  WriteFileAtomically(o.checkpoint_path, bytes.substr(0, bytes.size() / 2));
  m = ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  EXPECT_HAS(m, o.checkpoint_path);
}

// A checkpoint carries a CRC-32 over its whole content: a flipped byte inside the tensor data
// (which the LibTorch archive itself does not notice) or a truncated file is an error naming the
// file, never a silently different model. So is a checkpoint of an older format version.
TEST_F(AirlFileTest, CorruptTruncatedOrOldCheckpointsAreRejectedNamingTheFile) {
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  o.checkpoint_path = PathOf("airl.ckpt");
  TrainAirl(o, demos, env, nullptr, nullptr);
  const std::string good = ReadFile(o.checkpoint_path);
  ASSERT_GT(good.size(), 1000u);
  o.resume = true;
  o.iterations = 3;
  auto resume_error = [&](const std::string& bytes) {
    WriteFileAtomically(o.checkpoint_path, bytes);
    return ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  };

  // One bit of one byte in the middle of the file (tensor data of the archive).
  std::string flipped = good;
  flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x01);
  std::string m = resume_error(flipped);
  EXPECT_HAS(m, o.checkpoint_path);
  EXPECT_HAS(m, "checksum mismatch");
  EXPECT_HAS(m, "the checkpoint is corrupt");

  // Truncated: the last bytes, or half of the file, missing.
  for (const std::size_t keep : {good.size() - 5, good.size() / 2, std::size_t{10}}) {
    m = resume_error(good.substr(0, keep));
    EXPECT_HAS(m, o.checkpoint_path);
    EXPECT_HAS(m, "truncated");
  }
  m = resume_error("");
  EXPECT_HAS(m, o.checkpoint_path);

  // The trailer's digits themselves damaged.
  std::string trailer = good;
  trailer[trailer.size() - 2] = trailer[trailer.size() - 2] == '0' ? '1' : '0';
  EXPECT_HAS(resume_error(trailer), "checksum mismatch");

  // Version 1 (a bare LibTorch archive, no checksum) and an unknown version: clear errors.
  const std::size_t first_line = good.find('\n');
  ASSERT_NE(first_line, std::string::npos);
  EXPECT_EQ(good.substr(0, first_line), "secure-airl-checkpoint 2");
  const std::size_t trailer_size = std::string("\ncrc32 01234567\n").size();
  const std::string bare =
      good.substr(first_line + 1, good.size() - (first_line + 1) - trailer_size);
  m = resume_error(bare);
  EXPECT_HAS(m, o.checkpoint_path);
  EXPECT_HAS(m, "version 1");
  EXPECT_HAS(m, "reads version 2");
  m = resume_error("secure-airl-checkpoint 3" + good.substr(first_line));
  EXPECT_HAS(m, "version 3");
  m = resume_error("something else entirely\n");
  EXPECT_HAS(m, "not an AIRL checkpoint");

  // The intact file still resumes.
  WriteFileAtomically(o.checkpoint_path, good);
  AirlSummary s;
  TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_TRUE(s.resumed);
  EXPECT_EQ(s.start_iteration, 2);
  EXPECT_EQ(s.iterations, 3);
}

// A run cannot be shortened: resuming a checkpoint with more completed iterations than
// `iterations` is an error; with exactly as many it returns the checkpoint's policy.
TEST_F(AirlFileTest, ResumingWithFewerIterationsThanTheCheckpointIsAnError) {
  AirlOptions o = SmallAirl();
  o.iterations = 3;
  o.checkpoint_path = PathOf("airl.ckpt");
  const GaussianPolicy trained = TrainAirl(o, demos, env, nullptr, nullptr);
  o.resume = true;
  o.iterations = 2;
  const std::string m = ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  EXPECT_HAS(m, o.checkpoint_path +
                    ": checkpoint has 3 completed iterations, more than "
                    "iterations = 2");
  o.iterations = 3;
  AirlSummary s;
  EXPECT_TRUE(BitEqual(trained, TrainAirl(o, demos, env, nullptr, &s)));
  EXPECT_EQ(s.start_iteration, 3);
  EXPECT_EQ(s.iterations, 3);
}

// Timing is in the summary (and --json), not in the model file: two identical runs write
// identical model files.
TEST_F(AirlFileTest, IdenticalRunsWriteIdenticalModelFiles) {
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  AirlSummary s;
  const GaussianPolicy a = TrainAirl(o, demos, env, nullptr, &s);
  const GaussianPolicy b = TrainAirl(o, demos, env, nullptr, nullptr);
  EXPECT_TRUE(s.ToJson().contains("wall_seconds"));
  const nlohmann::json& summary = a.provenance.at("summary");
  for (const char* key : {"wall_seconds", "rollout_seconds", "discriminator_seconds", "ppo_seconds",
                          "iterations_per_second", "env_steps_per_second"})
    EXPECT_FALSE(summary.contains(key)) << key;
  EXPECT_FALSE(summary.at("last").contains("seconds"));
  EXPECT_EQ(summary["iterations"], 2);
  a.Save(PathOf("a.model"));
  b.Save(PathOf("b.model"));
  EXPECT_TRUE(ReadFile(PathOf("a.model")) == ReadFile(PathOf("b.model")));
}

// The trained discriminator's reward g and shaping V, exported for the shield's top-q
// aggregation: the policy's inputs and normaliser, the RL discount, the same bytes for the same
// seed, and a Q that varies with the next state.
TEST_F(AirlFileTest, ExportsTheRewardAndShapingNetworksAsARewardModel) {
  AirlOptions o = SmallAirl();
  o.gamma = 0.97;
  AirlRewardModel a, b;
  const GaussianPolicy pi = TrainAirl(o, demos, env, nullptr, nullptr, nullptr, &a);
  TrainAirl(o, demos, env, nullptr, nullptr, nullptr, &b);
  EXPECT_EQ(a.discount, 0.97);
  EXPECT_EQ(a.observation_features, pi.observation_features);
  EXPECT_EQ(a.input_features, pi.input_features);
  EXPECT_EQ(a.input.mean, pi.input.mean);
  EXPECT_EQ(a.input.scale, pi.input.scale);
  EXPECT_EQ(a.reward.spec.hidden, o.reward_hidden);
  EXPECT_EQ(a.shaping.spec.hidden, o.shaping_hidden);
  EXPECT_EQ(a.provenance["environment"], env.Describe());
  a.Save(PathOf("a.model"));
  b.Save(PathOf("b.model"));
  EXPECT_EQ(ReadFile(PathOf("a.model")), ReadFile(PathOf("b.model")));
  AirlActionValue value(AirlRewardModel::Load(PathOf("a.model")), env.ObservationFeatures(), 16);
  Eigen::MatrixXf next(2, 16);
  for (int c = 0; c < 16; ++c) next.col(c) << -1.0f + 0.13f * c, 0.5f - 0.07f * c;
  Eigen::VectorXd q(16);
  value.Evaluate(Eigen::Vector2f(0.1f, 0.2f), next, q);
  EXPECT_TRUE(q.allFinite());
  EXPECT_GT(q.maxCoeff() - q.minCoeff(), 1e-6);
}

TEST_F(AirlFileTest, WritesTheLearningCurveEveryIteration) {
  AirlOptions o = SmallAirl();
  o.iterations = 3;
  o.curve_path = PathOf("curve.csv");
  int calls = 0;
  TrainAirl(o, demos, env, nullptr, nullptr, [&](const AirlIterationStats& s) {
    ++calls;
    // Already on disk when the callback runs.
    EXPECT_EQ(Lines(ReadFile(o.curve_path)).size(), static_cast<std::size_t>(s.iteration + 1));
    return true;
  });
  EXPECT_EQ(calls, 3);
  const auto lines = Lines(ReadFile(o.curve_path));
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0],
            "iteration,env_steps,episodes,success_rate,collision_rate,mean_collisions,d_expert,"
            "d_policy,discriminator_loss,mean_reward,policy_loss,value_loss,entropy,mean_sigma,"
            "approx_kl,clip_fraction,bc_nll,seconds");
  const auto cells = data::SplitList(lines[3]);
  ASSERT_EQ(cells.size(), AirlIterationStats::Columns().size());
  EXPECT_EQ(cells[0], "3");
  EXPECT_EQ(cells[1], "1500");
  EXPECT_EQ(cells[2], "10");
}

}  // namespace
}  // namespace secure::policy
