// secure report RUN_DIR [--out FILE.html]: one self-contained HTML page (figures embedded) for a
// run directory of `secure demo --out` / `secure experiment --out`. The page is drawn by the
// Python script tools/report/report.py (matplotlib, Agg backend) under Debian's /usr/bin/python3;
// this command checks the run directory first (one-line errors naming the file), then runs the
// script with PYTHONPATH set to the build tree's Python module (for the barrier pictures).
//
// Where things are (configured at build time, each overridable by an environment variable):
//   SECURE_REPORT_SCRIPT      the script       (default <source>/tools/report/report.py)
//   SECURE_REPORT_PYTHON      the interpreter  (default /usr/bin/python3)
//   SECURE_REPORT_PYTHONPATH  prepended to PYTHONPATH (default <build>/python: `import secure`)
#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <unistd.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/input_limits.h"

extern char** environ;

namespace secure::cli {
namespace {

#ifndef SECURE_REPORT_SCRIPT_DEFAULT
#define SECURE_REPORT_SCRIPT_DEFAULT "tools/report/report.py"
#endif
#ifndef SECURE_REPORT_PYTHON_DEFAULT
#define SECURE_REPORT_PYTHON_DEFAULT "/usr/bin/python3"
#endif
#ifndef SECURE_REPORT_PYTHONPATH_DEFAULT
#define SECURE_REPORT_PYTHONPATH_DEFAULT ""
#endif

std::string EnvOr(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? std::string(v) : std::string(fallback);
}

// RUN_DIR must be a directory holding a result.json with an "experiment" object (or, from
// `secure reproduce`, a reproduce.json).
void CheckRunDirectory(const std::string& run_dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(run_dir, ec);
  SECURE_CHECK(fs::exists(st), run_dir << ": no such directory");
  SECURE_CHECK(fs::is_directory(st),
               run_dir << ": not a directory (expected a run directory written by `secure demo "
                          "--out` or `secure experiment --out`)");
  const std::string path = (fs::path(run_dir) / "result.json").string();
  // A `secure reproduce --out` directory (reproduce.json, no result.json): the script checks it.
  if (!fs::exists(fs::status(path, ec)) &&
      fs::is_regular_file(fs::status(fs::path(run_dir) / "reproduce.json", ec)))
    return;
  SECURE_CHECK(fs::is_regular_file(fs::status(path, ec)),
               path << ": missing: " << run_dir
                    << " is not a run directory (written by `secure demo --out` or `secure "
                       "experiment --out`)");
  const std::string text = ReadFile(path);
  nlohmann::json result;
  try {
    result = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    SECURE_THROW(path << ": malformed JSON: " << e.what());
  }
  // A label-efficiency run (issue 35; "experiment": "label-efficiency"): the script checks its
  // curves (tools/report/label_efficiency_page.py).
  if (result.is_object() && result.contains("experiment") &&
      result["experiment"] == "label-efficiency")
    return;
  SECURE_CHECK(result.is_object() && result.contains("experiment") &&
                   result["experiment"].is_object(),
               path << ": no object 'experiment': not the result of `secure demo` or `secure "
                       "experiment`");
  SECURE_CHECK((result.contains("methods") && result["methods"].is_object()) ||
                   (result.contains("variants") && result["variants"].is_object()),
               path << ": neither 'methods' nor 'variants': no evaluation to report");
}

// The page's path must be writable as WriteFileAtomically writes, checked before the (slow)
// script runs: not a directory, socket or block device; a FIFO must have a reader.
void CheckOutputTarget(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;  // a new file (or a dangling link): the writer's
  if (S_ISREG(st.st_mode) || S_ISCHR(st.st_mode)) return;
  if (S_ISFIFO(st.st_mode)) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    SECURE_CHECK(fd >= 0 || errno != ENXIO,
                 "cannot write '" << path << "': it is a FIFO that no process has open for reading");
    if (fd >= 0) ::close(fd);
    return;
  }
  SECURE_THROW("cannot write '" << path << "': it is " << FileTypeName(st.st_mode)
                                << ", not a regular file");
}

struct ReportCommand {
  std::string run_dir, out;

  void Run() const {
    CheckRunDirectory(run_dir);
    const std::string script = EnvOr("SECURE_REPORT_SCRIPT", SECURE_REPORT_SCRIPT_DEFAULT);
    const std::string python = EnvOr("SECURE_REPORT_PYTHON", SECURE_REPORT_PYTHON_DEFAULT);
    const std::string module_dir =
        EnvOr("SECURE_REPORT_PYTHONPATH", SECURE_REPORT_PYTHONPATH_DEFAULT);
    std::error_code ec;
    SECURE_CHECK(std::filesystem::is_regular_file(script, ec),
                 "the report script " << script
                                      << " does not exist (set SECURE_REPORT_SCRIPT to "
                                         "tools/report/report.py of the source tree)");

    // The page goes through the C++ writer (WriteFileAtomically: directories and reader-less
    // FIFOs refused, symlinks written through, devices never replaced, modes kept, no temporary
    // left behind): the script writes it to a scratch file, and its messages to another.
    const std::string page = out.empty() ? (std::filesystem::path(run_dir) / "report.html").string()
                                         : out;
    CheckOutputTarget(page);
    const std::string scratch_base =
        (std::filesystem::temp_directory_path(ec) / ("secure-report-" + std::to_string(::getpid())))
            .string();
    const ScratchFile scratch(scratch_base + ".html");
    const ScratchFile messages(scratch_base + ".err");
    std::vector<std::string> args = {python, script, run_dir, "--out", page, "--write-to",
                                     scratch.path()};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);

    // The environment: ours, with PYTHONPATH prefixed by the module's directory and matplotlib's
    // non-interactive backend.
    std::vector<std::string> env;
    std::string pythonpath = module_dir;
    for (char** e = environ; *e != nullptr; ++e) {
      const std::string entry(*e);
      if (entry.rfind("PYTHONPATH=", 0) == 0) {
        const std::string old = entry.substr(11);
        if (!old.empty()) pythonpath += (pythonpath.empty() ? "" : ":") + old;
      } else if (entry.rfind("MPLBACKEND=", 0) != 0) {
        env.push_back(entry);
      }
    }
    if (!pythonpath.empty()) env.push_back("PYTHONPATH=" + pythonpath);
    env.push_back("MPLBACKEND=Agg");
    std::vector<char*> envp;
    for (std::string& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);

    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 2, messages.path().c_str(), O_WRONLY | O_TRUNC, 0);
    pid_t pid = 0;
    const int spawned =
        ::posix_spawnp(&pid, python.c_str(), &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    SECURE_CHECK(spawned == 0, "cannot run the report's Python " << python << ": "
                                                                 << std::strerror(spawned)
                                                                 << " (set SECURE_REPORT_PYTHON)");
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0) {
      SECURE_CHECK(errno == EINTR, "waiting for " << python << ": " << std::strerror(errno));
    }
    const std::string said = ReadFile(messages.path());
    if (!(WIFEXITED(status) && WEXITSTATUS(status) == 0)) {
      // One line: the script's own error (without its prefix), else its last line.
      std::string line;
      std::istringstream lines(said);
      for (std::string l; std::getline(lines, l);)
        if (l.find_first_not_of(" \t") != std::string::npos) line = l;
      const std::string prefix = "secure report: error: ";
      if (line.rfind(prefix, 0) == 0) SECURE_THROW(line.substr(prefix.size()));
      SECURE_THROW("the report script " << script << " failed ("
                                        << (WIFEXITED(status)
                                                ? "exit code " +
                                                      std::to_string(WEXITSTATUS(status))
                                                : "signal " + std::to_string(WTERMSIG(status)))
                                        << (line.empty() ? std::string() : "): " + line)
                                        << (line.empty() ? ")" : ""));
    }
    std::cerr << said;  // warnings of a run that succeeded
    WriteFileAtomically(page, ReadFile(scratch.path()));
  }
};

}  // namespace

void RegisterReportCommand(CLI::App& app) {
  static ReportCommand report;
  CLI::App* cmd = app.add_subcommand(
      "report",
      "One self-contained HTML page (figures embedded) for a run directory of `secure demo "
      "--out` / `secure experiment --out`: the method comparison with its significance marks "
      "beside the paper's Table 3, learning curves, variants, the learned barrier");
  cmd->add_option("RUN_DIR", report.run_dir, "the run directory (holds result.json)")
      ->required()
      ->transform(DirectoryPath());
  cmd->add_option("--out", report.out,
                  "the HTML file (default RUN_DIR/report.html; the figures also go to "
                  "<out without .html>_figures/)");
  cmd->callback([] { report.Run(); });
}

}  // namespace secure::cli
