// Fault injection: the `secure` binary is killed with SIGKILL at random points of a barrier
// training, an AIRL training with checkpoints and an experiment run; the command is then run again
// (with --resume where it has one) until it completes. The final artefacts must equal those of an
// uninterrupted run byte for byte (result documents: every field but timings), and no temporary
// or partial file may be left behind.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "secure/common/rng.h"
#include "tests/json_util.h"
#include "tests/test_util.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

class FaultInjectionTest : public secure::test::TempDirTest {
 protected:
  // Runs `secure args...` to completion; returns its exit code (-signal if killed).
  int Run(const std::vector<std::string>& args) { return Spawn(args, -1.0); }

  // Starts `secure args...` and kills it with SIGKILL after `seconds` unless it ended before;
  // returns true if it was killed.
  bool RunAndKill(const std::vector<std::string>& args, double seconds) {
    return Spawn(args, seconds) == -SIGKILL;
  }

  // Seconds an uninterrupted run takes (measured, so that kill points fall inside the run).
  double Time(const std::vector<std::string>& args) {
    const auto start = Clock::now();
    EXPECT_EQ(Run(args), 0);
    return std::chrono::duration<double>(Clock::now() - start).count();
  }

  // Kills `args` at `kills` random points of an uninterrupted run's duration, each followed by
  // a restart of `restart` that is killed again; then runs `restart` to completion.
  void KillAndRestart(const std::vector<std::string>& args, const std::vector<std::string>& restart,
                      double duration, int kills, std::uint64_t seed) {
    secure::Rng rng(seed);
    int killed = 0;
    for (int k = 0; k < kills; ++k) {
      // A run may be faster than the measured reference (the machine's load varies): if it ended
      // before its kill point, the next attempt kills it at half that time.
      double at = rng.Uniform(0.05, 0.95) * duration;
      bool was_killed = false;
      for (int attempt = 0; attempt < 6 && !was_killed; ++attempt, at *= 0.5)
        was_killed = RunAndKill(k == 0 && killed == 0 ? args : restart, at);
      killed += was_killed;
    }
    EXPECT_GE(killed, 1) << "no run was interrupted: the test did not test anything";
    ASSERT_EQ(Run(restart), 0) << ReadOr(dir_ / "stderr.txt");
  }

  static std::string ReadOr(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }

  // Every regular file under `root`, by relative path, with its bytes.
  static std::map<std::string, std::string> Files(const fs::path& root) {
    std::map<std::string, std::string> files;
    for (const auto& entry : fs::recursive_directory_iterator(root))
      if (entry.is_regular_file())
        files[fs::relative(entry.path(), root).string()] = ReadOr(entry.path());
    return files;
  }

  // The same files with the same bytes (names, not contents, in failure messages).
  static void ExpectSameFiles(const std::map<std::string, std::string>& got,
                              const std::map<std::string, std::string>& want) {
    for (const auto& [name, bytes] : want) {
      const auto it = got.find(name);
      if (it == got.end()) {
        ADD_FAILURE() << name << " is missing after the interrupted runs";
      } else {
        EXPECT_TRUE(it->second == bytes) << name << " differs from the uninterrupted run's";
      }
    }
    for (const auto& [name, bytes] : got)
      EXPECT_EQ(want.count(name), 1u) << name << " was not written by the uninterrupted run";
  }

  // Runs the reference in <dir>/work, moves it to <dir>/reference, and returns its duration.
  // The interrupted runs then use <dir>/work too: options that name paths are the same.
  double Reference(const std::vector<std::string>& args) {
    fs::create_directories(dir_ / "work");
    const double seconds = Time(args);
    fs::rename(dir_ / "work", dir_ / "reference");
    fs::create_directories(dir_ / "work");
    return seconds;
  }

  static void ExpectNoTemporaries(const fs::path& root) {
    for (const auto& entry : fs::recursive_directory_iterator(root))
      EXPECT_EQ(entry.path().filename().string().find(".tmp-"), std::string::npos)
          << "left behind: " << entry.path();
  }

 private:
  int Spawn(const std::vector<std::string>& args, double kill_after) {
    std::vector<std::string> argv_storage = {SECURE_CLI};
    argv_storage.insert(argv_storage.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : argv_storage) argv.push_back(a.data());
    argv.push_back(nullptr);
    const std::string out = (dir_ / "stdout.txt").string(), err = (dir_ / "stderr.txt").string();
    const pid_t pid = ::fork();
    if (pid == 0) {
      if (!std::freopen(out.c_str(), "w", stdout) || !std::freopen(err.c_str(), "w", stderr))
        ::_exit(127);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    if (pid < 0) return -1000;
    int status = 0;
    if (kill_after >= 0) {
      const auto deadline = Clock::now() + std::chrono::duration<double>(kill_after);
      while (Clock::now() < deadline) {
        if (::waitpid(pid, &status, WNOHANG) == pid) return Decode(status);
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
      ::kill(pid, SIGKILL);
    }
    ::waitpid(pid, &status, 0);
    return Decode(status);
  }
  static int Decode(int status) {
    return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
  }
};

// Result documents: everything but what measures time (and the build context).
nlohmann::json WithoutTimings(const nlohmann::json& j) {
  return secure::test::WithoutTimings(j, {"context"});
}

TEST_F(FaultInjectionTest, KilledBarrierTrainingRerunsToTheSameModel) {
  const std::vector<std::string> train = {
      "cbf",     "train", "--domain", "double-integrator", "--safe", "400", "--unsafe", "400",
      "--epochs", "60",   "--seed",   "3", "--threads", "1", "--out", (dir_ / "work/cbf.model").string()};
  const double duration = Reference(train);
  KillAndRestart(train, train, duration, 3, 11);
  ExpectSameFiles(Files(dir_ / "work"), Files(dir_ / "reference"));
  ExpectNoTemporaries(dir_ / "work");
}

TEST_F(FaultInjectionTest, KilledAirlTrainingResumesToTheSameModel) {
  const std::string data = (dir_ / "data").string();
  ASSERT_EQ(Run({"demos", "generate", "--domain", "double-integrator", "--episodes", "4", "--out",
                 data}),
            0);
  // --resume from the start: a run killed before its first checkpoint starts afresh.
  const fs::path work = dir_ / "work";
  const std::vector<std::string> train = {
      "policy", "train", "--algo", "airl", "--demos", data + "/demos.csv", "--iterations", "6",
      "--checkpoint-every", "1", "--seed", "5", "--resume",
      "--checkpoint", (work / "airl.ckpt").string(), "--out", (work / "airl.model").string()};
  const double duration = Reference(train);
  KillAndRestart(train, train, duration, 4, 12);
  // The checkpoint records the training's wall time (for the summary across resumes): compared
  // by name only; the model must be identical.
  auto got = Files(work), want = Files(dir_ / "reference");
  got["airl.ckpt"].clear();
  want["airl.ckpt"].clear();
  ExpectSameFiles(got, want);
  ExpectNoTemporaries(work);
}

TEST_F(FaultInjectionTest, KilledExperimentRerunsToTheSameArtefacts) {
  const fs::path work = dir_ / "work";
  const std::vector<std::string> run = {"experiment", "derby-table3", "--quick", "--out",
                                        work.string()};
  const double duration = Reference(run);
  KillAndRestart(run, run, duration, 3, 13);
  auto got = Files(work), want = Files(dir_ / "reference");
  ASSERT_EQ(got.count("result.json"), 1u);
  EXPECT_EQ(WithoutTimings(nlohmann::json::parse(got.at("result.json"))),
            WithoutTimings(nlohmann::json::parse(want.at("result.json"))));
  // The seeds' task files (seed-K/task.json: a rerun reuses a finished seed's instead of
  // recomputing it) hold the seed's results and summary: equal but for timings.
  for (const auto& [name, bytes] : want) {
    if (name.find("task.json") == std::string::npos) continue;
    ASSERT_EQ(got.count(name), 1u) << name;
    EXPECT_EQ(WithoutTimings(nlohmann::json::parse(got.at(name))),
              WithoutTimings(nlohmann::json::parse(bytes)))
        << name;
  }
  // Learning curves record wall time per iteration: compared by name only. The models and the
  // data must be identical.
  for (auto* files : {&got, &want}) {
    files->erase("result.json");
    for (auto& [name, bytes] : *files)
      if (name.find("curve") != std::string::npos || name.find("task.json") != std::string::npos)
        bytes.clear();
  }
  ExpectSameFiles(got, want);
  ExpectNoTemporaries(work);
}

}  // namespace
