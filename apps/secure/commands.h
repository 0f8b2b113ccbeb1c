#pragma once
#include <CLI/CLI.hpp>

#include "cli_common.h"

namespace secure::cli {
/// secure cbf ...
void RegisterCbfCommands(CLI::App& app, const Config& config);
/// secure cbf check (cbf_check_command.cc), registered by RegisterCbfCommands.
void RegisterCbfCheckCommand(CLI::App& cbf, const Config& config);
/// secure cbf query / cbf label (cbf_query_command.cc), registered by RegisterCbfCommands.
void RegisterCbfQueryCommands(CLI::App& cbf, const Config& config);
/// secure shield run.
void RegisterShieldCommands(CLI::App& app, const Config& config);
/// secure demos generate, secure policy train, secure eval.
void RegisterPipelineCommands(CLI::App& app, const Config& config);
/// secure demos check-labels (label_check_command.cc), registered by RegisterPipelineCommands.
void RegisterLabelCheckCommand(CLI::App& demos, const Config& config);
/// secure demos convert (convert_command.cc): CSV <-> HDF5, registered by RegisterPipelineCommands.
void RegisterConvertCommand(CLI::App& demos);
/// secure render (render_command.cc): one evaluation episode as an MP4 or PPM frames.
void RegisterRenderCommand(CLI::App& app, const Config& config);
/// secure demo; secure experiment KIND --domain NAME (and the derby-* aliases).
void RegisterExperimentCommands(CLI::App& app, const Config& config);
/// secure experiment label-efficiency (label_efficiency_command.cc), registered by
/// RegisterExperimentCommands.
void RegisterLabelEfficiencyCommand(CLI::App& experiment, const Config& config);
/// secure reproduce --out DIR (reproduce_command.cc): every experiment of the paper on every
/// domain that declares it (secure/experiments/reproduce.h).
void RegisterReproduceCommand(CLI::App& app);
/// secure report RUN_DIR (report_command.cc): the run's HTML report (tools/report/report.py).
void RegisterReportCommand(CLI::App& app);
/// secure domains [NAME] (domains_command.cc): the registered domains, their capabilities, and
/// the values a domain's preset gives the commands.
void RegisterDomainsCommand(CLI::App& app);
/// secure compare A.json B.json (compare_command.cc): two `secure eval --json` results of the same
/// episodes, paired by seed (TOST of the rates, latencies).
void RegisterCompareCommand(CLI::App& app);
/// secure dynamics train | validate | collect (dynamics_commands.cc): a learned dynamics ensemble.
void RegisterDynamicsCommands(CLI::App& app, const Config& config);
/// secure experiment model-source (model_source_command.cc), registered by RegisterDynamicsCommands
/// under the `experiment` command.
void RegisterModelSourceCommand(CLI::App& experiment, const Config& config);
}  // namespace secure::cli
