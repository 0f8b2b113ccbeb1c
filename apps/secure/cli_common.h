#pragma once
// Pieces shared by the CLI commands.

#include <yaml-cpp/yaml.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/domains/double_integrator/double_integrator.h"
#include "secure/shield/shield.h"

namespace secure::cli {

/// The YAML config named by --config (pre-scanned from argv so that flags parsed afterwards
/// override it), or a null node.
struct Config {
  std::string path;
  YAML::Node root;
  /// The sub-mapping `key`, or a null node (test with IsMap()); throws if present but not a
  /// mapping.
  YAML::Node Section(const std::string& key) const;
};
Config PreScanConfig(int argc, char** argv);

/// Adds --config (for help and validation; the file is read by PreScanConfig).
void AddConfigFlag(CLI::App* cmd, const Config& config);

/// The one domain with a ground truth so far, as named by --domain.
inline constexpr const char* kDoubleIntegratorDomain = "double-integrator";
/// Throws unless `domain` is kDoubleIntegratorDomain ("--domain = 'x', must be double-integrator").
void CheckDoubleIntegratorDomain(const std::string& domain);

/// --obstacle X,Y --radius R --gamma G bound to `truth`.
void AddGroundTruthFlags(CLI::App* cmd, domains::double_integrator::GroundTruth* truth,
                         std::vector<double>* obstacle);
/// Applies the `double_integrator:` YAML section (obstacle: [x, y], radius, gamma).
void ApplyGroundTruthYaml(const YAML::Node& node, const std::string& source,
                          domains::double_integrator::GroundTruth* truth);
/// Copies a parsed --obstacle X,Y into truth (no-op when the flag was not given).
void FinishGroundTruth(const std::vector<double>& obstacle,
                       domains::double_integrator::GroundTruth* truth);

/// Flags for the shield's options (--samples, --safe-ratio, --class-k, ...), bound to `options`;
/// the enum-valued ones are parsed by ApplyTo() after CLI parsing.
struct ShieldFlags {
  std::string class_k, aggregation, resampling;
  void Add(CLI::App* cmd, shield::ShieldOptions* options);
  void ApplyTo(shield::ShieldOptions* options) const;
};

/// Prints `result` (with the build context added) as one JSON document on stdout.
void PrintJson(nlohmann::json result);

}  // namespace secure::cli
