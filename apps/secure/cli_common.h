#pragma once
// Pieces shared by the CLI commands.

#include <yaml-cpp/yaml.h>
#include <CLI/CLI.hpp>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "secure/common/limits.h"
#include "secure/shield/shield.h"

namespace secure::experiments {
class Domain;
struct ExperimentOptions;
}

namespace secure::cli {

/// The top-level sections a config file may have: the union of what the commands read with
/// Config::Section (airl, bc, check, trainer) and each registered domain's sections
/// (Domain::ConfigSection: pipeline, derby, ...; Domain::GroundTruthSection: double_integrator).
const std::vector<std::string>& KnownConfigSections();

/// The YAML config named by --config (pre-scanned from argv so that flags parsed afterwards
/// override it), or a null node. Loading never throws: an error (unreadable file, a directory,
/// invalid YAML, an unknown top-level section, a duplicate key at any depth) is kept and thrown
/// by Check(), which every command that takes --config calls when it runs; so --help, --version
/// and the commands not given --config work with a broken file.
struct Config {
  std::string path;
  YAML::Node root;
  std::exception_ptr error;  // set when the file could not be loaded or checked
  /// Throws the load error, if any.
  void Check() const;
  /// The sub-mapping `key` (one of KnownConfigSections()), or a null node (test with IsMap());
  /// throws the load error, or if present but not a mapping.
  YAML::Node Section(const std::string& key) const;
};
Config PreScanConfig(int argc, char** argv);

/// An error met while a command registers (applying its config sections), kept until the command
/// runs: a broken section must not break the other commands, --help or --version.
class DeferredError {
 public:
  /// Runs `f`; keeps the first exception it throws.
  template <typename F>
  void Capture(F&& f) {
    try {
      f();
    } catch (...) {
      if (!error_) error_ = std::current_exception();
    }
  }
  /// Throws the kept exception, if any (call first in the command's callback).
  void Rethrow() const {
    if (error_) std::rethrow_exception(error_);
  }

 private:
  std::exception_ptr error_;
};

/// Adds --config (for help; the file is read by PreScanConfig and checked by Config::Check).
void AddConfigFlag(CLI::App* cmd, const Config& config);

/// The registered domain `name` (profile quick or full) with its options from the config file's
/// section for it (key `domain`), validated; in `options` (when given) the experiment options of
/// that section: the domain's preset with the section's other keys over it. Both by
/// experiments::ReadSection, the one reader of a domain's section. Throws the config's load
/// error, an unknown domain's or a bad option's.
std::unique_ptr<experiments::Domain> MakeConfiguredDomain(
    const std::string& name, bool quick, const Config& config,
    experiments::ExperimentOptions* options = nullptr);

/// Adds `--domain` bound to `domain`, its help "<what>: <the registered domains>" (the list from
/// experiments::DomainRegistry, so a new plug-in appears in every command's help). The
/// vector overload takes the flag repeated.
CLI::Option* AddDomainOption(CLI::App* cmd, std::string* domain,
                             const std::string& what = "the domain");
CLI::Option* AddDomainOption(CLI::App* cmd, std::vector<std::string>* domains,
                             const std::string& what);

/// A capability a domain may offer (Domain::HasCheck, HasGroundTruth, ...) and its name in the
/// help and the errors ("a domain with a barrier check", "the derby domain has no barrier
/// check").
struct DomainCapability {
  bool (experiments::Domain::*offers)() const;
  std::string name;
};
extern const DomainCapability kBarrierCheck, kGroundTruth, kLabeller, kLabelCheck, kShieldRun,
    kPopulation;
/// The registered domains that offer `capability`: "a | b".
std::string DomainsWith(const DomainCapability& capability);
/// `--domain` with the help "a domain with a <name>: <the domains that offer it>".
CLI::Option* AddDomainOption(CLI::App* cmd, std::string* domain,
                             const DomainCapability& capability);
/// Throws "<prefix>the <name> domain has no <capability> (<why>domains with one: a | b)" unless
/// `domain` offers it.
void RequireCapability(const experiments::Domain& domain, const std::string& name,
                       const DomainCapability& capability, const std::string& prefix = "",
                       const std::string& why = "");

/// Rejects a negative value for an unsigned 64-bit seed (which CLI11 would wrap around to
/// 2^64 - 1).
const CLI::Validator& NonNegativeSeed();
/// Adds `--<name>` for an unsigned 64-bit seed, checked by NonNegativeSeed().
CLI::Option* AddSeedOption(CLI::App* cmd, const std::string& name, std::uint64_t* seed,
                           const std::string& help);

/// A transform for directory options (`->transform(DirectoryPath())`): the path without
/// repeated or trailing slashes and "." components ("data//x/./" -> "data/x", "./" -> "."), so
/// the files under it print as "data/x/demos.csv". ".." is kept (it is not lexical with
/// symbolic links).
const CLI::Validator& DirectoryPath();
/// The same normalisation of one path.
std::string NormalDirectoryPath(const std::string& path);

/// Adds --progress auto|always|never: a live progress line on stderr (done/total, elapsed, time
/// left; common/progress.h) when stderr is a terminal (auto), always, or never. Without one only
/// the milestone lines are printed, as they always were.
CLI::Option* AddProgressOption(CLI::App* cmd, std::string* mode);
/// Whether --progress's value (checked by AddProgressOption) draws the live line.
bool ProgressIsLive(const std::string& mode);

/// Throws "NAME = VALUE, must be in [LO, HI]" unless lo <= value <= hi (limits:
/// secure/common/limits.h).
void CheckRange(const std::string& name, long value, long lo, long hi);

/// Prints "secure: error: MESSAGE" (the first line of it) on stderr and returns 1, the exit code
/// of every error.
int ReportError(const std::string& message);

/// The global flags --max-input-bytes, --max-config-nodes, --max-hdf5-memory, --max-hdf5-seconds
/// (input_limit_flags.cc): scanned from argv and applied at once (before the config file is
/// read), and declared on `app`.
void AddInputLimitFlags(CLI::App& app, int argc, char** argv);

/// Flags that set options of the domain's task (its `task:` keys of the same names: the double
/// integrator's --obstacle X,Y, --radius, --gamma, --accel-bound, ...), and the domain's
/// ground-truth config section (Domain::GroundTruthSection, e.g. `double_integrator:`; its keys
/// are the ground truth's parameters, Domain::GroundTruthJson, and task options too). A domain
/// without such an option rejects it by name; a flag not given leaves the domain's value, so the
/// help names no default.
class TaskFlags {
 public:
  /// --obstacle X,Y, --radius R, --gamma G (the ground truth's geometry).
  void AddGeometry(CLI::App* cmd);
  /// `--<flag> A,B` for task option `key` (a pair).
  CLI::Option* AddPair(CLI::App* cmd, const std::string& flag, const std::string& key,
                       const std::string& help);
  /// `--<flag> VALUE` for task option `key` (a number; `integer`: an integer).
  CLI::Option* AddNumber(CLI::App* cmd, const std::string& flag, const std::string& key,
                         const std::string& help, bool integer = false);
  /// Applies to `domain` its ground-truth section of `config` (if the domain has one and the file
  /// holds it), then the flags given, as `task:` options, and validates the domain. @throws
  /// secure::Error naming the file and line, or the flags, and the key.
  void ApplyTo(experiments::Domain* domain, const Config& config) const;

 private:
  struct Entry {
    CLI::Option* option;
    std::string key;
    std::function<YAML::Node()> value;
  };
  std::vector<Entry> entries_;
  std::vector<std::unique_ptr<std::vector<double>>> pairs_;
  std::vector<std::unique_ptr<double>> numbers_;
  std::vector<std::unique_ptr<long>> integers_;
};

/// Flags for the shield's options (--samples, --safe-ratio, --class-k, ...), bound to `options`;
/// the enum-valued ones are parsed by ApplyTo() after CLI parsing.
struct ShieldFlags {
  std::string class_k, aggregation, resampling, sampler, action_bounds, proposal, qp_metric,
      qp_target;
  /// `domain_preset`: the command starts from a chosen domain's options (OverlayGiven onto its
  /// preset), so the help shows "=preset" (the values: `secure domains NAME`), not the general
  /// defaults in `options`.
  void Add(CLI::App* cmd, shield::ShieldOptions* options, bool domain_preset = false);
  void ApplyTo(shield::ShieldOptions* options) const;
  /// Copies onto `base` (e.g. a domain's preset) the fields whose flags were given, from
  /// `parsed` (the options Add() bound, after ApplyTo()).
  void OverlayGiven(const shield::ShieldOptions& parsed, shield::ShieldOptions* base) const;

 private:
  std::vector<std::pair<CLI::Option*,
                        std::function<void(const shield::ShieldOptions&, shield::ShieldOptions*)>>>
      given_;
};

/// The shield of a command: `from_file` (the domain's preset with its config section's `shield:`
/// key, MakeConfiguredDomain), then the fields whose flags were given, overlaid from `parsed` (the
/// options `flags` are bound to; flags.ApplyTo(parsed) is called first). Not validated.
shield::ShieldOptions OverlayShieldFlags(shield::ShieldOptions from_file, const ShieldFlags& flags,
                                         shield::ShieldOptions* parsed);

/// Prints `result` (with the build context added) as one JSON document on stdout.
void PrintJson(nlohmann::json result);

}  // namespace secure::cli
