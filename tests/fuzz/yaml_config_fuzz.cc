// libFuzzer target: a config file's text as `--config` reads it (issue 34): the depth check on
// the text, yaml-cpp's parser, the node and depth limits with aliases expanded, the duplicate-key
// check. Any input must load or throw secure::Error (or a YAML::Exception, which LoadConfig turns
// into one); a crash, another exception, a run over libFuzzer's -timeout (an alias bomb that
// escapes the node limit) or its -rss_limit_mb is a defect. The corpus holds the bombs.
#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "secure/common/error.h"
#include "secure/common/yaml_keys.h"
#include "secure/common/yaml_limits.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    CheckYamlTextDepth(text, "fuzz.yaml");
    const YAML::Node root = YAML::Load(text);
    CheckYamlLimits(root, "fuzz.yaml");
    CheckNoDuplicateKeys(root, "fuzz.yaml");
  } catch (const Error&) {
  } catch (const YAML::Exception&) {
  }
  return 0;
}
