// Sharded experiments (secure/experiments/experiment.h, docs/CLUSTER.md): a quick experiment run
// unsharded, and as shards -- `--shard k/N`, simulated SLURM array elements, `mpirun -np 2` ranks
// -- then `secure experiment merge`d, gives the same result.json and table. The comparison is
// exact on every number but the timing fields: keys containing "second" (seconds, data_seconds)
// and the measured decision latencies ("latency_us", the table's last column); `context` (the
// build) is not in result.json.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/json_util.h"
#include "tests/test_util.h"

namespace {

namespace fs = std::filesystem;

struct Result {
  int exit_code;
  std::string out, err;
};

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The experiment of every test: the double integrator's method comparison, small. The driver
// variables of the environment are unset so that only a test's own shard variables count.
const std::string kExperiment =
    "experiment method-comparison --domain double-integrator --quick --seeds 3 --episodes 6 "
    "--threads 1";
const std::string kClean =
    "env -u SLURM_ARRAY_TASK_ID -u SLURM_ARRAY_TASK_COUNT -u SLURM_ARRAY_TASK_MIN "
    "-u OMPI_COMM_WORLD_RANK -u OMPI_COMM_WORLD_SIZE -u PMI_RANK -u PMI_SIZE -u PMIX_RANK ";

class ShardTest : public secure::test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    // mpirun refuses root without these (CI runs as root).
    ::setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 1);
    ::setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 1);
  }

  // Runs `prefix secure args` (prefix: environment assignments, a launcher) in the shell; stdout
  // and stderr of the command (all its processes) are captured.
  Result Run(const std::string& args, const std::string& prefix = "") {
    const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    const std::string cmd = kClean + prefix + " " + SECURE_CLI + " " + args + " >" + out.string() +
                            " 2>" + err.string();
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, Slurp(out), Slurp(err)};
  }

  // Runs two commands at once (the shards), each with its own prefix; both must succeed.
  void RunTwo(const std::string& prefix0, const std::string& args0, const std::string& prefix1,
              const std::string& args1) {
    const std::string cmd = "(" + kClean + prefix0 + " " + SECURE_CLI + " " + args0 + " >" +
                            (dir_ / "s0.out").string() + " 2>" + (dir_ / "s0.err").string() +
                            " & " + kClean + prefix1 + " " + SECURE_CLI + " " + args1 + " >" +
                            (dir_ / "s1.out").string() + " 2>" + (dir_ / "s1.err").string() +
                            " ; r1=$?; wait $!; r0=$?; test $r0 = 0 -a $r1 = 0)";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << Slurp(dir_ / "s0.err") << "\n---\n"
                                           << Slurp(dir_ / "s1.err");
  }

  // The unsharded reference: its result.json and stdout (the table).
  // It runs in <dir>/run and is then moved to <dir>/full, so that a sharded run into <dir>/run
  // names the same paths (models record their learning curve's path).
  void RunReference() {
    const Result r = Run(kExperiment + " --out " + (dir_ / "run").string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    fs::rename(dir_ / "run", dir_ / "full");
    reference_table_ = r.out;
    reference_ = nlohmann::json::parse(Slurp(dir_ / "full" / "result.json"));
  }

  // Merges `dirs` (writing result.json to `out`, or the first directory) and compares with the
  // reference.
  void MergeAndCompare(const std::string& dirs, const fs::path& result_dir,
                       const std::string& extra = "") {
    const Result m = Run("experiment merge " + dirs + extra);
    ASSERT_EQ(m.exit_code, 0) << m.err;
    const nlohmann::json merged = nlohmann::json::parse(Slurp(result_dir / "result.json"));
    EXPECT_EQ(secure::test::WithoutTimings(merged), secure::test::WithoutTimings(reference_));
    EXPECT_EQ(merged["experiment"]["seeds"].size(), 3u);
    // The per-episode outcomes: the same file as the unsharded run's.
    EXPECT_TRUE(Slurp(result_dir / "episodes.csv") == Slurp(dir_ / "full" / "episodes.csv"));
    EXPECT_FALSE(Slurp(result_dir / "episodes.csv").empty());
    EXPECT_EQ(TableWithoutTimings(m.out), TableWithoutTimings(reference_table_));
  }

  // The table without the latency column (each row's last cell) and the total time.
  static std::string TableWithoutTimings(const std::string& table) {
    std::string out, line;
    std::istringstream in(table);
    while (std::getline(in, line)) {
      if (line.rfind("| ", 0) == 0) {
        const std::size_t last = line.rfind(" | ", line.size() - 3);
        if (last != std::string::npos) line = line.substr(0, last);
      }
      const std::size_t total = line.find(" Total ");
      if (total != std::string::npos) line = line.substr(0, total);
      out += line + "\n";
    }
    return out;
  }

  nlohmann::json reference_;
  std::string reference_table_;
};

TEST_F(ShardTest, TwoShardsInOneDirectoryMergeToTheUnshardedResult) {
  RunReference();
  const std::string run = (dir_ / "run").string();
  RunTwo("", kExperiment + " --shard 0/2 --out " + run, "",
         kExperiment + " --shard 1/2 --out " + run);
  EXPECT_HAS(Slurp(dir_ / "s1.err"), "shard 1/2 (from --shard)");
  EXPECT_HAS(Slurp(dir_ / "s0.out"), "seeds 0, 2 computed");
  EXPECT_HAS(Slurp(dir_ / "s1.out"), "seeds 1 computed");
  EXPECT_FALSE(fs::exists(dir_ / "run" / "result.json"));  // the merge writes it
  MergeAndCompare(run, dir_ / "run");
  // The unsharded run's files (result.json, the task files and the learning curves hold
  // timings: same names); the models and the data byte for byte.
  for (const auto& entry : fs::recursive_directory_iterator(dir_ / "full")) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), dir_ / "full");
    ASSERT_TRUE(fs::exists(dir_ / "run" / rel)) << rel;
    const bool compared = (rel.extension() == ".model" || rel.extension() == ".csv") &&
                          rel.string().find("curve") == std::string::npos;
    if (compared) {
      EXPECT_TRUE(Slurp(entry.path()) == Slurp(dir_ / "run" / rel)) << rel << " differs";
    }
  }

  // A rerun of a shard reuses its task files; a shard killed before its task files were
  // written recomputes only its own seeds.
  Result r = Run(kExperiment + " --shard 1/2 --out " + run);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "seeds none computed, 1 reused");
  fs::remove(dir_ / "run" / "seed-2" / "task.json");
  r = Run("experiment merge " + run);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "1 of 3 seeds have no task file (seed 2)");
  r = Run(kExperiment + " --shard 0/2 --out " + run);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "seeds 2 computed, 0 reused");
  MergeAndCompare(run, dir_ / "run");
}

TEST_F(ShardTest, SlurmArrayElementsInTheirOwnDirectoriesMergeToTheUnshardedResult) {
  RunReference();
  const std::string a = (dir_ / "a").string(), b = (dir_ / "b").string();
  RunTwo("SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=2", kExperiment + " --out " + a,
         "SLURM_ARRAY_TASK_ID=1 SLURM_ARRAY_TASK_COUNT=2", kExperiment + " --out " + b);
  const std::string err = Slurp(dir_ / "s1.err");
  EXPECT_EQ(err.rfind("shard 1/2 (from SLURM_ARRAY_TASK_ID/COUNT): secure experiment", 0), 0u)
      << "the first line says where the shard came from: " << err;
  EXPECT_TRUE(fs::exists(dir_ / "a" / "demos.csv"));  // the data: shard 0 writes it
  EXPECT_FALSE(fs::exists(dir_ / "b" / "demos.csv"));
  MergeAndCompare(a + " " + b, dir_ / "merged", " --out " + (dir_ / "merged").string());
}

TEST_F(ShardTest, MpirunRanksMergeToTheUnshardedResult) {
  ASSERT_EQ(std::system("command -v mpirun >/dev/null"), 0)
      << "mpirun not found: scripts/setup.sh installs it (Debian package openmpi-bin)";
  RunReference();
  const std::string run = (dir_ / "run").string();
  const Result r =
      Run(kExperiment + " --out " + run, "mpirun -np 2 --oversubscribe --allow-run-as-root");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.err, "shard 0/2 (from OMPI_COMM_WORLD_RANK/SIZE)");
  EXPECT_HAS(r.err, "shard 1/2 (from OMPI_COMM_WORLD_RANK/SIZE)");
  MergeAndCompare(run, dir_ / "run");
}

// Cheap runs (BC only, two episodes): the checks of merge and of the task files.
TEST_F(ShardTest, MergeNamesMissingDuplicateAndForeignTasks) {
  const std::string cheap =
      "experiment method-comparison --domain double-integrator --quick --seeds 2 --episodes 2 "
      "--methods bc --threads 1";
  const std::string a = (dir_ / "a").string(), b = (dir_ / "b").string();
  ASSERT_EQ(Run(cheap + " --shard 0/2 --out " + a).exit_code, 0);
  // An array --array=4-5 (SLURM_ARRAY_TASK_MIN = 4): element 5 is shard 1/2.
  Result r = Run(cheap + " --out " + b,
                 "SLURM_ARRAY_TASK_ID=5 SLURM_ARRAY_TASK_COUNT=2 SLURM_ARRAY_TASK_MIN=4");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.rfind("shard 1/2 (from SLURM_ARRAY_TASK_ID-MIN/COUNT)", 0), 0u) << r.err;
  r = Run("experiment merge " + a + " " + b + " " + a);  // a twice: once
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The merged directory (a) links the other shard's seed directory, so that it holds every
  // seed's models and curves for `secure report`; merging again reads that seed once.
  EXPECT_HAS(r.err, "linked 1 seed directory");
  EXPECT_TRUE(fs::is_symlink(dir_ / "a" / "seed-1"));
  EXPECT_TRUE(fs::equivalent(dir_ / "a" / "seed-1", dir_ / "b" / "seed-1"));
  EXPECT_FALSE(fs::is_symlink(dir_ / "a" / "seed-0"));
  r = Run("experiment merge " + a + " " + b);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("linked"), std::string::npos) << r.err;
  fs::remove(dir_ / "a" / "seed-1");
  // Missing: only one shard's directory.
  r = Run("experiment merge " + b);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "(seed 0)");
  // Duplicate: seed 1 in both directories.
  fs::copy(dir_ / "b" / "seed-1", dir_ / "a" / "seed-1", fs::copy_options::recursive);
  r = Run("experiment merge " + a + " " + b);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "seed 1 is there twice");
  fs::remove_all(dir_ / "a" / "seed-1");
  // Another experiment (more episodes) in b: merge names the files and the difference; a rerun
  // into b with the first experiment's options refuses to reuse it, naming the file.
  fs::remove_all(dir_ / "b");
  ASSERT_EQ(Run("experiment method-comparison --domain double-integrator --quick --seeds 2 "
                "--episodes 3 --methods bc --shard 1/2 --out " +
                b)
                .exit_code,
            0);
  r = Run("experiment merge " + a + " " + b);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "are tasks of different experiments (options.episodes: ");
  r = Run(cheap + " --shard 1/2 --out " + b);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, (dir_ / "b" / "seed-1" / "task.json").string());
  EXPECT_HAS(r.err, "options.episodes: 3 vs 2");
  // Not a task file.
  std::ofstream(dir_ / "b" / "seed-1" / "task.json") << "{ truncated";
  r = Run("experiment merge " + a + " " + b);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "seed-1/task.json: not a task file");
  // No task file at all.
  r = Run("experiment merge " + (dir_ / "a" / "seed-0").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "no task file");
}

TEST_F(ShardTest, BadShardValuesAreOneLineErrors) {
  const std::string run = " --out " + (dir_ / "x").string();
  const struct {
    std::string prefix, args, message;
  } cases[] = {
      {"", "--shard 2/2" + run, "--shard '2/2': expected k/N"},
      {"", "--shard 1/0" + run, "--shard '1/0'"},
      {"", "--shard a/b" + run, "--shard 'a/b'"},
      {"", "--shard 1" + run, "--shard '1'"},
      {"", "--shard -1/2" + run, "--shard '-1/2'"},
      {"", "--shard 1/2", "needs --out"},
      {"SLURM_ARRAY_TASK_ID=x SLURM_ARRAY_TASK_COUNT=2", run,
       "SLURM_ARRAY_TASK_ID = 'x' is not a non-negative integer"},
      {"SLURM_ARRAY_TASK_ID=1", run, "SLURM_ARRAY_TASK_COUNT is not"},
      {"SLURM_ARRAY_TASK_ID=2 SLURM_ARRAY_TASK_COUNT=2", run, "not below SLURM_ARRAY_TASK_COUNT"},
      {"SLURM_ARRAY_TASK_ID=1 SLURM_ARRAY_TASK_COUNT=2 SLURM_ARRAY_TASK_MIN=3", run,
       "SLURM_ARRAY_TASK_MIN = '3' is above"},
      {"OMPI_COMM_WORLD_RANK=1 OMPI_COMM_WORLD_SIZE=two", run,
       "OMPI_COMM_WORLD_SIZE = 'two' is not a non-negative integer"},
      {"PMI_RANK=3 PMI_SIZE=2", run, "PMI_RANK = '3' must be below PMI_SIZE"},
      {"PMIX_RANK=2 PMI_SIZE=2", run, "PMIX_RANK = '2' must be below PMI_SIZE"},
      {"PMI_RANK=1 PMI_SIZE=2", "", "needs --out"},
      {"SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=2 OMPI_COMM_WORLD_RANK=1 "
       "OMPI_COMM_WORLD_SIZE=2",
       run, "give --shard k/N"},
  };
  for (const auto& c : cases) {
    const Result r = Run("demo --quick " + c.args, c.prefix);
    EXPECT_EQ(r.exit_code, 1) << c.prefix << " " << c.args;
    EXPECT_HAS(r.err, c.message);
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "one line: " << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "x" / "demos.csv"));  // before any work
  }
  // A world of one is no shard: the ordinary run (only its first line says where it came from).
  const Result one = Run("demo --quick --seeds 1 --episodes 1 --methods bc" + run,
                         "OMPI_COMM_WORLD_RANK=0 OMPI_COMM_WORLD_SIZE=1");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_EQ(one.err.rfind("shard 0/1 (from OMPI_COMM_WORLD_RANK/SIZE): secure demo", 0), 0u);
  EXPECT_TRUE(fs::exists(dir_ / "x" / "result.json"));
}

}  // namespace
