#pragma once
// Resource limits on what the program reads (issue 34): no small input may exhaust memory or
// hang a command. Each limit is stated here, with its default, and can be raised: by an
// environment variable (read once, at the first use) or by a program calling SetInputLimits (the
// CLI's global flags --max-input-bytes, --max-config-nodes, --max-hdf5-memory,
// --max-hdf5-seconds). tests/README.md lists them.
//
//   input file size      SECURE_MAX_INPUT_BYTES    4 GiB    every file read (CSV, model files,
//                                                           HDF5, task.json, result.json)
//   HDF5 declared data   (the same limit)                   a dataset's declared bytes, checked
//                                                           before any read allocates them
//   config nodes         SECURE_MAX_CONFIG_NODES   100000   YAML nodes visited with aliases
//                                                           expanded (configs, Python options)
//   config depth         SECURE_MAX_CONFIG_DEPTH   64       nesting of mappings and sequences
//   HDF5 reader memory   SECURE_MAX_HDF5_MEMORY    1 GiB +  address space the child process
//                                                  8 x the  reading an HDF5 file may map beyond
//                                                  file     its parent's (secure/data/data.h)
//   HDF5 reader time     SECURE_MAX_HDF5_SECONDS   600      wall-clock seconds that child may
//                                                           take before it is killed
//
// Inputs must also be regular files (a FIFO would block, /dev/zero never ends): see
// CheckRegularInputFile.

#include <cstdint>
#include <string>

namespace secure {

struct InputLimits {
  std::uint64_t max_input_bytes = std::uint64_t{4} << 30;
  long max_config_nodes = 100'000;
  int max_config_depth = 64;
  // 0: 1 GiB plus 8 times the size of the file read (Hdf5ReaderMemoryLimit).
  std::uint64_t max_hdf5_memory_bytes = 0;
  // Wall-clock seconds the child process reading one HDF5 file may take (a malformed file can
  // send libhdf5 into a loop; a child stuck after fork must not hang the command).
  std::uint64_t max_hdf5_seconds = 600;
};

/// The memory limit of the child process that reads an HDF5 file of `file_bytes` bytes:
/// max_hdf5_memory_bytes if set, else 1 GiB + 8 * file_bytes (the file's image, libhdf5's copy
/// of it, its values as doubles and as floats fit with room to spare).
std::uint64_t Hdf5ReaderMemoryLimit(std::uint64_t file_bytes);

/// The limits in force: the defaults, overridden by the environment variables above (a value
/// that is not a positive integer is ignored with a note on stderr), or by SetInputLimits.
const InputLimits& GetInputLimits();
void SetInputLimits(const InputLimits& limits);

/// Checks that `path` names a regular file (symlinks followed) of at most max_input_bytes,
/// before anything opens it (opening a FIFO without a writer blocks; /dev/zero never ends).
/// Returns its size. `what` names the input in the message ("config file", "model file").
/// @throws secure::Error, one line naming the path: "cannot read 'p': no such file",
///   "cannot read 'p': it is a directory, not a regular file", "... it is a FIFO ...",
///   "... it is a character device ...", "cannot read 'p': 5368709120 bytes, more than the
///   input limit of 4294967296 bytes (raise it with SECURE_MAX_INPUT_BYTES or
///   --max-input-bytes)".
std::uint64_t CheckRegularInputFile(const std::string& path);

/// "a FIFO", "a directory", ... for st_mode's file type.
std::string FileTypeName(unsigned mode);

}  // namespace secure
