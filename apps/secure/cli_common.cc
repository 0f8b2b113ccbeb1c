#include "cli_common.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string_view>
#include <iostream>

#include "secure/common/build_info.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/excerpt.h"
#include "secure/common/filesystem.h"
#include "secure/common/progress.h"
#include "secure/common/strings.h"
#include "secure/common/yaml_keys.h"
#include "secure/common/yaml_limits.h"
#include "secure/common/input_limits.h"
#include "secure/common/atomic_file.h"
#include "secure/common/yaml_value.h"
#include "secure/experiments/config_section.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::cli {

const std::vector<std::string>& KnownConfigSections() {
  // The commands' own sections, then each registered domain's experiment section
  // (Domain::ConfigSection: "pipeline" for the double integrator, "derby", ...) and ground-truth
  // section (Domain::GroundTruthSection: "double_integrator"). Computed once, after main()
  // registered the domains.
  static const std::vector<std::string> known = [] {
    std::vector<std::string> names = {"airl", "bc", "check", "trainer"};
    const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    for (const std::string& domain : registry.Names()) {
      const std::unique_ptr<experiments::Domain> d = registry.Make(domain);
      names.push_back(d->ConfigSection());
      if (!d->GroundTruthSection().empty()) names.push_back(d->GroundTruthSection());
    }
    std::sort(names.begin(), names.end());
    names.erase(std::unique(names.begin(), names.end()), names.end());
    return names;
  }();
  return known;
}

void Config::Check() const {
  if (error) std::rethrow_exception(error);
}

YAML::Node Config::Section(const std::string& key) const {
  const auto& known = KnownConfigSections();
  SECURE_INTERNAL_CHECK(std::find(known.begin(), known.end(), key) != known.end(),
                        "config section '" << key << "' is missing from KnownConfigSections()");
  Check();
  if (!root || !root.IsMap() || !root[key]) return YAML::Node();
  const YAML::Node node = root[key];
  SECURE_CHECK(node.IsMap(), path << ":" << node.Mark().line + 1 << ": section '" << key
                                  << "' must be a mapping");
  return node;
}

namespace {

// Loads and checks the file (experiments::LoadConfigFile) and its section names; throws
// secure::Error naming the file (and the line where known).
YAML::Node LoadConfig(const std::string& path) {
  const YAML::Node root = experiments::LoadConfigFile(path);
  if (!root) return root;
  const auto& known = KnownConfigSections();
  for (const auto& item : root) {
    const std::string key = YamlKeyText(item.first);
    SECURE_CHECK(std::find(known.begin(), known.end(), key) != known.end(),
                 path << ":" << item.first.Mark().line + 1 << ": unknown section '" << Excerpt(key)
                      << "' (known sections: " << Join(known) << ")");
  }
  return root;
}

}  // namespace

Config PreScanConfig(int argc, char** argv) {
  Config config;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--config" && i + 1 < argc) {
      config.path = argv[i + 1];
    } else if (arg.rfind("--config=", 0) == 0) {
      config.path = arg.substr(std::strlen("--config="));
    }
  }
  if (config.path.empty()) return config;
  try {
    config.root = LoadConfig(config.path);
  } catch (...) {
    config.error = std::current_exception();
    config.root = YAML::Node();
  }
  return config;
}

void AddConfigFlag(CLI::App* cmd, const Config& /*config*/) {
  // No CLI11 file check: a missing or unreadable file is reported by Config::Check as
  // "secure: error: ...", like every other error.
  cmd->add_option("--config", "YAML file with option sections; command-line flags override it");
}

std::unique_ptr<experiments::Domain> MakeConfiguredDomain(const std::string& name, bool quick,
                                                          const Config& config,
                                                          experiments::ExperimentOptions* options) {
  config.Check();
  std::unique_ptr<experiments::Domain> d = experiments::DomainRegistry::Global().Make(
      name, quick ? experiments::Profile::kQuick : experiments::Profile::kFull);
  // The whole section, as every command reads it (experiments::ReadSection): a key `secure
  // experiment` would reject (e.g. a domain option outside `domain:`) is an error here too.
  experiments::ExperimentOptions section = experiments::ReadSection(config.root, config.path, *d);
  if (options != nullptr) *options = std::move(section);
  return d;
}

shield::ShieldOptions OverlayShieldFlags(shield::ShieldOptions from_file, const ShieldFlags& flags,
                                         shield::ShieldOptions* parsed) {
  flags.ApplyTo(parsed);
  flags.OverlayGiven(*parsed, &from_file);
  return from_file;
}

const CLI::Validator& NonNegativeSeed() {
  static const CLI::Validator validator(
      [](std::string& value) -> std::string {
        const auto first = value.find_first_not_of(" \t");
        if (first != std::string::npos && value[first] == '-')
          return "value " + value + " is negative; a seed is an integer in [0, 2^64 - 1]";
        return "";
      },
      "UINT64");
  return validator;
}

CLI::Option* AddSeedOption(CLI::App* cmd, const std::string& name, std::uint64_t* seed,
                           const std::string& help) {
  return cmd->add_option(name, *seed, help)->check(NonNegativeSeed())->capture_default_str();
}

std::string NormalDirectoryPath(const std::string& path) {
  if (path.empty()) return path;
  std::string out = path.front() == '/' ? "/" : "";
  std::size_t begin = 0;
  while (begin <= path.size()) {
    std::size_t end = path.find('/', begin);
    if (end == std::string::npos) end = path.size();
    const std::string_view part(path.data() + begin, end - begin);
    if (!part.empty() && part != ".") {
      if (!out.empty() && out.back() != '/') out += '/';
      out += part;
    }
    begin = end + 1;
  }
  return out.empty() ? "." : out;
}

const CLI::Validator& DirectoryPath() {
  static const CLI::Validator validator(
      [](std::string& value) -> std::string {
        value = NormalDirectoryPath(value);
        return "";
      },
      "DIR");
  return validator;
}

CLI::Option* AddProgressOption(CLI::App* cmd, std::string* mode) {
  return cmd
      ->add_option("--progress", *mode,
                   "a live progress line on stderr (done/total, elapsed, time left): auto (when "
                   "stderr is a terminal), always, never")
      ->check(CLI::IsMember({"auto", "always", "never"}))
      ->capture_default_str();
}

bool ProgressIsLive(const std::string& mode) {
  return ProgressLine::Live(FromString(kProgressModeNames, mode, "--progress"));
}

void CheckRange(const std::string& name, long value, long lo, long hi) {
  SECURE_CHECK(value >= lo && value <= hi,
               name << " = " << value << ", must be in [" << lo << ", " << hi << "]");
}

int ReportError(const std::string& message) {
  const std::string first_line = message.substr(0, message.find('\n'));
  std::cerr << "secure: error: " << (first_line.empty() ? "unknown error" : first_line) << "\n";
  return 1;
}

void ShieldFlags::Add(CLI::App* cmd, shield::ShieldOptions* so, bool domain_preset) {
  class_k = ToString(shield::kClassKNames, so->class_k);
  aggregation = ToString(shield::kAggregationNames, so->aggregation);
  resampling = ToString(shield::kResamplingNames, so->resampling);
  sampler = ToString(shield::kSamplerNames, so->sampler);
  action_bounds = ToString(shield::kActionBoundsNames, so->action_bounds);
  proposal = ToString(shield::kProposalNames, so->proposal);
  using Copy = std::function<void(const shield::ShieldOptions&, shield::ShieldOptions*)>;
  // The default shown: the general one, or "preset" where the chosen domain's preset applies.
  auto track = [this, domain_preset](CLI::Option* option, Copy copy) {
    if (domain_preset) option->default_str("preset");
    given_.emplace_back(option, copy);
  };
#define SECURE_SHIELD_FIELD_COPY(field) \
  [](const shield::ShieldOptions& from, shield::ShieldOptions* to) { to->field = from.field; }
  track(cmd->add_option("--samples", so->num_samples, "M: actions drawn per round")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(num_samples));
  track(cmd->add_option("--safe-ratio", so->safe_ratio, "rho0: resample while #safe / M <= rho0")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(safe_ratio));
  track(cmd->add_option("--class-k", class_k, "class-K function: linear | cubic")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(class_k));
  track(cmd->add_option("--class-k-gain", so->class_k_gain, "k in alpha(h) (linear: keep k dt < 1)")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(class_k_gain));
  track(cmd->add_option("--aggregation", aggregation,
                        "mean | random-safe | policy-draw | top-q (AIRL's task value) | policy-mean")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(aggregation));
  track(cmd->add_option("--top-q-fraction", so->top_q_fraction,
                        "aggregation top-q: the fraction of the safe samples averaged")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(top_q_fraction));
  track(cmd->add_option("--lookahead-steps", so->lookahead_steps,
                        "H: the CBF condition H control periods ahead, the action held")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(lookahead_steps));
  track(cmd->add_option("--resampling", resampling, "adaptive | none")->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(resampling));
  track(cmd->add_option("--sampler", sampler,
                        "how each round's M actions are drawn: iid | antithetic | qmc")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(sampler));
  track(cmd->add_option("--action-bounds", action_bounds,
                        "the environment's actuator box: clip (samples clipped onto it) | reject "
                        "(samples outside count unsafe) | ignore (decisions may leave it)")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(action_bounds));
  track(cmd->add_option("--proposal", proposal,
                        "none | qp (the CBF-QP projection of the mean first, Algorithms 1-2 if "
                        "its exact g < 0) | qp-only (the CBF-QP filter alone) | refine (gradient "
                        "refinement of the mean alone)")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(proposal));
  track(cmd->add_option("--qp-iterations", so->qp_iterations,
                        "proposal: linearisations per decision (re-linearised at a rejected "
                        "projection)")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(qp_iterations));
  track(cmd->add_option("--qp-margin", so->qp_margin,
                        "proposal: the projection asks the linearised g >= this margin")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(qp_margin));
  track(cmd->add_option("--refine-steps", so->refine_steps,
                        "proposal refine: gradient steps per decision at most")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(refine_steps));
  track(cmd->add_option("--max-iterations", so->max_iterations, "sampling rounds per decision")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(max_iterations));
  track(cmd->add_option("--time-budget-us", so->time_budget_us,
                        "wall-time budget per decision in microseconds (0: none)")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(time_budget_us));
  track(cmd->add_option("--probes", so->num_probes, "N: probe actions per adaptive step")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(num_probes));
  track(
      cmd->add_option("--probe-extent", so->probe_extent, "R: probes are uniform in mu + [-R, R]^n")
          ->capture_default_str(),
      SECURE_SHIELD_FIELD_COPY(probe_extent));
  track(cmd->add_option("--sigma-step", so->sigma_step, "alpha_sigma: sigma widening step")
            ->capture_default_str(),
        SECURE_SHIELD_FIELD_COPY(sigma_step));
#undef SECURE_SHIELD_FIELD_COPY
}

void ShieldFlags::ApplyTo(shield::ShieldOptions* so) const {
  so->class_k = FromString(shield::kClassKNames, class_k, "--class-k");
  so->aggregation = FromString(shield::kAggregationNames, aggregation, "--aggregation");
  so->resampling = FromString(shield::kResamplingNames, resampling, "--resampling");
  so->sampler = FromString(shield::kSamplerNames, sampler, "--sampler");
  so->action_bounds = FromString(shield::kActionBoundsNames, action_bounds, "--action-bounds");
  so->proposal = FromString(shield::kProposalNames, proposal, "--proposal");
}

void ShieldFlags::OverlayGiven(const shield::ShieldOptions& parsed,
                               shield::ShieldOptions* base) const {
  for (const auto& [option, copy] : given_)
    if (option->count() > 0) copy(parsed, base);
}

void TaskFlags::AddGeometry(CLI::App* cmd) {
  AddPair(cmd, "--obstacle", "obstacle", "obstacle centre X,Y");
  AddNumber(cmd, "--radius", "radius", "obstacle radius r");
  AddNumber(cmd, "--gamma", "gamma", "gamma of the ground-truth CBF");
}

namespace {
// The help of a task flag: what it sets, and that its default is the domain's.
std::string TaskFlagHelp(const std::string& help, const std::string& key) {
  return help + " (task." + key + "; default: the domain's, `secure domains NAME`)";
}
}  // namespace

CLI::Option* TaskFlags::AddPair(CLI::App* cmd, const std::string& flag, const std::string& key,
                                const std::string& help) {
  pairs_.push_back(std::make_unique<std::vector<double>>());
  std::vector<double>* value = pairs_.back().get();
  CLI::Option* option =
      cmd->add_option(flag, *value, TaskFlagHelp(help, key))->delimiter(',')->expected(2);
  entries_.push_back({option, key, [value] {
                        YAML::Node pair(YAML::NodeType::Sequence);
                        for (double v : *value) pair.push_back(v);
                        return pair;
                      }});
  return option;
}

CLI::Option* TaskFlags::AddNumber(CLI::App* cmd, const std::string& flag, const std::string& key,
                                  const std::string& help, bool integer) {
  CLI::Option* option = nullptr;
  if (integer) {
    integers_.push_back(std::make_unique<long>(0));
    long* value = integers_.back().get();
    option = cmd->add_option(flag, *value, TaskFlagHelp(help, key));
    entries_.push_back({option, key, [value] { return YAML::Node(*value); }});
  } else {
    numbers_.push_back(std::make_unique<double>(0.0));
    double* value = numbers_.back().get();
    option = cmd->add_option(flag, *value, TaskFlagHelp(help, key));
    entries_.push_back({option, key, [value] { return YAML::Node(*value); }});
  }
  return option;
}

void TaskFlags::ApplyTo(experiments::Domain* domain, const Config& config) const {
  config.Check();
  // The domain's ground-truth section: only the ground truth's parameters, as task options.
  const std::string section = domain->GroundTruthSection();
  if (!section.empty()) {
    const YAML::Node node = config.Section(section);
    if (node.IsMap()) {
      const nlohmann::json parameters = domain->GroundTruthJson();
      std::vector<std::string> valid;
      for (const auto& item : parameters.items()) valid.push_back(item.key());
      const std::string source = config.path + " [" + section + "]";
      YAML::Node task(YAML::NodeType::Map);
      for (const auto& item : node) {
        const std::string key = YamlKey(item.first, source);
        SECURE_CHECK(parameters.contains(key),
                     config.path << ":" << item.first.Mark().line + 1 << ": unknown field '"
                                 << Excerpt(key) << "' in section " << section
                                 << " (valid: " << Join(valid) << ")");
        task[key] = item.second;
      }
      YAML::Node wrapped;
      wrapped["task"] = task;
      domain->ApplyYaml(wrapped, source);
    }
  }
  // Then the flags given (they win).
  YAML::Node task(YAML::NodeType::Map);
  std::string flags;
  for (const Entry& e : entries_) {
    if (e.option->count() == 0) continue;
    task[e.key] = e.value();
    flags += (flags.empty() ? "" : "/") + e.option->get_name();
  }
  if (task.size() > 0) {
    YAML::Node wrapped;
    wrapped["task"] = task;
    domain->ApplyYaml(wrapped, flags);
  }
  domain->Validate();
}

void PrintJson(nlohmann::json result) {
  result["context"] = BuildContext();
  std::cout << result.dump(2) << std::endl;
}

}  // namespace secure::cli
