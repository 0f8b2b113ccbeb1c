// libFuzzer target: the options read from YAML config files. The input is parsed as YAML; each
// top-level key picks an options struct (the config file's sections, plus the structs nested in
// them) whose ApplyYaml, Validate and ToJson are run. Malformed YAML may throw YAML::Exception
// from the parser (the CLI reports it); past the parser, any input must be applied or rejected
// with secure::Error, and never crash or throw anything else.
#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/car_barrier_trainer.h"
#include "secure/common/error.h"
#include "domains/derby/derby.h"
#include "domains/double_integrator/reach_avoid.h"
#include "domains/derby/domain.h"
#include "domains/double_integrator/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"

namespace {

template <typename Options>
void Apply(const YAML::Node& node) {
  Options options;
  try {
    options.ApplyYaml(node, "fuzz.yaml");
    options.Validate();
    (void)options.ToJson().dump();
  } catch (const secure::Error&) {
  }
}

// An experiment's section with its domain (the `domain:` key reaches the domain's own options).
template <typename Domain>
void ApplyExperiment(const YAML::Node& node) {
  Domain domain(secure::experiments::Profile::kQuick);
  secure::experiments::ExperimentOptions options = domain.Preset();
  try {
    options.ApplyYaml(node, "fuzz.yaml", &domain);
    domain.Validate();
    options.Validate();
    secure::experiments::CheckExperimentOptions(domain, options);
    (void)options.ToJson().dump();
    (void)domain.OptionsJson().dump();
  } catch (const secure::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  YAML::Node root;
  try {
    root = YAML::Load(std::string(reinterpret_cast<const char*>(data), size));
  } catch (const YAML::Exception&) {
    return 0;
  }
  if (!root.IsMap()) return 0;
  for (const auto& section : root) {
    if (!section.first.IsScalar()) continue;
    const std::string key = section.first.Scalar();
    const YAML::Node& node = section.second;
    if (key == "trainer") Apply<cbf::BarrierTrainerOptions>(node);
    else if (key == "car_barrier") Apply<cbf::CarBarrierTrainerOptions>(node);
    else if (key == "bc") Apply<policy::BcOptions>(node);
    else if (key == "airl") Apply<policy::AirlOptions>(node);
    else if (key == "joint") Apply<policy::JointCbfOptions>(node);
    else if (key == "reach_avoid") Apply<domains::double_integrator::ReachAvoidOptions>(node);
    else if (key == "derby_task") Apply<domains::derby::DerbyOptions>(node);
    else if (key == "pipeline")
      ApplyExperiment<domains::double_integrator::DoubleIntegratorDomain>(node);
    else if (key == "derby") ApplyExperiment<domains::derby::DerbyDomain>(node);
  }
  return 0;
}
