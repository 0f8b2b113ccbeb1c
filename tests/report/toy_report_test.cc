// A domain that tools/report never names gets its barrier picture from its hints alone
// (experiments::ReportHints): the toy domain (examples/toy_domain, a plug-in registered like the
// built-ins) runs a quick method comparison into a run directory, and tools/report/report.py
// draws its barrier from the hints the Python module gives for it, or from the run directory's
// report_hints.json where one is present.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/report_hints.h"
#include "tests/domains/domain_contract_util.h"
#include "tests/test_util.h"

namespace secure::test {
namespace {

std::string ReadAll(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class ToyReport : public TempDirTest {
 protected:
  // The toy's quick comparison (one seed) into <dir>/run, once per test.
  std::string RunDir() {
    ContractDomainNames();  // the built-in plug-ins, the toy (examples/toy_domain) among them
    toy_ = experiments::DomainRegistry::Global().Make("toy-cart", experiments::Profile::kQuick);
    experiments::ExperimentOptions o = toy_->Preset();
    o.verbose = false;
    o.seeds = 1;
    o.episodes = 10;
    o.output_dir = PathOf("run");
    experiments::RunExperiment(experiments::ExperimentKind::kMethodComparison, *toy_, o, nullptr);
    return o.output_dir;
  }
  // report.py on `run` (exit code); the page is <run>/report.html, the output <dir>/report.log.
  int Report(const std::string& run) {
    const std::string command =
        std::string("PYTHONPATH=") + SECURE_PYTHON_DIR + " /usr/bin/python3 " + SECURE_SOURCE_DIR +
        "/tools/report/report.py " + run + " > " + PathOf("report.log") + " 2>&1";
    const int status = std::system(command.c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  std::unique_ptr<experiments::Domain> toy_;
};

// The toy is a plug-in that tools/report never names (examples/toy_domain): its barrier picture
// comes from its hints through the registry (the Python module), a run directory's
// report_hints.json takes their place, and a bad field there is a note naming it.
TEST_F(ToyReport, HintsFromTheRegistryOrTheRunDirectoryDrawTheBarrier) {
  const std::string run = RunDir();
  ASSERT_EQ(Report(run), 0) << ReadAll(PathOf("report.log"));
  const std::string page = ReadAll(PathOf("run/report.html"));
  EXPECT_HAS(page, "<img id=\"fig-barrier\"");
  EXPECT_HAS(page, "The toy cart's barrier of <code>seed-0/barrier.model</code>");
  EXPECT_TRUE(std::filesystem::is_regular_file(PathOf("run/report_figures/barrier.png")));
  EXPECT_HAS(page, "toy-cart");
  // The paper has no Table 3 row for the toy: a note, not numbers.
  EXPECT_HAS(page, "the paper has no Table 3 row for the toy-cart domain");

  // The run directory's hints replace the registry's.
  nlohmann::json hints = experiments::ReportHintsJson(*toy_);
  ASSERT_TRUE(hints.is_object());
  hints["barrier"]["caption"] = "Hints from the run directory.";
  Write("run/report_hints.json", hints.dump(1));
  Write("run/paper_reference.json", experiments::PaperReferenceJson(*toy_).dump(1));
  ASSERT_EQ(Report(run), 0) << ReadAll(PathOf("report.log"));
  const std::string from_file = ReadAll(PathOf("run/report.html"));
  EXPECT_HAS(from_file, "<img id=\"fig-barrier\"");
  EXPECT_HAS(from_file, "Hints from the run directory.");

  // A field of the wrong kind: a note naming the file, the field and the value.
  nlohmann::json bad = hints;
  bad["barrier"]["grid"] = "many";
  Write("run/report_hints.json", bad.dump(1));
  ASSERT_EQ(Report(run), 0) << ReadAll(PathOf("report.log"));
  const std::string noted = ReadAll(PathOf("run/report.html"));
  EXPECT_EQ(noted.find("<img id=\"fig-barrier\""), std::string::npos);
  EXPECT_HAS(noted,
             "report_hints.json: &#x27;barrier.grid&#x27; = &quot;many&quot;, must be an "
             "integer");
}

// The report's sources name no registered domain: what they draw comes from the hints.
TEST(ToyReportSources, ReportScriptsNameNoDomain) {
  const std::vector<std::string> names = ContractDomainNames();
  int scripts = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(SECURE_SOURCE_DIR) + "/tools/report")) {
    if (entry.path().extension() != ".py") continue;
    ++scripts;
    const std::string text = ReadAll(entry.path());
    for (const std::string& name : names)
      EXPECT_EQ(text.find(name), std::string::npos) << entry.path() << " names " << name;
  }
  EXPECT_GE(scripts, 2);
}

}  // namespace
}  // namespace secure::test
