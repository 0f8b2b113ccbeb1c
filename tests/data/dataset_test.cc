// Tests of state sets, trajectories, random splits, column selection and list splitting.

#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "tests/test_util.h"

namespace secure::data {
namespace {

namespace fs = std::filesystem;

class DatasetTest : public secure::test::TempDirTest {};

using secure::test::ErrorOf;
using secure::test::ExpectContainsAll;

// ---------------------------------------------------------------------------------------------
// ReadStateSet and CheckNonEmptyFinite

TEST_F(DatasetTest, ReadStateSetSelectsFeaturesAsFloat) {
  const std::string path = Write("states.csv", "x,y,z\n1,2,3\n4,5,6\n");
  const StateSet set = ReadStateSet(path, {"z", "x"});
  EXPECT_EQ(set.source, path);
  EXPECT_EQ(set.features, (std::vector<std::string>{"z", "x"}));
  EXPECT_EQ(set.dim(), 2);
  EXPECT_EQ(set.size(), 2);
  EXPECT_EQ(set.states, (Eigen::MatrixXf(2, 2) << 3, 6, 1, 4).finished());
  EXPECT_EQ(ReadStateSet(path).dim(), 3);
}

TEST_F(DatasetTest, ReadStateSetRejectsZeroRows) {
  const std::string path = Write("states.csv", "x,y\n\n");
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(path); }), {path, "no data rows"});
}

TEST_F(DatasetTest, ReadStateSetRejectsFloatOverflow) {
  const std::string path = Write("states.csv", "x,y\n1,2\n3,1e300\n");
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(path); }),
                    {path + ":3:", "column 'y'", "1e+300", "float"});
}

TEST_F(DatasetTest, CheckNonEmptyFiniteAcceptsGoodSet) {
  StateSet set;
  set.source = "safe.csv";
  set.features = {"a", "b"};
  set.states = Eigen::MatrixXf::Ones(2, 3);
  EXPECT_NO_THROW(CheckNonEmptyFinite(set, "safe states"));
}

TEST_F(DatasetTest, CheckNonEmptyFiniteRejectsEmptySet) {
  StateSet set;
  set.source = "file.csv";
  set.features = {"a", "b"};
  set.states.resize(2, 0);
  ExpectContainsAll(ErrorOf([&] { CheckNonEmptyFinite(set, "near-dangerous states"); }),
                    {"near-dangerous states (file.csv): 0 states; each class needs at least one"});
}

TEST_F(DatasetTest, CheckNonEmptyFiniteRejectsNonFiniteState) {
  StateSet set;
  set.source = "file.csv";
  set.features = {"a", "b"};
  set.states = Eigen::MatrixXf::Zero(2, 4);
  set.states(1, 3) = std::numeric_limits<float>::quiet_NaN();
  ExpectContainsAll(ErrorOf([&] { CheckNonEmptyFinite(set, "safe states"); }),
                    {"safe states (file.csv)", "state 3", "feature 'b'", "nan"});
}

// ---------------------------------------------------------------------------------------------
// ReadTrajectories

TEST_F(DatasetTest, ReadTrajectoriesGroupsAdjacentEpisodeIds) {
  const std::string path = Write("demos.csv",
                                 "episode,step,s1,s2,a\n"
                                 "0,0,1,10,100\n"
                                 "0,1,2,20,200\n"
                                 "0.0,2,3,30,300\n"
                                 "3,0,4,40,400\n"
                                 "3.0,1,5,50,500\n"
                                 "1,0,6,60,600\n");
  const TrajectorySet set = ReadTrajectories(path, {"s2", "s1"}, {"a"});
  EXPECT_EQ(set.source, path);
  EXPECT_EQ(set.state_features, (std::vector<std::string>{"s2", "s1"}));
  EXPECT_EQ(set.action_features, (std::vector<std::string>{"a"}));
  EXPECT_EQ(set.num_episodes(), 3);
  EXPECT_EQ(set.num_steps(), 6);
  EXPECT_EQ(set.episode_begin, (std::vector<long>{0, 3, 5, 6}));
  EXPECT_EQ(set.states,
            (Eigen::MatrixXf(2, 6) << 10, 20, 30, 40, 50, 60, 1, 2, 3, 4, 5, 6).finished());
  EXPECT_EQ(set.actions, (Eigen::MatrixXf(1, 6) << 100, 200, 300, 400, 500, 600).finished());
}

TEST_F(DatasetTest, ReadTrajectoriesUsesTheGivenEpisodeColumn) {
  const std::string path = Write("demos.csv", "run,s,a\n7,1,0\n7,2,0\n-2,3,0\n");
  const TrajectorySet set = ReadTrajectories(path, {"s"}, {"a"}, "run");
  EXPECT_EQ(set.episode_begin, (std::vector<long>{0, 2, 3}));
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"s"}, {"a"}); }),
                    {path, "column 'episode' not found"});
}

TEST_F(DatasetTest, ReadTrajectoriesRejectsNonIntegerEpisode) {
  const std::string path = Write("demos.csv", "episode,s,a\n0,1,2\n1.5,1,2\n");
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"s"}, {"a"}); }),
                    {path + ":3:", "column 'episode'", "value '1.5'", "not an integer"});
}

TEST_F(DatasetTest, ReadTrajectoriesRejectsReappearingEpisode) {
  const std::string path = Write("demos.csv", "episode,s,a\n0,1,2\n0,1,2\n1,1,2\n0,1,2\n");
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"s"}, {"a"}); }),
                    {path + ":5:", "episode 0 reappears after episode 1", "line 3"});
}

TEST_F(DatasetTest, ReadTrajectoriesRejectsBadStateCell) {
  const std::string path = Write("demos.csv", "episode,s,a\n0,1,2\n0,oops,2\n");
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"s"}, {"a"}); }),
                    {path + ":3:", "column 's'", "value 'oops'"});
}

// ---------------------------------------------------------------------------------------------
// WriteStateSet and WriteTrajectories

// Values that need all of a float's digits, plus extremes of its range.
Eigen::MatrixXf AwkwardFloats(Eigen::Index rows, Eigen::Index cols, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::MatrixXf m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i)
    m(i) = static_cast<float>(rng.Uniform(-10.0, 10.0)) / 3.0f;
  m(0) = std::numeric_limits<float>::max();
  m(m.size() - 1) = std::numeric_limits<float>::denorm_min();
  return m;
}

TEST_F(DatasetTest, WriteStateSetRoundTripsBitExactly) {
  StateSet set{"", {"x", "y", "vx"}, AwkwardFloats(3, 17, 1)};
  const std::string path = PathOf("states.csv");
  WriteStateSet(path, set);
  const StateSet back = ReadStateSet(path);
  EXPECT_EQ(back.source, path);
  EXPECT_EQ(back.features, set.features);
  EXPECT_EQ(back.states, set.states);
}

TEST_F(DatasetTest, WriteStateSetRejectsBadSets) {
  const std::string path = PathOf("states.csv");
  ExpectContainsAll(ErrorOf([&] {
                      WriteStateSet(path, StateSet{"", {"x"}, Eigen::MatrixXf(1, 0)});
                    }),
                    {path, "0 states"});
  ExpectContainsAll(ErrorOf([&] {
                      WriteStateSet(path, StateSet{"", {"x"}, Eigen::MatrixXf::Zero(2, 3)});
                    }),
                    {path, "2 rows but 1 feature names"});
  ExpectContainsAll(ErrorOf([&] {
                      WriteStateSet(path, StateSet{"", {"x", "x"}, Eigen::MatrixXf::Zero(2, 3)});
                    }),
                    {path, "column 2 'x' repeats column 1"});
  StateSet nan{"", {"x", "y"}, Eigen::MatrixXf::Zero(2, 3)};
  nan.states(1, 2) = std::numeric_limits<float>::quiet_NaN();
  ExpectContainsAll(ErrorOf([&] { WriteStateSet(path, nan); }), {path, "column 'y'", "row 2"});
  EXPECT_FALSE(fs::exists(path));  // nothing half-written
}

TrajectorySet ThreeEpisodes() {
  TrajectorySet set;
  set.state_features = {"x", "y"};
  set.action_features = {"ax"};
  set.states = AwkwardFloats(2, 6, 2);
  set.actions = AwkwardFloats(1, 6, 3);
  set.episode_begin = {0, 3, 4, 6};
  return set;
}

TEST_F(DatasetTest, WriteTrajectoriesRoundTripsBitExactly) {
  const TrajectorySet set = ThreeEpisodes();
  const std::string path = PathOf("demos.csv");
  WriteTrajectories(path, set);
  const TrajectorySet back = ReadTrajectories(path, set.state_features, set.action_features);
  EXPECT_EQ(back.source, path);
  EXPECT_EQ(back.state_features, set.state_features);
  EXPECT_EQ(back.action_features, set.action_features);
  EXPECT_EQ(back.states, set.states);
  EXPECT_EQ(back.actions, set.actions);
  EXPECT_EQ(back.episode_begin, set.episode_begin);

  // The layout: episode, step, states, actions; steps count within each episode.
  const NumericTable table = ReadCsv(path);
  EXPECT_EQ(table.columns, (std::vector<std::string>{"episode", "step", "x", "y", "ax"}));
  EXPECT_EQ(Eigen::RowVectorXd(table.values.row(0)),
            (Eigen::RowVectorXd(6) << 0, 0, 0, 1, 2, 2).finished());
  EXPECT_EQ(Eigen::RowVectorXd(table.values.row(1)),
            (Eigen::RowVectorXd(6) << 0, 1, 2, 0, 0, 1).finished());
}

TEST_F(DatasetTest, WriteTrajectoriesUsesTheGivenEpisodeColumnAndAllowsNoActions) {
  TrajectorySet set = ThreeEpisodes();
  set.action_features.clear();
  set.actions.resize(0, 6);
  const std::string path = PathOf("demos.csv");
  WriteTrajectories(path, set, "run");
  const TrajectorySet back = ReadTrajectories(path, {"x", "y"}, {}, "run");
  EXPECT_EQ(back.states, set.states);
  EXPECT_EQ(back.episode_begin, set.episode_begin);
}

TEST_F(DatasetTest, WriteTrajectoriesRejectsInconsistentSets) {
  const std::string path = PathOf("demos.csv");
  const auto error_of = [&](const std::function<void(TrajectorySet&)>& breaker) {
    TrajectorySet set = ThreeEpisodes();
    breaker(set);
    return ErrorOf([&] { WriteTrajectories(path, set); });
  };
  ExpectContainsAll(error_of([](TrajectorySet& s) {
                      s.episode_begin = {0, 3, 3, 6};
                    }),
                    {path, "episode 1 is empty", "episode_begin[1] = 3"});
  ExpectContainsAll(error_of([](TrajectorySet& s) {
                      s.episode_begin = {0, 3, 5};
                    }),
                    {path, "episode_begin must start at 0 and end at 6", "from 0 to 5"});
  ExpectContainsAll(error_of([](TrajectorySet& s) { s.episode_begin.clear(); }),
                    {path, "episode_begin must start at 0", "0 entries"});
  ExpectContainsAll(error_of([](TrajectorySet& s) { s.actions.resize(1, 5); }),
                    {path, "6 states but 5 actions"});
  ExpectContainsAll(error_of([](TrajectorySet& s) { s.state_features = {"x"}; }),
                    {path, "2 rows but 1 state feature names"});
  ExpectContainsAll(error_of([](TrajectorySet& s) { s.action_features = {"x"}; }),
                    {path, "column 5 'x' repeats column 3"});
  ExpectContainsAll(error_of([](TrajectorySet& s) {
                      s.state_features = {"step", "y"};
                    }),
                    {path, "column 3 'step' repeats column 2"});
  ExpectContainsAll(error_of([](TrajectorySet& s) {
                      s.states.resize(2, 0);
                      s.actions.resize(1, 0);
                      s.episode_begin = {0};
                    }),
                    {path, "0 steps"});
  ExpectContainsAll(
      error_of([](TrajectorySet& s) { s.actions(0, 4) = std::numeric_limits<float>::infinity(); }),
      {path, "column 'ax'", "row 4"});
  EXPECT_FALSE(fs::exists(path));
}

TEST_F(DatasetTest, ReadsRealTaskDemos) {
  const std::string path = SECURE_SHARED_DIR "/data/panda_push/task_demos.csv";
  if (!fs::exists(path)) GTEST_SKIP() << path << " not found";
  const std::vector<std::string> state = {
      "ee_x",     "ee_y",     "ee_z",     "ee_vx",      "ee_vy",       "ee_vz",
      "block_x",  "block_y",  "block_z",  "block_roll", "block_pitch", "block_yaw",
      "block_vx", "block_vy", "block_vz", "block_wx",   "block_wy",    "block_wz"};
  const TrajectorySet set = ReadTrajectories(path, state, {"act_x", "act_y", "act_z"});
  EXPECT_EQ(set.num_episodes(), 2);
  EXPECT_EQ(set.episode_begin, (std::vector<long>{0, 133, 246}));
  EXPECT_EQ(set.num_steps(), 246);
  EXPECT_EQ(set.states.rows(), 18);
  EXPECT_EQ(set.actions.rows(), 3);
  EXPECT_EQ(set.actions.cols(), 246);
  EXPECT_FLOAT_EQ(set.states(0, 0), 0.09280236065387726f);
  EXPECT_FLOAT_EQ(set.actions(2, 0), -0.9000000357627869f);
  EXPECT_TRUE(set.states.allFinite());
}

// ---------------------------------------------------------------------------------------------
// RandomSplit

std::vector<std::size_t> Sizes(const std::vector<std::vector<long>>& parts) {
  std::vector<std::size_t> sizes;
  for (const auto& part : parts) sizes.push_back(part.size());
  return sizes;
}

TEST(SplitForValidationTest, HoldsOutARoundedShareOfAtLeastOneAndAtMostAllButOne) {
  Rng rng(3);
  IndexSplit s = SplitForValidation(100, 0.1, rng);
  EXPECT_EQ(s.validation.size(), 10u);
  EXPECT_EQ(s.train.size(), 90u);
  std::vector<long> all = s.train;
  all.insert(all.end(), s.validation.begin(), s.validation.end());
  std::sort(all.begin(), all.end());
  for (long i = 0; i < 100; ++i) EXPECT_EQ(all[static_cast<std::size_t>(i)], i);
  EXPECT_EQ(SplitForValidation(10, 0.01, rng).validation.size(), 1u);  // at least one
  EXPECT_EQ(SplitForValidation(2, 0.9, rng).validation.size(), 1u);    // at most n - 1
  EXPECT_TRUE(SplitForValidation(1, 0.5, rng).validation.empty());     // too small to split
  EXPECT_TRUE(SplitForValidation(50, 0.0, rng).validation.empty());
  EXPECT_EQ(SplitForValidation(50, 0.0, rng).train.size(), 50u);
}

TEST(SplitTwoClassesForValidationTest, EqualsTwoSplitsInTurnAndHoldsOutBothOrNeither) {
  Rng rng(5), same(5);
  const auto [a, b] = SplitTwoClassesForValidation(40, 20, 0.25, rng);
  const IndexSplit a_ref = SplitForValidation(40, 0.25, same);
  const IndexSplit b_ref = SplitForValidation(20, 0.25, same);
  EXPECT_EQ(a.train, a_ref.train);
  EXPECT_EQ(a.validation, a_ref.validation);
  EXPECT_EQ(b.train, b_ref.train);
  EXPECT_EQ(b.validation, b_ref.validation);
  // One state in class b: it cannot be split, so class a keeps everything for training too.
  const auto [c, d] = SplitTwoClassesForValidation(40, 1, 0.25, rng);
  EXPECT_TRUE(c.validation.empty());
  EXPECT_TRUE(d.validation.empty());
  EXPECT_EQ(c.train.size(), 40u);
  EXPECT_EQ(d.train.size(), 1u);
}

TEST(RandomSplitTest, PartSizesRoundDownExceptTheLast) {
  Rng rng(1);
  EXPECT_EQ(Sizes(RandomSplit(10, {0.7, 0.2, 0.1}, rng)), (std::vector<std::size_t>{7, 2, 1}));
  EXPECT_EQ(Sizes(RandomSplit(7, {0.5, 0.5}, rng)), (std::vector<std::size_t>{3, 4}));
  EXPECT_EQ(Sizes(RandomSplit(100, {0.29, 0.71}, rng)), (std::vector<std::size_t>{29, 71}));
  EXPECT_EQ(Sizes(RandomSplit(5, {1.0}, rng)), (std::vector<std::size_t>{5}));
  EXPECT_EQ(Sizes(RandomSplit(0, {0.8, 0.2}, rng)), (std::vector<std::size_t>{0, 0}));
}

TEST(RandomSplitTest, PartsAreADisjointCover) {
  Rng rng(42);
  const long n = 1000;
  const auto parts = RandomSplit(n, {0.6, 0.25, 0.15}, rng);
  std::vector<long> all;
  for (const auto& part : parts) all.insert(all.end(), part.begin(), part.end());
  ASSERT_EQ(static_cast<long>(all.size()), n);
  std::sort(all.begin(), all.end());
  std::vector<long> expected(n);
  std::iota(expected.begin(), expected.end(), 0L);
  EXPECT_EQ(all, expected);
  // Shuffled, not the identity.
  std::vector<long> first_identity(parts[0].size());
  std::iota(first_identity.begin(), first_identity.end(), 0L);
  EXPECT_NE(parts[0], first_identity);
}

TEST(RandomSplitTest, DeterministicForSeedAndDifferentAcrossSeeds) {
  Rng a(123);
  Rng b(123);
  Rng c(124);
  const auto split_a = RandomSplit(200, {0.5, 0.5}, a);
  EXPECT_EQ(split_a, RandomSplit(200, {0.5, 0.5}, b));
  EXPECT_NE(split_a, RandomSplit(200, {0.5, 0.5}, c));
}

TEST(RandomSplitTest, RejectsBadArguments) {
  Rng rng(0);
  ExpectContainsAll(ErrorOf([&] {
                      RandomSplit(10, {0.5, -0.25, 0.75}, rng);
                    }),
                    {"fraction 2 is -0.25", "> 0"});
  ExpectContainsAll(ErrorOf([&] { RandomSplit(10, {0.0, 1.0}, rng); }), {"fraction 1 is 0"});
  ExpectContainsAll(ErrorOf([&] {
                      RandomSplit(10, {0.5, 0.6}, rng);
                    }),
                    {"sum to 1.1", "must sum to 1"});
  ExpectContainsAll(ErrorOf([&] { RandomSplit(10, {0.5, 0.5 - 1e-6}, rng); }), {"sum to"});
  ExpectContainsAll(ErrorOf([&] {
                      RandomSplit(10, {std::numeric_limits<double>::quiet_NaN(), 1.0}, rng);
                    }),
                    {"fraction 1 is nan"});
  ExpectContainsAll(ErrorOf([&] { RandomSplit(10, {}, rng); }), {"no fractions"});
  ExpectContainsAll(ErrorOf([&] { RandomSplit(-3, {1.0}, rng); }), {"-3", ">= 0"});
  EXPECT_NO_THROW(RandomSplit(10, {0.5, 0.5 + 1e-12}, rng));
}

// ---------------------------------------------------------------------------------------------
// SelectColumns and SplitList

TEST(SelectColumnsTest, PicksColumnsInTheGivenOrder) {
  Eigen::MatrixXf states(2, 4);
  states << 0, 1, 2, 3, 10, 11, 12, 13;
  EXPECT_EQ(SelectColumns(states, {3, 0, 3}),
            (Eigen::MatrixXf(2, 3) << 3, 0, 3, 13, 10, 13).finished());
  EXPECT_EQ(SelectColumns(states, {}).cols(), 0);
  ExpectContainsAll(ErrorOf([&] { SelectColumns(states, {1, 4}); }), {"index 4", "[0, 4)"});
  ExpectContainsAll(ErrorOf([&] { SelectColumns(states, {-1}); }), {"index -1"});
}

TEST(SplitListTest, SplitsAtCommasAndTrims) {
  EXPECT_EQ(SplitList("a,b,c"), (std::vector<std::string>{"a", "b", "c"}));
  EXPECT_EQ(SplitList("  ee_x , ee_y,\tee_z  "),
            (std::vector<std::string>{"ee_x", "ee_y", "ee_z"}));
  EXPECT_EQ(SplitList("single"), (std::vector<std::string>{"single"}));
  EXPECT_TRUE(SplitList("").empty());
  EXPECT_TRUE(SplitList("   ").empty());
  EXPECT_EQ(SplitList("a,,b"), (std::vector<std::string>{"a", "", "b"}));
}

}  // namespace
}  // namespace secure::data
