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

CLI::Option* AddDomainOption(CLI::App* cmd, std::string* domain, const std::string& what) {
  return cmd->add_option("--domain", *domain,
                         what + ": " + experiments::DomainRegistry::Global().NameList());
}

CLI::Option* AddDomainOption(CLI::App* cmd, std::vector<std::string>* domains,
                             const std::string& what) {
  return cmd->add_option("--domain", *domains,
                         what + ": " + experiments::DomainRegistry::Global().NameList());
}

const DomainCapability kBarrierCheck{&experiments::Domain::HasCheck, "barrier check"};
const DomainCapability kGroundTruth{&experiments::Domain::HasGroundTruth, "ground truth"};
const DomainCapability kLabeller{&experiments::Domain::HasLabeller, "labeller"};
const DomainCapability kLabelCheck{&experiments::Domain::HasLabelCheck, "label check"};
const DomainCapability kShieldRun{&experiments::Domain::HasShieldRun, "shield run"};
const DomainCapability kPopulation{&experiments::Domain::HasPopulation, "population"};

std::string DomainsWith(const DomainCapability& capability) {
  return experiments::DomainRegistry::Global().ListOffering(
      [&capability](const experiments::Domain& d) { return (d.*capability.offers)(); });
}

CLI::Option* AddDomainOption(CLI::App* cmd, std::string* domain,
                             const DomainCapability& capability) {
  return cmd->add_option("--domain", *domain,
                         "a domain with a " + capability.name + ": " + DomainsWith(capability));
}

void RequireCapability(const experiments::Domain& domain, const std::string& name,
                       const DomainCapability& capability, const std::string& prefix,
                       const std::string& why) {
  SECURE_CHECK((domain.*capability.offers)(),
               prefix << "the " << name << " domain has no " << capability.name << " (" << why
                      << "domains with one: " << DomainsWith(capability) << ")");
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

namespace {
// One shield flag: `--<flag>` bound to `bound` (the field itself, or the string an enum field is
// parsed from), and the copy of `field` that OverlayGiven makes when the flag was given.
template <typename Bound, typename Field>
std::pair<CLI::Option*, std::function<void(const shield::ShieldOptions&, shield::ShieldOptions*)>>
ShieldFlag(CLI::App* cmd, const std::string& flag, Bound* bound,
           Field shield::ShieldOptions::*field, const std::string& help) {
  return {cmd->add_option(flag, *bound, help)->capture_default_str(),
          [field](const shield::ShieldOptions& from, shield::ShieldOptions* to) {
            to->*field = from.*field;
          }};
}
}  // namespace

void ShieldFlags::Add(CLI::App* cmd, shield::ShieldOptions* so, bool domain_preset) {
  class_k = ToString(shield::kClassKNames, so->class_k);
  aggregation = ToString(shield::kAggregationNames, so->aggregation);
  resampling = ToString(shield::kResamplingNames, so->resampling);
  sampler = ToString(shield::kSamplerNames, so->sampler);
  action_bounds = ToString(shield::kActionBoundsNames, so->action_bounds);
  proposal = ToString(shield::kProposalNames, so->proposal);
  qp_metric = ToString(shield::kQpMetricNames, so->qp_metric);
  qp_target = ToString(shield::kQpTargetNames, so->qp_target);
  using O = shield::ShieldOptions;
  // The flags in help order; each binds its field (or the enum's string) and copies its field.
  const std::vector<std::pair<CLI::Option*, std::function<void(const O&, O*)>>> flags = {
      ShieldFlag(cmd, "--samples", &so->num_samples, &O::num_samples, "M: actions drawn per round"),
      ShieldFlag(cmd, "--safe-ratio", &so->safe_ratio, &O::safe_ratio,
                 "rho0: resample while #safe / M <= rho0"),
      ShieldFlag(cmd, "--class-k", &class_k, &O::class_k, "class-K function: linear | cubic"),
      ShieldFlag(cmd, "--class-k-gain", &so->class_k_gain, &O::class_k_gain,
                 "k in alpha(h) (linear: keep k dt < 1)"),
      ShieldFlag(cmd, "--aggregation", &aggregation, &O::aggregation,
                 "mean | random-safe | policy-draw | top-q (AIRL's task value) | policy-mean"),
      ShieldFlag(cmd, "--top-q-fraction", &so->top_q_fraction, &O::top_q_fraction,
                 "aggregation top-q: the fraction of the safe samples averaged"),
      ShieldFlag(cmd, "--lookahead-steps", &so->lookahead_steps, &O::lookahead_steps,
                 "H: the CBF condition H control periods ahead, the action held"),
      ShieldFlag(cmd, "--resampling", &resampling, &O::resampling, "adaptive | none"),
      ShieldFlag(cmd, "--sampler", &sampler, &O::sampler,
                 "how each round's M actions are drawn: iid | antithetic | qmc"),
      ShieldFlag(cmd, "--action-bounds", &action_bounds, &O::action_bounds,
                 "the environment's actuator box: clip (samples clipped onto it) | reject "
                 "(samples outside count unsafe) | ignore (decisions may leave it)"),
      ShieldFlag(cmd, "--proposal", &proposal, &O::proposal,
                 "none | qp (the CBF-QP projection of the mean first, Algorithms 1-2 if its exact "
                 "g < 0) | qp-only (the CBF-QP filter alone) | refine (gradient refinement of "
                 "the mean alone)"),
      ShieldFlag(cmd, "--qp-iterations", &so->qp_iterations, &O::qp_iterations,
                 "proposal: linearisations per decision (re-linearised at a rejected "
                 "projection)"),
      ShieldFlag(cmd, "--qp-line-search", &so->qp_line_search, &O::qp_line_search,
                 "proposal qp, qp-only: secant steps on the exact g along a rejected "
                 "projection's line (0: none)"),
      ShieldFlag(cmd, "--qp-bisection", &so->qp_bisection, &O::qp_bisection,
                 "proposal qp, qp-only: bisection steps on the exact g back along the line of "
                 "an accepted projection that overshot the boundary (0: none)"),
      ShieldFlag(cmd, "--qp-margin", &so->qp_margin, &O::qp_margin,
                 "proposal: the projection asks the linearised g >= this margin"),
      ShieldFlag(cmd, "--qp-max-step", &so->qp_max_step, &O::qp_max_step,
                 "proposal qp: a projection (with --qp-bisection, the bisected decision) farther "
                 "than this from the mean falls back to sampling (0: no limit)"),
      ShieldFlag(cmd, "--qp-smoothing", &so->qp_smoothing, &O::qp_smoothing,
                 "proposal qp: after failed projections, one more round on the slope of the "
                 "exact g at mu +- this many sigma along each action (0: off)"),
      ShieldFlag(cmd, "--qp-metric", &qp_metric, &O::qp_metric,
                 "proposal qp, qp-only: the projection's metric: euclidean | policy (the "
                 "policy's Gaussian, (a - mu)^T diag(sigma)^-2 (a - mu))"),
      ShieldFlag(cmd, "--qp-target", &qp_target, &O::qp_target,
                 "proposal qp, qp-only: where the projection lands: boundary (the least change) "
                 "| safe-mean (the policy's Gaussian's mean over the linearised safe half-space; "
                 "needs --qp-metric policy)"),
      ShieldFlag(cmd, "--refine-steps", &so->refine_steps, &O::refine_steps,
                 "proposal refine: gradient steps per decision at most"),
      ShieldFlag(cmd, "--max-iterations", &so->max_iterations, &O::max_iterations,
                 "sampling rounds per decision"),
      ShieldFlag(cmd, "--time-budget-us", &so->time_budget_us, &O::time_budget_us,
                 "wall-time budget per decision in microseconds (0: none)"),
      ShieldFlag(cmd, "--probes", &so->num_probes, &O::num_probes,
                 "N: probe actions per adaptive step"),
      ShieldFlag(cmd, "--probe-extent", &so->probe_extent, &O::probe_extent,
                 "R: probes are uniform in mu + [-R, R]^n"),
      ShieldFlag(cmd, "--sigma-step", &so->sigma_step, &O::sigma_step,
                 "alpha_sigma: sigma widening step"),
  };
  // The default shown: the general one, or "preset" where the chosen domain's preset applies.
  if (domain_preset)
    for (const auto& flag : flags) flag.first->default_str("preset");
  given_.insert(given_.end(), flags.begin(), flags.end());
}

void ShieldFlags::ApplyTo(shield::ShieldOptions* so) const {
  so->class_k = FromString(shield::kClassKNames, class_k, "--class-k");
  so->aggregation = FromString(shield::kAggregationNames, aggregation, "--aggregation");
  so->resampling = FromString(shield::kResamplingNames, resampling, "--resampling");
  so->sampler = FromString(shield::kSamplerNames, sampler, "--sampler");
  so->action_bounds = FromString(shield::kActionBoundsNames, action_bounds, "--action-bounds");
  so->proposal = FromString(shield::kProposalNames, proposal, "--proposal");
  so->qp_metric = FromString(shield::kQpMetricNames, qp_metric, "--qp-metric");
  so->qp_target = FromString(shield::kQpTargetNames, qp_target, "--qp-target");
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
