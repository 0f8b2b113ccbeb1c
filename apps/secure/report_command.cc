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
#include <spawn.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"

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

// RUN_DIR must be a directory holding a result.json with an "experiment" object.
void CheckRunDirectory(const std::string& run_dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(run_dir, ec);
  SECURE_CHECK(fs::exists(st), run_dir << ": no such directory");
  SECURE_CHECK(fs::is_directory(st),
               run_dir << ": not a directory (expected a run directory written by `secure demo "
                          "--out` or `secure experiment --out`)");
  const std::string path = (fs::path(run_dir) / "result.json").string();
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
  SECURE_CHECK(result.is_object() && result.contains("experiment") &&
                   result["experiment"].is_object(),
               path << ": no object 'experiment': not the result of `secure demo` or `secure "
                       "experiment`");
  SECURE_CHECK((result.contains("methods") && result["methods"].is_object()) ||
                   (result.contains("variants") && result["variants"].is_object()),
               path << ": neither 'methods' nor 'variants': no evaluation to report");
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

    std::vector<std::string> args = {python, script, run_dir};
    if (!out.empty()) {
      args.push_back("--out");
      args.push_back(out);
    }
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

    pid_t pid = 0;
    const int spawned =
        ::posix_spawnp(&pid, python.c_str(), nullptr, nullptr, argv.data(), envp.data());
    SECURE_CHECK(spawned == 0, "cannot run the report's Python " << python << ": "
                                                                 << std::strerror(spawned)
                                                                 << " (set SECURE_REPORT_PYTHON)");
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0) {
      SECURE_CHECK(errno == EINTR, "waiting for " << python << ": " << std::strerror(errno));
    }
    SECURE_CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0,
                 "the report script " << script << " failed ("
                                      << (WIFEXITED(status)
                                              ? "exit code " + std::to_string(WEXITSTATUS(status))
                                              : "signal " + std::to_string(WTERMSIG(status)))
                                      << "; its message is above)");
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
