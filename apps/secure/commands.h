#pragma once
#include <CLI/CLI.hpp>

#include "cli_common.h"

namespace secure::cli {
/// secure cbf ... and secure demo.
void RegisterCbfCommands(CLI::App& app, const Config& config);
/// secure shield run.
void RegisterShieldCommands(CLI::App& app, const Config& config);
}  // namespace secure::cli
