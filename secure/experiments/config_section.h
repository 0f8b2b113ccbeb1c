#pragma once
// One reader of a domain's section of a config file (docs/ARCHITECTURE.md, "One reader per config
// section"): `secure experiment`, `eval`, `render`, `shield run`, `cbf check`, `demos
// check-labels`, the user study and the Python module read a domain's section here, so a value
// in it means the same to each of them.
#include <string>

#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace YAML {
class Node;
}  // namespace YAML

namespace secure::experiments {

/// Reads the section of `domain` (Domain::ConfigSection(): `pipeline`, `panda_push`, ...) of a
/// config file's root mapping `config` (null: no file; `source` names the file in messages):
///   1. the section's `domain:` key into the domain's own options (Domain::ApplyYaml), then
///      Domain::Validate (its errors prefixed "<source> [<section>] [domain]: ");
///   2. the domain's preset (Domain::Preset(), which follows the domain's options: e.g. shield.dt
///      is the domain's control period);
///   3. the section's other keys over the preset (ExperimentOptions::ApplyYaml: barrier, bc,
///      airl, joint, shield, check, closed_loop; an unknown key is an error naming it).
/// Returns the experiment options; a missing section gives the (validated) domain's preset.
/// Flags come after, each overriding its field only when given (the commands' one rule).
ExperimentOptions ReadSection(const YAML::Node& config, const std::string& source,
                              Domain& domain);

/// A config file's root: a regular file within the input limits (secure/common/input_limits.h),
/// strict YAML (no duplicate key at any depth, bounded depth and nodes), a mapping of sections
/// or empty (a null node). Throws secure::Error naming the file (and the line where known). The
/// CLI adds its check of the section names (apps/secure/cli_common.cc).
YAML::Node LoadConfigFile(const std::string& path);

}  // namespace secure::experiments
