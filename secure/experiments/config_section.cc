// ReadSection (config_section.h): a domain's config section into its options and the experiment
// options, in one order for every command.
#include "secure/experiments/config_section.h"

#include <yaml-cpp/yaml.h>

#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/excerpt.h"
#include "secure/common/input_limits.h"
#include "secure/common/yaml_keys.h"
#include "secure/common/yaml_limits.h"
#include "secure/common/yaml_value.h"

namespace secure::experiments {

ExperimentOptions ReadSection(const YAML::Node& config, const std::string& source,
                              Domain& domain) {
  const std::string name = domain.ConfigSection();
  YAML::Node section;
  if (config && config.IsMap() && config[name]) {
    section = config[name];
    SECURE_CHECK(section.IsMap(), source << ":" << section.Mark().line + 1 << ": section '"
                                         << name << "' must be a mapping");
  }
  const std::string where = source + " [" + name + "]";
  // 1. The domain's own options (the `domain:` key), checked before the preset reads them.
  YAML::Node rest(YAML::NodeType::Map);
  if (section.IsMap()) {
    for (const auto& entry : section) {
      const std::string key = YamlKey(entry.first, where);
      if (key == "domain") {
        domain.ApplyYaml(entry.second, where + " [domain]");
      } else {
        rest[entry.first] = entry.second;
      }
    }
  }
  try {
    domain.Validate();
  } catch (const Error& e) {
    if (!section.IsMap()) throw;
    throw Error(where + " [domain]: " + e.what());  // the value came from this file
  }
  // 2. and 3. The preset, then the section's other keys.
  ExperimentOptions options = domain.Preset();
  if (section.IsMap()) options.ApplyYaml(rest, where, &domain);
  return options;
}

YAML::Node LoadConfigFile(const std::string& path) {
  // A regular file of bounded size (a FIFO would block, /dev/zero never end), nested no deeper
  // than the parser can take, and at most so many nodes with aliases expanded (input_limits.h).
  if (::access(path.c_str(), F_OK) != 0)
    SECURE_THROW("cannot open config file '" << path << "': " << std::strerror(errno));
  CheckRegularInputFile(path);
  const std::string text = ReadFile(path);
  CheckYamlTextDepth(text, path);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    SECURE_THROW(path << ": invalid YAML: " << Excerpt(e.what()));
  }
  CheckYamlLimits(root, path);
  SECURE_CHECK(!root || root.IsMap(), path << ": the config file must be a mapping of sections");
  if (root) CheckNoDuplicateKeys(root, path);
  return root;
}

}  // namespace secure::experiments
