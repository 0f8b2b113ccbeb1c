// The global flags that raise the input limits (secure/common/input_limits.h): --max-input-bytes,
// --max-config-nodes, --max-hdf5-memory and --max-hdf5-seconds, given before the command (`secure
// --max-input-bytes 10000000000 demos convert ...`). They are applied before anything is read, the --config file included (which
// is read before the command line is parsed), so they are scanned from argv here and also
// declared to CLI11 (for --help and the value check).
#include <CLI/CLI.hpp>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string>

#include "cli_common.h"
#include "secure/common/error.h"
#include "secure/common/input_limits.h"

namespace secure::cli {

namespace {
unsigned long long PositiveInteger(const std::string& flag, const std::string& text) {
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  SECURE_CHECK(!text.empty() && text[0] != '-' && errno == 0 && end != nullptr && *end == '\0' &&
                   v > 0,
               flag << " = '" << text << "', expected a positive integer");
  return v;
}
}  // namespace

void AddInputLimitFlags(CLI::App& app, int argc, char** argv) {
  InputLimits limits = GetInputLimits();
  // Only before the command's name (the flags belong to `secure` itself).
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg.empty() || arg[0] != '-') break;
    for (const char* flag : {"--max-input-bytes", "--max-config-nodes", "--max-hdf5-memory",
                             "--max-hdf5-seconds"}) {
      std::string value;
      const std::string prefix = std::string(flag) + "=";
      if (arg == flag && i + 1 < argc) {
        value = argv[i + 1];
      } else if (arg.rfind(prefix, 0) == 0) {
        value = arg.substr(prefix.size());
      } else {
        continue;
      }
      const unsigned long long v = PositiveInteger(flag, value);
      if (std::strcmp(flag, "--max-input-bytes") == 0) {
        limits.max_input_bytes = v;
      } else if (std::strcmp(flag, "--max-hdf5-memory") == 0) {
        limits.max_hdf5_memory_bytes = v;
      } else if (std::strcmp(flag, "--max-hdf5-seconds") == 0) {
        limits.max_hdf5_seconds = v;
      } else {
        SECURE_CHECK(v <= 1'000'000'000ull, flag << " = " << v << ", must be at most 1000000000");
        limits.max_config_nodes = static_cast<long>(v);
      }
    }
  }
  SetInputLimits(limits);
  app.add_option("--max-input-bytes", "largest input file read, and largest HDF5 data declared, "
                                      "in bytes (default 4294967296; env SECURE_MAX_INPUT_BYTES); "
                                      "before the command");
  app.add_option("--max-hdf5-memory", "memory, in bytes, of the child process that reads an "
                                      "HDF5 file (default 1 GiB + 8 x the file's size; env "
                                      "SECURE_MAX_HDF5_MEMORY); before the command");
  app.add_option("--max-hdf5-seconds", "wall-clock seconds the child process that reads an "
                                       "HDF5 file may take (default 600; env "
                                       "SECURE_MAX_HDF5_SECONDS); before the command");
  app.add_option("--max-config-nodes", "most YAML nodes of a --config file with aliases expanded "
                                       "(default 100000; env SECURE_MAX_CONFIG_NODES); before "
                                       "the command");
}

}  // namespace secure::cli
