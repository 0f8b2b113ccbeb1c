// Tests of demonstrations and state sets in robomimic's HDF5 layout: reading files written by
// the HDF5 C API directly (as robomimic's h5py would), round trips through our writer, and one
// precise error per kind of bad file.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/data/data.h"
#include "tests/data/hdf5_test_file.h"
#include "tests/test_util.h"

namespace secure::data {
namespace {

using secure::test::ErrorOf;
using secure::test::Hdf5TestFile;

class Hdf5Test : public secure::test::TempDirTest {};

// The shared check, and the message is one line.
void ExpectContainsAll(const std::string& message, const std::vector<std::string>& parts) {
  test::ExpectContainsAll(message, parts);
  EXPECT_EQ(message.find('\n'), std::string::npos) << "not one line: " << message;
}

const std::vector<std::string> kActions = {"actions[0]", "actions[1]"};

TEST_F(Hdf5Test, ExtensionSelectsTheFormat) {
  EXPECT_TRUE(IsHdf5Path("a/demos.h5"));
  EXPECT_TRUE(IsHdf5Path("demos.HDF5"));
  EXPECT_FALSE(IsHdf5Path("demos.csv"));
  EXPECT_FALSE(IsHdf5Path("h5"));
  EXPECT_FALSE(IsHdf5Path("demos.h5.csv"));
}

TEST_F(Hdf5Test, ReadsRobomimicDemosInIndexOrder) {
  const std::string path = PathOf("demos.h5");
  {
    Hdf5TestFile f(path);
    f.Demo(10, 2);  // demo_10 sorts after demo_2 (robomimic orders by the number)
    f.Demo(2, 3);
  }
  const TrajectorySet set = ReadTrajectories(path, {}, {});
  EXPECT_EQ(set.state_features, (std::vector<std::string>{"pos[0]", "pos[1]", "vel"}));
  EXPECT_EQ(set.action_features, kActions);
  EXPECT_EQ(set.episode_begin, (std::vector<long>{0, 3, 5}));
  ASSERT_EQ(set.states.cols(), 5);
  // demo_2 step 1: pos = (1, 1.1), vel = 101; demo_10 step 0: pos = (0, 0.1).
  EXPECT_EQ(set.states.col(1), Eigen::Vector3f(1.0f, 1.1f, 101.0f));
  EXPECT_EQ(set.states.col(3), Eigen::Vector3f(0.0f, 0.1f, 100.0f));
  EXPECT_EQ(set.actions.col(2), Eigen::Vector2f(2.0f, -2.0f));
}

TEST_F(Hdf5Test, SelectsColumnsAndWholeKeysByName) {
  const std::string path = PathOf("demos.h5");
  {
    Hdf5TestFile f(path);
    f.Demo(0, 2);
  }
  // An obs key stands for all its columns; a column by its own name; order as given.
  TrajectorySet set = ReadTrajectories(path, {"vel", "pos"}, {"actions[1]"});
  EXPECT_EQ(set.state_features, (std::vector<std::string>{"vel", "pos[0]", "pos[1]"}));
  EXPECT_EQ(set.states.col(1), Eigen::Vector3f(101.0f, 1.0f, 1.1f));
  EXPECT_EQ(set.action_features, (std::vector<std::string>{"actions[1]"}));
  EXPECT_EQ(set.actions(0, 1), -1.0f);
  set = ReadTrajectories(path, {"pos[1]"}, {"actions"});
  EXPECT_EQ(set.state_features, (std::vector<std::string>{"pos[1]"}));
  EXPECT_EQ(set.action_features, kActions);
  // Without safety/, a state set is every demo step.
  const StateSet states = ReadStateSet(path, {"vel"});
  EXPECT_EQ(states.features, (std::vector<std::string>{"vel"}));
  EXPECT_EQ(states.states, (Eigen::MatrixXf(1, 2) << 100, 101).finished());
}

TEST_F(Hdf5Test, OneDimensionalDatasetsAreOneColumn) {
  const std::string path = PathOf("demos.h5");
  {
    Hdf5TestFile f(path);
    f.Floats("data/demo_0/obs/x", {3}, {1, 2, 3});
    f.Doubles("data/demo_0/actions", {3}, {4, 5, 6});
  }
  const TrajectorySet set = ReadTrajectories(path, {"x"}, {});
  EXPECT_EQ(set.state_features, (std::vector<std::string>{"x"}));
  EXPECT_EQ(set.action_features, (std::vector<std::string>{"actions"}));
  EXPECT_EQ(set.actions, (Eigen::MatrixXf(1, 3) << 4, 5, 6).finished());
}

// Random data with awkward floats (subnormals, extremes, -0) through our writer and back.
TrajectorySet RandomDemos() {
  TrajectorySet set;
  set.state_features = {"x", "pos[0]", "pos[1]", "pos[2]", "q[1]", "theta"};
  set.action_features = {"ax", "ay"};
  set.episode_begin = {0, 4, 5, 9};
  set.states = Eigen::MatrixXf::Random(6, 9);
  set.actions = Eigen::MatrixXf::Random(2, 9);
  set.states(0, 0) = std::numeric_limits<float>::denorm_min();
  set.states(1, 1) = std::numeric_limits<float>::max();
  set.states(2, 2) = -0.0f;
  set.actions(1, 8) = std::numeric_limits<float>::lowest();
  return set;
}

TEST_F(Hdf5Test, TrajectoriesRoundTripBitExactly) {
  const TrajectorySet set = RandomDemos();
  const std::string path = PathOf("demos.hdf5");
  WriteTrajectories(path, set);
  const TrajectorySet back = ReadTrajectories(path, set.state_features, set.action_features);
  EXPECT_EQ(back.states, set.states);
  EXPECT_EQ(back.actions, set.actions);
  EXPECT_EQ(back.episode_begin, set.episode_begin);
  EXPECT_TRUE(std::signbit(back.states(2, 2)));
  // All columns in the order written, the action names from our attribute.
  const TrajectorySet all = ReadTrajectories(path, {}, {});
  EXPECT_EQ(all.state_features, set.state_features);
  EXPECT_EQ(all.action_features, set.action_features);
  EXPECT_EQ(all.states, set.states);
  const Hdf5Contents c = InspectHdf5(path);
  EXPECT_TRUE(c.has_demonstrations);
  EXPECT_EQ(c.observation_features, set.state_features);
  EXPECT_TRUE(c.state_sets.empty());
  // What robomimic reads: data.total, data.env_args (a JSON string), demo num_samples, dones.
  {
    const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    long long total = 0, num_samples = 0;
    const hid_t a_total = H5Aopen_by_name(file, "data", "total", H5P_DEFAULT, H5P_DEFAULT);
    H5Aread(a_total, H5T_NATIVE_LLONG, &total);
    H5Aclose(a_total);
    const hid_t a_n = H5Aopen_by_name(file, "data/demo_1", "num_samples", H5P_DEFAULT, H5P_DEFAULT);
    H5Aread(a_n, H5T_NATIVE_LLONG, &num_samples);
    H5Aclose(a_n);
    EXPECT_EQ(total, 9);
    EXPECT_EQ(num_samples, 1);
    const hid_t a_env = H5Aopen_by_name(file, "data", "env_args", H5P_DEFAULT, H5P_DEFAULT);
    const hid_t type = H5Aget_type(a_env);
    EXPECT_GT(H5Tis_variable_str(type), 0);
    char* env = nullptr;
    H5Aread(a_env, type, &env);
    EXPECT_EQ(std::string(env), R"({"env_name": "secure", "type": 2, "env_kwargs": {}})");
    H5free_memory(env);
    H5Tclose(type);
    H5Aclose(a_env);
    long long dones[4] = {};
    const hid_t d = H5Dopen2(file, "data/demo_0/dones", H5P_DEFAULT);
    H5Dread(d, H5T_NATIVE_LLONG, H5S_ALL, H5S_ALL, H5P_DEFAULT, dones);
    H5Dclose(d);
    EXPECT_EQ(std::vector<long long>(dones, dones + 4), (std::vector<long long>{0, 0, 0, 1}));
    H5Fclose(file);
  }
  // Same data, same bytes (no time stamps).
  const std::string again = PathOf("again.hdf5");
  WriteTrajectories(again, set);
  EXPECT_EQ(ReadFile(path), ReadFile(again));
}

TEST_F(Hdf5Test, StateSetsByLabel) {
  const StateSet safe{"", {"x", "y"}, (Eigen::MatrixXf(2, 3) << 1, 2, 3, 4, 5, 6).finished()};
  const StateSet nd{"", {"x", "y"}, (Eigen::MatrixXf(2, 1) << -1, -2).finished()};
  const TrajectorySet demos = RandomDemos();
  const std::string both = PathOf("all.h5");
  WriteHdf5(both, &demos, {{kSafeLabel, &safe}, {kNearDangerousLabel, &nd}});
  EXPECT_EQ(ReadStateSet(both, {}, kSafeLabel).states, safe.states);
  EXPECT_EQ(ReadStateSet(both, {"y"}, kNearDangerousLabel).states,
            (Eigen::MatrixXf(1, 1) << -2).finished());
  EXPECT_EQ(InspectHdf5(both).state_sets,
            (std::vector<std::string>{kSafeLabel, kNearDangerousLabel}));
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(both, {}, "other"); }),
                    {both, "no state set 'safety/other'", "the file has 2: safe, near_dangerous"});
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(both); }), {both, "name the state set to read"});
  // One set: read whatever its label (the file name's stem by default).
  const std::string one = PathOf("check_safe.h5");
  WriteStateSet(one, safe);
  EXPECT_EQ(InspectHdf5(one).state_sets, (std::vector<std::string>{"check_safe"}));
  EXPECT_EQ(ReadStateSet(one, {"x", "y"}, kSafeLabel).states, safe.states);
  EXPECT_EQ(ReadStateSet(one).features, safe.features);
}

// ---------------------------------------------------------------------------------------------
// Bad files: one line naming the file, the dataset and the index.

TEST_F(Hdf5Test, RejectsFilesThatAreNotHdf5) {
  const std::string text = Write("demos.h5", "episode,x\n0,1\n");
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(text, {"x"}, {}); }),
                    {text, "not an HDF5 file"});
  const std::string missing = PathOf("missing.h5");
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(missing); }), {missing});
  // A truncated file keeps its signature but not its content.
  const std::string good = PathOf("good.h5");
  WriteTrajectories(good, RandomDemos());
  const std::string bytes = ReadFile(good);
  const std::string cut = Write("cut.h5", bytes.substr(0, bytes.size() / 3));
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(cut, {}, {}); }), {cut});
}

TEST_F(Hdf5Test, RejectsMissingGroupsAndKeys) {
  const std::string path = PathOf("demos.h5");
  {
    Hdf5TestFile f(path);
    f.Demo(0, 3);
    f.Floats("data/demo_1/obs/pos", {2, 2}, {1, 2, 3, 4});  // no vel, no actions
  }
  ExpectContainsAll(ErrorOf([&] {
                      ReadTrajectories(path, {"pos", "vel"}, {});
                    }),
                    {path, "data/demo_1/obs", "no key 'vel'"});
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"pos"}, kActions); }),
                    {path, "data/demo_1/actions"});
  // An unknown key lists the available ones.
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"speed"}, {}); }),
                    {path, "data/demo_0/obs", "no key or column 'speed'",
                     "pos (2 columns: pos[0] .. pos[1]), vel"});
  ExpectContainsAll(
      ErrorOf([&] { ReadTrajectories(path, {"pos"}, {"throttle"}); }),
      {path, "data/demo_0/actions", "no action column 'throttle'", "actions[0], actions[1]"});
  const std::string empty = PathOf("empty.h5");
  {
    Hdf5TestFile f(empty);
    f.Group("mask");
  }
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(empty, {"x"}, {}); }),
                    {empty, "no group 'data'"});
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(empty); }), {empty, "neither group"});
  const std::string no_demos = PathOf("no_demos.h5");
  {
    Hdf5TestFile f(no_demos);
    f.Group("data/trajectory_0");
  }
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(no_demos, {"x"}, {}); }),
                    {no_demos, "data/trajectory_0", "not a demo"});
  const std::string no_obs = PathOf("no_obs.h5");
  {
    Hdf5TestFile f(no_obs);
    f.Floats("data/demo_0/actions", {1, 1}, {1});
  }
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(no_obs, {"x"}, {}); }),
                    {no_obs, "no group 'data/demo_0/obs'"});
}

TEST_F(Hdf5Test, RejectsWrongRankShapeAndType) {
  const std::string path = PathOf("demos.h5");
  {
    Hdf5TestFile f(path);
    f.Doubles("data/demo_0/obs/image", {2, 2, 2}, std::vector<double>(8, 0.0));
    f.Doubles("data/demo_0/obs/x", {2}, {1, 2});
  }
  // An unusable key (robomimic's images) is an error only when selected, or with no selection.
  for (const std::vector<std::string>& select :
       {std::vector<std::string>{"image"}, std::vector<std::string>{}}) {
    ExpectContainsAll(
        ErrorOf([&] { ReadStateSet(path, select); }),
        {path, "data/demo_0/obs/image", "shape (2, 2, 2) has rank 3", "expected (T,) or (T, k)"});
  }
  EXPECT_EQ(ReadStateSet(path, {"x"}).size(), 2);
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(path, {"y"}); }),
                    {"the keys are: image (not (T,) or (T, k) float), x"});
  // Every key is checked when the keys are listed; the others one file each.
  const std::string types = PathOf("types.h5");
  {
    Hdf5TestFile f(types);
    f.Ints("safety/safe/obs/count", {2}, {1, 2});
  }
  ExpectContainsAll(
      ErrorOf([&] { ReadStateSet(types); }),
      {types, "safety/safe/obs/count", "data type is int64 (shape (2,))",
       "expected float32 or float64"});
  const std::string zero = PathOf("zero.h5");
  {
    Hdf5TestFile f(zero);
    f.Doubles("safety/safe/obs/none", {2, 0}, {});
  }
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(zero); }),
                    {zero, "safety/safe/obs/none", "(2, 0) has no columns"});
  const std::string group = PathOf("group.h5");
  {
    Hdf5TestFile f(group);
    f.Group("safety/safe/obs/nested");
  }
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(group); }),
                    {group, "safety/safe/obs/nested is a group"});
}

// A robomimic file as released: low-dimensional keys beside (T, H, W, C) uint8 images. The
// images are read only when selected (an error naming the file, the dataset and its dtype);
// InspectHdf5 lists them apart.
TEST_F(Hdf5Test, RobomimicImageKeysAreAnErrorOnlyWhenSelected) {
  const std::string path = PathOf("image.hdf5");
  {
    Hdf5TestFile f(path);
    for (int d = 0; d < 2; ++d) {
      const std::string demo = "data/demo_" + std::to_string(d);
      f.UInt8s(demo + "/obs/agentview_image", {3, 4, 4, 3}, std::vector<unsigned char>(144, 7));
      f.Doubles(demo + "/obs/robot0_eef_pos", {3, 3}, {1, 2, 3, 4, 5, 6, 7, 8, 9});
      f.Floats(demo + "/obs/object", {3, 2}, {0, 1, 2, 3, 4, 5});
      f.Doubles(demo + "/actions", {3, 2}, {0.5, -0.5, 1, -1, 2, -2});
      f.IntAttribute(demo, "num_samples", 3);
    }
    f.Group("mask");
  }
  const Hdf5Contents c = InspectHdf5(path);
  EXPECT_TRUE(c.has_demonstrations);
  EXPECT_EQ(c.observation_features,
            (std::vector<std::string>{"object[0]", "object[1]", "robot0_eef_pos[0]",
                                      "robot0_eef_pos[1]", "robot0_eef_pos[2]"}));
  EXPECT_EQ(c.unreadable_obs_keys, (std::vector<std::string>{"agentview_image"}));
  EXPECT_EQ(c.action_features, kActions);

  const TrajectorySet set = ReadTrajectories(path, {"robot0_eef_pos"}, {});
  EXPECT_EQ(set.state_features,
            (std::vector<std::string>{"robot0_eef_pos[0]", "robot0_eef_pos[1]",
                                      "robot0_eef_pos[2]"}));
  EXPECT_EQ(set.episode_begin, (std::vector<long>{0, 3, 6}));
  EXPECT_EQ(set.states.col(4), Eigen::Vector3f(4, 5, 6));
  EXPECT_EQ(set.actions.col(5), Eigen::Vector2f(2, -2));
  EXPECT_EQ(ReadStateSet(path, {"object[1]"}).size(), 6);

  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"object", "agentview_image"}, {}); }),
                    {path, "data/demo_0/obs/agentview_image",
                     "data type is uint8 (shape (3, 4, 4, 3)), expected float32 or float64"});
  // With no selection every key is read: the message names the keys to select.
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {}, {}); }),
                    {path, "data/demo_0/obs/agentview_image", "data type is uint8",
                     "select the others by name (object, robot0_eef_pos)"});
}

// What robomimic reads beyond obs and actions: next_obs, and the filter keys mask/train and
// mask/valid (fixed-length byte strings, as h5py writes np.array(names, dtype="S")).
TEST_F(Hdf5Test, WritesNextObsAndRobomimicFilterKeys) {
  TrajectorySet set;
  set.state_features = {"p[0]", "p[1]", "v"};
  set.action_features = {"a"};
  const long demos = 12;
  for (long k = 0; k <= demos; ++k) set.episode_begin.push_back(3 * k - (k > 0 ? 1 : 0));
  set.episode_begin.front() = 0;  // demo 0: 2 steps, the others 3
  const long steps = set.episode_begin.back();
  set.states.resize(3, steps);
  set.actions.resize(1, steps);
  for (long t = 0; t < steps; ++t) {
    set.states.col(t) << float(t), float(10 * t), float(-t);
    set.actions(0, t) = float(t) / 2;
  }
  const std::string path = PathOf("masks.hdf5");
  WriteTrajectories(path, set);

  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  // next_obs of demo_1 (steps 2, 3, 4): rows 3, 4, 4 of p (the last repeats).
  {
    std::vector<double> next(6), obs(6);
    const hid_t d = H5Dopen2(file, "data/demo_1/next_obs/p", H5P_DEFAULT);
    H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, next.data());
    H5Dclose(d);
    EXPECT_EQ(next, (std::vector<double>{3, 30, 4, 40, 4, 40}));
    const hid_t v = H5Dopen2(file, "data/demo_1/next_obs/v", H5P_DEFAULT);
    const hid_t space = H5Dget_space(v);
    hsize_t dims[2] = {};
    EXPECT_EQ(H5Sget_simple_extent_ndims(space), 2);
    H5Sget_simple_extent_dims(space, dims, nullptr);
    EXPECT_EQ(dims[0], 3u);
    EXPECT_EQ(dims[1], 1u);
    H5Sclose(space);
    H5Dclose(v);
  }
  const auto strings = [&](const char* name) {
    const hid_t d = H5Dopen2(file, name, H5P_DEFAULT);
    const hid_t type = H5Dget_type(d);
    EXPECT_EQ(H5Tget_class(type), H5T_STRING) << name;
    EXPECT_LE(H5Tis_variable_str(type), 0) << name << ": robomimic's are fixed-length";
    const std::size_t width = H5Tget_size(type);
    const hid_t space = H5Dget_space(d);
    const hssize_t n = H5Sget_simple_extent_npoints(space);
    std::string bytes(width * static_cast<std::size_t>(n), '\0');
    if (n > 0) H5Dread(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, bytes.data());
    std::vector<std::string> out;
    for (hssize_t i = 0; i < n; ++i) {
      std::string s = bytes.substr(static_cast<std::size_t>(i) * width, width);
      out.push_back(s.substr(0, s.find('\0')));
    }
    H5Sclose(space);
    H5Tclose(type);
    H5Dclose(d);
    return out;
  };
  EXPECT_EQ(strings("mask/valid"), (std::vector<std::string>{"demo_9"}));
  std::vector<std::string> train;
  for (long k = 0; k < demos; ++k)
    if (k != 9) train.push_back("demo_" + std::to_string(k));
  EXPECT_EQ(strings("mask/train"), train);
  H5Fclose(file);
  // Our reader ignores next_obs and mask/: the data read back as written.
  const TrajectorySet back = ReadTrajectories(path, {}, {});
  EXPECT_EQ(back.states, set.states);
  EXPECT_EQ(back.episode_begin, set.episode_begin);

  // The split rule: every tenth demo; with 2 to 9 demos the last; one demo trains.
  const auto valid = [](long n) {
    std::vector<long> v;
    for (long k = 0; k < n; ++k)
      if (IsValidationDemo(k, n)) v.push_back(k);
    return v;
  };
  EXPECT_EQ(valid(1), std::vector<long>{});
  EXPECT_EQ(valid(2), std::vector<long>{1});
  EXPECT_EQ(valid(9), std::vector<long>{8});
  EXPECT_EQ(valid(10), std::vector<long>{9});
  EXPECT_EQ(valid(25), (std::vector<long>{9, 19}));
  // One demo: an empty valid key, still a (0,) dataset robomimic can read.
  TrajectorySet one = set;
  one.episode_begin = {0, steps};
  const std::string single = PathOf("single.hdf5");
  WriteTrajectories(single, one);
  const hid_t f1 = H5Fopen(single.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(f1, 0);
  const hid_t d = H5Dopen2(f1, "mask/valid", H5P_DEFAULT);
  EXPECT_GE(d, 0);
  const hid_t space = H5Dget_space(d);
  EXPECT_EQ(H5Sget_simple_extent_npoints(space), 0);
  H5Sclose(space);
  H5Dclose(d);
  H5Fclose(f1);
}

TEST_F(Hdf5Test, RejectsNonFiniteValuesNamingRowAndColumn) {
  const std::string nan = PathOf("nan.h5");
  {
    Hdf5TestFile f(nan);
    f.Demo(0, 3);
    f.Doubles("data/demo_1/obs/pos", {3, 2}, {0, 0, 0, 0, 0, std::nan("")});
    f.Doubles("data/demo_1/obs/vel", {3}, {0, 0, 0});
    f.Floats("data/demo_1/actions", {3, 2}, {0, 0, 0, 0, 0, 0});
  }
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(nan, {"pos"}, {}); }),
                    {nan, "data/demo_1/obs/pos: row 2, column 1: value nan is not finite"});
  const std::string inf = PathOf("inf.h5");
  {
    Hdf5TestFile f(inf);
    f.Doubles("safety/near_dangerous/obs/x", {2}, {1, -HUGE_VAL});
    f.Doubles("safety/near_dangerous/obs/y", {2}, {1e300, 1});
  }
  ExpectContainsAll(
      ErrorOf([&] { ReadStateSet(inf, {"x"}); }),
      {inf, "safety/near_dangerous/obs/x: row 1, column 0: value -inf is not finite"});
  ExpectContainsAll(ErrorOf([&] { ReadStateSet(inf, {"y"}); }),
                    {inf,
                     "safety/near_dangerous/obs/y: row 0, column 0: value 1e+300 is out of "
                     "the float range"});
}

TEST_F(Hdf5Test, RejectsLengthMismatchesAndEmptyDemos) {
  const std::string path = PathOf("demos.h5");
  {
    Hdf5TestFile f(path);
    f.Doubles("data/demo_0/obs/x", {3}, {1, 2, 3});
    f.Doubles("data/demo_0/obs/y", {2}, {1, 2});
    f.Doubles("data/demo_0/actions", {2, 1}, {1, 2});
  }
  ExpectContainsAll(ErrorOf([&] {
                      ReadTrajectories(path, {"x", "y"}, {});
                    }),
                    {path, "data/demo_0/obs/y: 2 rows, but data/demo_0/obs/x has 3"});
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(path, {"x"}, {"actions"}); }),
                    {path, "data/demo_0/actions: 2 rows, but data/demo_0/obs/x has 3"});
  const std::string empty = PathOf("empty.h5");
  {
    Hdf5TestFile f(empty);
    f.Demo(0, 2);
    f.Demo(1, 0);
  }
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(empty, {"pos"}, kActions); }),
                    {empty, "data/demo_1: empty demo (0 steps)"});
  const std::string samples = PathOf("samples.h5");
  {
    Hdf5TestFile f(samples);
    f.Demo(0, 2);
    f.IntAttribute("data/demo_0", "num_samples_x", 0);
    f.IntAttribute("data", "total", 2);
  }
  EXPECT_EQ(ReadTrajectories(samples, {"pos"}, kActions).num_steps(), 2);
  const std::string widths = PathOf("widths.h5");
  {
    Hdf5TestFile f(widths);
    f.Demo(0, 2);
    f.Demo(1, 2, {"pos", "vel"}, {3, 1});
  }
  ExpectContainsAll(ErrorOf([&] { ReadTrajectories(widths, {"pos"}, kActions); }),
                    {widths, "data/demo_1/obs/pos: 3 columns, but 2"});
}

TEST_F(Hdf5Test, WriterRejectsWhatWouldNotReadBack) {
  TrajectorySet set = RandomDemos();
  set.state_features[0] = "a/b";
  ExpectContainsAll(ErrorOf([&] { WriteTrajectories(PathOf("x.h5"), set); }),
                    {"x.h5", "feature 'a/b'"});
  set = RandomDemos();
  set.state_features[0] = "pos";  // "pos" and "pos[0..2]" would be one key twice
  ExpectContainsAll(ErrorOf([&] { WriteTrajectories(PathOf("x.h5"), set); }),
                    {"x.h5", "obs key 'pos' would be written twice"});
  set = RandomDemos();
  set.states(3, 4) = std::numeric_limits<float>::quiet_NaN();
  ExpectContainsAll(ErrorOf([&] { WriteTrajectories(PathOf("x.h5"), set); }),
                    {"x.h5", "feature 'pos[2]', row 4", "not finite"});
  EXPECT_FALSE(std::filesystem::exists(PathOf("x.h5")));
}

// Issue 34: a 10 KB file declaring a (2e9,) dataset (chunked, never written) and num_samples =
// 2e9 made `demos convert` allocate 16 GB. The declared size is checked before anything is read.
TEST_F(Hdf5Test, ADeclaredSizeOverTheInputLimitFailsBeforeAllocating) {
  const std::string path = PathOf("bomb.h5");
  {
    Hdf5TestFile f(path);
    f.Unwritten("data/demo_0/obs/pos", {2'000'000'000});
    f.Unwritten("data/demo_0/actions", {2'000'000'000, 2});
    f.IntAttribute("data/demo_0", "num_samples", 2'000'000'000);
  }
  EXPECT_LT(std::filesystem::file_size(path), 100'000u);
  const std::string message = ErrorOf([&] { ReadTrajectories(path, {}, {}); });
  ExpectContainsAll(message, {path, "data/demo_0/obs/pos", "(2000000000,)", "declares",
                              "over the input limit of 4294967296 bytes",
                              "SECURE_MAX_INPUT_BYTES"});
  const std::string states = ErrorOf([&] { ReadStateSet(path, {}); });
  EXPECT_NE(states.find("over the input limit"), std::string::npos) << states;
}

TEST_F(Hdf5Test, ManySmallDatasetsCountTogetherAgainstTheLimit) {
  const std::string path = PathOf("many.h5");
  {
    Hdf5TestFile f(path);
    for (const char* demo : {"data/demo_0", "data/demo_1"}) {
      f.Unwritten(std::string(demo) + "/obs/pos", {1000});
      f.Unwritten(std::string(demo) + "/actions", {1000, 2});
    }
  }
  ASSERT_LT(std::filesystem::file_size(path), 30'000u);
  const InputLimits saved = GetInputLimits();
  InputLimits limits = saved;
  // Demo 0's datasets (1000 x (1 + 2) doubles = 24000 bytes) fit, demo 1's do not.
  limits.max_input_bytes = 30'000;
  SetInputLimits(limits);
  const std::string message = ErrorOf([&] { ReadTrajectories(path, {}, {}); });
  SetInputLimits(saved);
  ExpectContainsAll(message, {path, "data/demo_1", "over the input limit of 30000 bytes"});
  EXPECT_EQ(ReadTrajectories(path, {}, {}).num_steps(), 2000);
}

}  // namespace
}  // namespace secure::data
