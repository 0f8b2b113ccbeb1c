// secure: learn safe behaviour from demonstrations (SECURE, CBF shielding). main() only parses
// and dispatches; see cbf_commands.cc, shield_commands.cc, pipeline_commands.cc, render_command.cc
// experiment_commands.cc and report_command.cc.
#include <CLI/CLI.hpp>
#include <iostream>
#include <new>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/build_info.h"
#include "secure/common/error.h"
#include "secure/experiments/domain.h"

int main(int argc, char** argv) {
  CLI::App app{
      "secure: learn control barrier functions from demonstrations and shield "
      "learned policies with them (SECURE)"};
  app.set_version_flag("--version", std::string(secure::Version()) + " (" + secure::GitSha() + ")");
  app.require_subcommand(1);
  try {
    // The domain plug-ins first: the commands list them, and the config's sections include theirs.
    secure::plugins::RegisterBuiltinDomains(secure::experiments::DomainRegistry::Global());
    secure::cli::AddInputLimitFlags(app, argc, argv);  // before anything is read
    const secure::cli::Config config = secure::cli::PreScanConfig(argc, argv);
    secure::cli::RegisterCbfCommands(app, config);
    secure::cli::RegisterShieldCommands(app, config);
    secure::cli::RegisterPipelineCommands(app, config);
    secure::cli::RegisterRenderCommand(app, config);
    secure::cli::RegisterExperimentCommands(app, config);
    secure::cli::RegisterReportCommand(app);
    secure::cli::RegisterReproduceCommand(app);
    secure::cli::RegisterCompareCommand(app);
    secure::cli::RegisterDomainsCommand(app);
    secure::cli::RegisterDynamicsCommands(app, config);
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version end parsing with exit code 0: CLI11 prints them. Every other parse
    // error (a missing or unknown option, a value a validator rejects) is an error like any
    // other: one line, exit code 1.
    if (e.get_exit_code() == 0) return app.exit(e);
    return secure::cli::ReportError(e.what());
  } catch (const secure::Error& e) {
    return secure::cli::ReportError(e.what());
  } catch (const std::bad_alloc&) {
    return secure::cli::ReportError(
        "out of memory (an option asks for more than this machine has; see the limits in "
        "apps/secure/README.md)");
  } catch (const std::exception& e) {
    return secure::cli::ReportError(e.what());
  } catch (...) {
    return secure::cli::ReportError("unknown error");
  }
  return 0;
}
