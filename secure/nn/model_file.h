#pragma once
// The secure model file: one self-describing, checksummed file per trained model.
//
// Layout (version 1):
//   line 1   "secure-model 1\n"                     format name and version
//   line 2   one line of JSON (the header):         {"kind": ..., "metadata": {...},
//                                                    "tensors": [{"name", "shape"}...],
//                                                    "payload_bytes": N}
//   N bytes  the tensors' float32 values, little-endian, in header order, each row-major
//   trailer  "\ncrc32 xxxxxxxx\n"                  CRC-32 (Boost.CRC) of line 2 including its
//                                                   newline, then the payload
// Readers reject a wrong format name or version, a truncated payload, a checksum mismatch,
// malformed JSON and non-finite values, each with a message naming the file and what is wrong.
// Writes are atomic (common/atomic_file.h).

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "secure/nn/mlp.h"

namespace secure::nn {

inline constexpr const char* kModelFormatName = "secure-model";
inline constexpr int kModelFormatVersion = 1;

struct NamedTensor {
  std::string name;
  std::vector<std::int64_t> shape;  // row-major
  std::vector<float> values;        // product(shape) values
};

struct ModelFile {
  std::string kind;  // e.g. "barrier_mlp", "gaussian_policy"
  nlohmann::json metadata = nlohmann::json::object();
  std::vector<NamedTensor> tensors;

  /// The tensor called `name`; throws secure::Error naming `name` and the file's kind if absent.
  const NamedTensor& Tensor(const std::string& name) const;
};

/// CRC-32 (boost::crc_32_type: the zlib/PNG polynomial) of `bytes`: the model file's checksum,
/// also used by other checksummed files (AIRL checkpoints).
std::uint32_t Crc32(std::string_view bytes);

/// Serialises to bytes (exposed for tests) and back. `source` names the file in messages.
std::string SerializeModelFile(const ModelFile& file);
ModelFile ParseModelFile(const std::string& bytes, const std::string& source);

/// Atomic write / checked read of a model file.
void WriteModelFile(const std::string& path, const ModelFile& file);
ModelFile ReadModelFile(const std::string& path);
/// ReadModelFile of a file that must hold a `kind` model: @throws secure::Error "<path>: holds a
/// '<its kind>' model, expected '<kind>'" otherwise.
ModelFile ReadModelFileOfKind(const std::string& path, const std::string& kind);

/// `summary` without wall-clock timing: every member, at any depth, named "seconds" or ending in
/// "_seconds" or "_per_second" is removed. Trainers store a training summary in the model file
/// through this, so that the same seed and data give byte-identical model files; the timing stays
/// in the run record (the command's --json output and printed summary).
nlohmann::json WithoutTiming(nlohmann::json summary);

/// Stores an MLP as tensors "<prefix>.layer<i>.weight" / ".bias" and its spec under
/// metadata[prefix]; and reads it back, validating shapes against the stored spec.
void AddMlp(const std::string& prefix, const MlpParams& params, ModelFile* file);
MlpParams GetMlp(const std::string& prefix, const ModelFile& file, const std::string& source);

/// Stores a Normalizer as tensors "<prefix>.mean" / "<prefix>.scale", and reads it back.
void AddNormalizer(const std::string& prefix, const Normalizer& normalizer, ModelFile* file);
Normalizer GetNormalizer(const std::string& prefix, const ModelFile& file,
                         const std::string& source);

}  // namespace secure::nn
