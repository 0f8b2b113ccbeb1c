// secure: learn safe behaviour from demonstrations (SECURE, CBF shielding). main() only parses
// and dispatches; see cbf_commands.cc, shield_commands.cc and pipeline_commands.cc.
#include <CLI/CLI.hpp>
#include <iostream>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/build_info.h"
#include "secure/common/error.h"

int main(int argc, char** argv) {
  CLI::App app{
      "secure: learn control barrier functions from demonstrations and shield "
      "learned policies with them (SECURE)"};
  app.set_version_flag("--version", std::string(secure::Version()) + " (" + secure::GitSha() + ")");
  app.require_subcommand(1);
  try {
    const secure::cli::Config config = secure::cli::PreScanConfig(argc, argv);
    secure::cli::RegisterCbfCommands(app, config);
    secure::cli::RegisterShieldCommands(app, config);
    secure::cli::RegisterPipelineCommands(app, config);
    secure::cli::RegisterExperimentCommands(app, config);
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const secure::Error& e) {
    std::cerr << "secure: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
