#include "secure/nn/model_file.h"

#include <algorithm>
#include <boost/crc.hpp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>

#include "secure/common/atomic_file.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"

// Format choices (version 1), beyond what model_file.h states:
//  * The CRC-32 (boost::crc_32_type) covers one contiguous byte range: the JSON header line
//    INCLUDING its terminating '\n', followed by the payload. It does not cover the format line
//    (which is compared byte for byte anyway) nor the trailer's leading '\n'.
//  * The trailer is exactly "\ncrc32 " + 8 lowercase hex digits + "\n" and must end the file;
//    anything after it is rejected as a corrupt trailer.
//  * The header is nlohmann::json::dump() without indentation: keys sorted, control characters
//    escaped, so it never contains a newline. Unknown header fields are ignored on read.
//  * Tensor shapes are JSON arrays of non-negative integers; [] is a scalar (1 value).
//  * Parse order is chosen so that corruption is reported as such: the header's JSON and
//    payload_bytes are read first (needed to find the payload's end), then the trailer and the
//    checksum, and only then the remaining header fields, so a flipped byte that keeps the JSON
//    valid is reported as a checksum mismatch rather than as a confusing field error.

namespace secure::nn {
namespace {

using nlohmann::json;

constexpr std::string_view kTrailerPrefix = "\ncrc32 ";
constexpr std::size_t kTrailerSize = kTrailerPrefix.size() + 8 + 1;

// Values are stored little-endian; on a little-endian host a float's bytes are copied as they
// are, elsewhere they are reversed.
#if defined(__BYTE_ORDER__) && defined(__ORDER_LITTLE_ENDIAN__) && \
    __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
constexpr bool kHostIsLittleEndian = true;
#elif defined(__BYTE_ORDER__) && defined(__ORDER_BIG_ENDIAN__) && \
    __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
constexpr bool kHostIsLittleEndian = false;
#else
#error "cannot determine the byte order of this platform (model files are little-endian)"
#endif
static_assert(sizeof(float) == 4 && std::numeric_limits<float>::is_iec559,
              "model files store IEEE-754 binary32 floats");

void AppendFloatsLittleEndian(const std::vector<float>& values, std::string* out) {
  const std::size_t start = out->size();
  out->resize(start + values.size() * 4);
  char* dst = out->data() + start;
  if (values.empty()) return;
  std::memcpy(dst, values.data(), values.size() * 4);
  if constexpr (!kHostIsLittleEndian) {
    for (std::size_t i = 0; i < values.size(); ++i) std::reverse(dst + 4 * i, dst + 4 * i + 4);
  }
}

void ReadFloatsLittleEndian(const char* src, std::size_t count, std::vector<float>* values) {
  values->resize(count);
  if (count == 0) return;
  std::memcpy(values->data(), src, count * 4);
  if constexpr (!kHostIsLittleEndian) {
    char* bytes = reinterpret_cast<char*>(values->data());
    for (std::size_t i = 0; i < count; ++i) std::reverse(bytes + 4 * i, bytes + 4 * i + 4);
  }
}

std::string Hex8(std::uint32_t value) {
  char buffer[9];
  std::snprintf(buffer, sizeof(buffer), "%08x", static_cast<unsigned>(value));
  return buffer;
}

// A possibly binary line, shortened and with non-printable bytes escaped, for a message.
std::string Printable(std::string_view text) {
  constexpr std::size_t kMaxShown = 60;
  std::string out;
  for (std::size_t i = 0; i < text.size() && i < kMaxShown; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      char buffer[5];
      std::snprintf(buffer, sizeof(buffer), "\\x%02x", c);
      out += buffer;
    }
  }
  if (text.size() > kMaxShown) out += "...";
  return out;
}

std::string ShapeString(const std::vector<std::int64_t>& shape) {
  std::string out = "[";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) out += ",";
    out += std::to_string(shape[i]);
  }
  return out + "]";
}

// Number of values of `shape`, or -1 if a dim is negative or the count exceeds `limit` (so an
// absurd shape can neither overflow nor be read past the payload).
std::int64_t CountValues(const std::vector<std::int64_t>& shape, std::uint64_t limit) {
  for (const std::int64_t dim : shape)
    if (dim < 0) return -1;
  for (const std::int64_t dim : shape)
    if (dim == 0) return 0;
  std::uint64_t count = 1;
  for (const std::int64_t dim : shape) {
    const auto d = static_cast<std::uint64_t>(dim);
    if (count > limit / d) return -1;
    count *= d;
  }
  return count <= limit ? static_cast<std::int64_t>(count) : -1;
}

// Metadata must survive a write/read round trip unchanged; JSON has no NaN or Inf (nlohmann
// would silently write null), so such numbers are rejected with their location.
void CheckMetadataFinite(const json& value, const std::string& where, const std::string& what) {
  if (value.is_number_float()) {
    SECURE_CHECK(std::isfinite(value.get<double>()),
                 what << ": metadata value at '" << where << "' is " << value.get<double>()
                      << "; JSON cannot store non-finite numbers");
  } else if (value.is_object()) {
    for (const auto& [key, item] : value.items())
      CheckMetadataFinite(item, where + "/" + key, what);
  } else if (value.is_array()) {
    for (std::size_t i = 0; i < value.size(); ++i)
      CheckMetadataFinite(value[i], where + "/" + std::to_string(i), what);
  }
}

// Throws naming the first non-finite value of `tensor`.
void CheckFinite(const NamedTensor& tensor, const std::string& what) {
  for (std::size_t i = 0; i < tensor.values.size(); ++i) {
    SECURE_CHECK(std::isfinite(tensor.values[i]),
                 what << ": tensor '" << tensor.name << "' has a non-finite value ("
                      << tensor.values[i] << ") at index " << i << " (row-major)");
  }
}

std::string SerializeChecked(const ModelFile& file, const std::string& what) {
  SECURE_CHECK(!file.kind.empty(), what << ": model kind is empty");
  SECURE_CHECK(file.metadata.is_object(),
               what << ": metadata must be a JSON object, not " << file.metadata.type_name());
  CheckMetadataFinite(file.metadata, "", what);

  json header;
  header["kind"] = file.kind;
  header["metadata"] = file.metadata;
  json tensors = json::array();
  std::set<std::string> names;
  std::uint64_t payload_bytes = 0;
  for (const NamedTensor& tensor : file.tensors) {
    SECURE_CHECK(!tensor.name.empty(), what << ": a tensor has an empty name");
    SECURE_CHECK(names.insert(tensor.name).second,
                 what << ": duplicate tensor name '" << tensor.name << "'");
    const std::int64_t count =
        CountValues(tensor.shape, std::numeric_limits<std::uint64_t>::max() / 4);
    SECURE_CHECK(count >= 0, what << ": tensor '" << tensor.name << "' has invalid shape "
                                  << ShapeString(tensor.shape));
    SECURE_CHECK(static_cast<std::uint64_t>(count) == tensor.values.size(),
                 what << ": tensor '" << tensor.name << "' has " << tensor.values.size()
                      << " values but shape " << ShapeString(tensor.shape) << " needs " << count);
    CheckFinite(tensor, what);
    tensors.push_back({{"name", tensor.name}, {"shape", tensor.shape}});
    payload_bytes += tensor.values.size() * 4;
  }
  header["tensors"] = std::move(tensors);
  header["payload_bytes"] = payload_bytes;

  std::string header_line;
  try {
    header_line = header.dump();
  } catch (const json::exception& e) {  // e.g. a string that is not valid UTF-8
    SECURE_THROW(what << ": cannot encode the JSON header: " << e.what());
  }
  header_line += '\n';

  std::string out =
      std::string(kModelFormatName) + " " + std::to_string(kModelFormatVersion) + "\n";
  const std::size_t crc_start = out.size();
  out.reserve(crc_start + header_line.size() + payload_bytes + kTrailerSize);
  out += header_line;
  for (const NamedTensor& tensor : file.tensors) AppendFloatsLittleEndian(tensor.values, &out);
  const std::uint32_t crc = Crc32(std::string_view(out).substr(crc_start));
  out += kTrailerPrefix;
  out += Hex8(crc);
  out += '\n';
  return out;
}

// Header field access with messages naming the field.
const json& Field(const json& object, const char* name, const std::string& source) {
  const auto it = object.find(name);
  SECURE_CHECK(it != object.end(), source << ": missing header field '" << name << "'");
  return *it;
}

bool ParseHex8(std::string_view text, std::uint32_t* value) {
  if (text.size() != 8) return false;
  std::uint32_t v = 0;
  for (const char c : text) {
    int digit;
    if (c >= '0' && c <= '9') {
      digit = c - '0';
    } else if (c >= 'a' && c <= 'f') {
      digit = c - 'a' + 10;
    } else {
      return false;
    }
    v = (v << 4) | static_cast<std::uint32_t>(digit);
  }
  *value = v;
  return true;
}

const NamedTensor* FindTensor(const ModelFile& file, const std::string& name) {
  for (const NamedTensor& tensor : file.tensors)
    if (tensor.name == name) return &tensor;
  return nullptr;
}

// The tensor `name`, checked to have exactly `shape` and matching values; `why` ends the shape
// message ("from the stored architecture").
const NamedTensor& ExpectTensor(const ModelFile& file, const std::string& name,
                                const std::vector<std::int64_t>& shape, const std::string& why,
                                const std::string& source) {
  const NamedTensor* tensor = FindTensor(file, name);
  SECURE_CHECK(tensor != nullptr,
               source << ": missing tensor '" << name << "' (model kind '" << file.kind << "')");
  SECURE_CHECK(tensor->shape == shape, source << ": tensor '" << name << "' has shape "
                                              << ShapeString(tensor->shape) << ", expected "
                                              << ShapeString(shape) << " " << why);
  const std::int64_t count = CountValues(shape, std::numeric_limits<std::uint64_t>::max() / 4);
  SECURE_CHECK(count >= 0 && static_cast<std::uint64_t>(count) == tensor->values.size(),
               source << ": tensor '" << name << "' has " << tensor->values.size()
                      << " values but shape " << ShapeString(shape) << " needs " << count);
  CheckFinite(*tensor, source);
  return *tensor;
}

// A positive int from an MLP's metadata, e.g. metadata["barrier"]["input_dim"].
int PositiveInt(const json& value, const std::string& field, const std::string& source) {
  SECURE_CHECK(value.is_number_integer() && value.get<std::int64_t>() > 0 &&
                   value.get<std::int64_t>() <= std::numeric_limits<int>::max(),
               source << ": metadata field '" << field << "' = " << value.dump()
                      << ", must be a positive integer");
  return static_cast<int>(value.get<std::int64_t>());
}

// {input_dim, hidden..., output_dim} (the same as MlpSpec::Widths, kept local so that the file
// format does not depend on mlp.cc beyond validation).
std::vector<int> LayerWidths(const MlpSpec& spec) {
  std::vector<int> widths{spec.input_dim};
  widths.insert(widths.end(), spec.hidden.begin(), spec.hidden.end());
  widths.push_back(spec.output_dim);
  return widths;
}

const json& MetadataField(const json& object, const std::string& prefix, const char* name,
                          const std::string& source) {
  const auto it = object.find(name);
  SECURE_CHECK(it != object.end(),
               source << ": metadata field '" << prefix << "." << name << "' is missing");
  return *it;
}

}  // namespace

std::uint32_t Crc32(std::string_view bytes) {
  boost::crc_32_type crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

const NamedTensor& ModelFile::Tensor(const std::string& name) const {
  if (const NamedTensor* tensor = FindTensor(*this, name)) return *tensor;
  std::ostringstream available;
  constexpr std::size_t kMaxListed = 12;
  for (std::size_t i = 0; i < tensors.size() && i < kMaxListed; ++i)
    available << (i ? ", " : "") << "'" << tensors[i].name << "'";
  if (tensors.size() > kMaxListed) available << ", ...";
  SECURE_THROW("model of kind '" << kind << "' has no tensor '" << name << "' (it has "
                                 << (tensors.empty() ? std::string("none") : available.str())
                                 << ")");
}

std::string SerializeModelFile(const ModelFile& file) {
  return SerializeChecked(file, "model file (kind '" + file.kind + "')");
}

ModelFile ParseModelFile(const std::string& bytes, const std::string& source) {
  // --- Format line.
  SECURE_CHECK(!bytes.empty(), source << ": not a secure model file (the file is empty)");
  const std::size_t format_end = bytes.find('\n');
  const std::string_view format_line = std::string_view(bytes).substr(
      0, format_end == std::string::npos ? bytes.size() : format_end);
  const std::size_t space = format_line.find(' ');
  SECURE_CHECK(
      space != std::string_view::npos && format_line.substr(0, space) == kModelFormatName,
      source << ": not a secure model file (first line is '" << Printable(format_line) << "')");
  const std::string_view version = format_line.substr(space + 1);
  SECURE_CHECK(version == std::to_string(kModelFormatVersion),
               source << ": unsupported format version " << Printable(version)
                      << " (this build reads version " << kModelFormatVersion << ")");
  SECURE_CHECK(format_end != std::string::npos,
               source << ": truncated: the file ends inside the format line");

  // --- JSON header (only payload_bytes is needed before the checksum).
  const std::size_t header_start = format_end + 1;
  const std::size_t header_end = bytes.find('\n', header_start);
  SECURE_CHECK(header_end != std::string::npos,
               source << ": truncated: the JSON header line has no terminating newline");
  json header;
  try {
    header = json::parse(bytes.begin() + static_cast<std::ptrdiff_t>(header_start),
                         bytes.begin() + static_cast<std::ptrdiff_t>(header_end));
  } catch (const json::exception& e) {  // parse_error, or out_of_range for e.g. 1e400
    SECURE_THROW(source << ": malformed JSON header: " << e.what());
  }
  SECURE_CHECK(header.is_object(), source << ": malformed JSON header: expected an object, found "
                                          << header.type_name());
  const json& payload_json = Field(header, "payload_bytes", source);
  SECURE_CHECK(payload_json.is_number_unsigned(),
               source << ": header field 'payload_bytes' = " << payload_json.dump()
                      << ", must be a non-negative integer");
  const std::uint64_t payload_bytes = payload_json.get<std::uint64_t>();

  // --- Payload length, trailer, checksum.
  const std::size_t payload_start = header_end + 1;
  const std::size_t available = bytes.size() - payload_start;
  SECURE_CHECK(payload_bytes <= available, source << ": truncated: header announces "
                                                  << payload_bytes << " payload bytes, file has "
                                                  << available);
  const std::size_t payload_end = payload_start + static_cast<std::size_t>(payload_bytes);
  const std::string_view trailer = std::string_view(bytes).substr(payload_end);
  std::uint32_t stored_crc = 0;
  SECURE_CHECK(trailer.size() == kTrailerSize &&
                   trailer.substr(0, kTrailerPrefix.size()) == kTrailerPrefix &&
                   trailer.back() == '\n' &&
                   ParseHex8(trailer.substr(kTrailerPrefix.size(), 8), &stored_crc),
               source << ": truncated or corrupt trailer (expected '\\ncrc32 xxxxxxxx\\n' after "
                      << payload_bytes << " payload bytes, found '" << Printable(trailer) << "')");
  const std::uint32_t computed_crc =
      Crc32(std::string_view(bytes).substr(header_start, payload_end - header_start));
  SECURE_CHECK(stored_crc == computed_crc, source << ": checksum mismatch (stored "
                                                  << Hex8(stored_crc) << ", computed "
                                                  << Hex8(computed_crc) << "): file is corrupt");

  // --- The rest of the header.
  ModelFile file;
  const json& kind = Field(header, "kind", source);
  SECURE_CHECK(
      kind.is_string() && !kind.get_ref<const std::string&>().empty(),
      source << ": header field 'kind' = " << kind.dump() << ", must be a non-empty string");
  file.kind = kind.get<std::string>();
  const json& metadata = Field(header, "metadata", source);
  SECURE_CHECK(metadata.is_object(), source << ": header field 'metadata' must be an object, not "
                                            << metadata.type_name());
  file.metadata = metadata;
  const json& tensors = Field(header, "tensors", source);
  SECURE_CHECK(tensors.is_array(),
               source << ": header field 'tensors' must be an array, not " << tensors.type_name());

  std::set<std::string> names;
  std::uint64_t offset = 0;  // into the payload
  file.tensors.reserve(tensors.size());
  for (std::size_t t = 0; t < tensors.size(); ++t) {
    const json& entry = tensors[t];
    const std::string where = "tensors[" + std::to_string(t) + "]";
    SECURE_CHECK(entry.is_object(), source << ": header field '" << where
                                           << "' must be an object, not " << entry.type_name());
    const json& name = Field(entry, "name", source + ": " + where);
    SECURE_CHECK(name.is_string() && !name.get_ref<const std::string&>().empty(),
                 source << ": header field '" << where << ".name' = " << name.dump()
                        << ", must be a non-empty string");
    NamedTensor tensor;
    tensor.name = name.get<std::string>();
    SECURE_CHECK(names.insert(tensor.name).second,
                 source << ": duplicate tensor name '" << tensor.name << "'");
    const json& shape = Field(entry, "shape", source + ": tensor '" + tensor.name + "'");
    SECURE_CHECK(shape.is_array(), source << ": tensor '" << tensor.name
                                          << "': shape must be an array, not "
                                          << shape.type_name());
    for (const json& dim : shape) {
      SECURE_CHECK(dim.is_number_unsigned() &&
                       dim.get<std::uint64_t>() <=
                           static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()),
                   source << ": tensor '" << tensor.name << "' has shape " << shape.dump()
                          << "; dimensions must be non-negative integers");
      tensor.shape.push_back(dim.get<std::int64_t>());
    }
    const std::uint64_t remaining = (payload_bytes - offset) / 4;
    const std::int64_t count = CountValues(tensor.shape, remaining);
    SECURE_CHECK(count >= 0, source << ": tensor '" << tensor.name << "' with shape "
                                    << ShapeString(tensor.shape) << " extends past the end of the "
                                    << payload_bytes << "-byte payload (it starts at byte "
                                    << offset << ")");
    ReadFloatsLittleEndian(bytes.data() + payload_start + offset, static_cast<std::size_t>(count),
                           &tensor.values);
    offset += static_cast<std::uint64_t>(count) * 4;
    CheckFinite(tensor, source);
    file.tensors.push_back(std::move(tensor));
  }
  SECURE_CHECK(
      offset == payload_bytes,
      source << ": header announces " << payload_bytes << " payload bytes but its "
             << file.tensors.size() << " tensors use only " << offset
             << (file.tensors.empty() ? std::string()
                                      : " (last tensor '" + file.tensors.back().name + "')"));
  return file;
}

void WriteModelFile(const std::string& path, const ModelFile& file) {
  // Serialise (and validate) before touching the file system, so a bad model leaves no file.
  const std::string bytes = SerializeChecked(file, path);
  WriteFileAtomically(path, bytes);
}

ModelFile ReadModelFile(const std::string& path) { return ParseModelFile(ReadFile(path), path); }

ModelFile ReadModelFileOfKind(const std::string& path, const std::string& kind) {
  ModelFile file = ReadModelFile(path);
  SECURE_CHECK(file.kind == kind,
               path << ": holds a '" << file.kind << "' model, expected '" << kind << "'");
  return file;
}

namespace {
bool IsTimingKey(const std::string& key) {
  auto ends_with = [&](const std::string& suffix) {
    return key.size() >= suffix.size() &&
           key.compare(key.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  return key == "seconds" || ends_with("_seconds") || ends_with("_per_second");
}
}  // namespace

nlohmann::json WithoutTiming(nlohmann::json summary) {
  if (summary.is_object()) {
    for (auto it = summary.begin(); it != summary.end();) {
      if (IsTimingKey(it.key())) {
        it = summary.erase(it);
      } else {
        *it = WithoutTiming(std::move(*it));
        ++it;
      }
    }
  } else if (summary.is_array()) {
    for (auto& element : summary) element = WithoutTiming(std::move(element));
  }
  return summary;
}

void AddMlp(const std::string& prefix, const MlpParams& params, ModelFile* file) {
  SECURE_INTERNAL_CHECK(file != nullptr, "AddMlp needs a ModelFile");
  SECURE_CHECK(!prefix.empty(), "AddMlp: empty prefix");
  SECURE_CHECK(file->metadata.is_object() && !file->metadata.contains(prefix),
               "AddMlp: metadata already has an entry '" << prefix << "'");
  params.Validate(prefix);
  // Shapes are checked here as well so that what is written always matches the spec written
  // next to it, whatever MlpParams::Validate checks.
  const std::vector<int> widths = LayerWidths(params.spec);
  SECURE_CHECK(params.layers.size() + 1 == widths.size(), prefix << ": " << params.layers.size()
                                                                 << " layers, spec needs "
                                                                 << widths.size() - 1);

  // Build everything first so that a failure leaves *file unchanged.
  std::vector<NamedTensor> tensors;
  for (std::size_t i = 0; i < params.layers.size(); ++i) {
    const DenseLayer& layer = params.layers[i];
    const std::string name = prefix + ".layer" + std::to_string(i);
    SECURE_CHECK(layer.weight.rows() == widths[i + 1] && layer.weight.cols() == widths[i] &&
                     layer.bias.size() == widths[i + 1],
                 prefix << ": layer " << i << " has weight " << layer.weight.rows() << "x"
                        << layer.weight.cols() << " and bias " << layer.bias.size()
                        << ", spec needs " << widths[i + 1] << "x" << widths[i] << " and "
                        << widths[i + 1]);
    // Eigen matrices are column-major; the file is row-major (out x in), so copy through a
    // row-major map rather than the raw buffer.
    NamedTensor weight{name + ".weight", {layer.weight.rows(), layer.weight.cols()}, {}};
    weight.values.resize(static_cast<std::size_t>(layer.weight.size()));
    Eigen::Map<Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
        weight.values.data(), layer.weight.rows(), layer.weight.cols()) = layer.weight;
    NamedTensor bias{name + ".bias",
                     {layer.bias.size()},
                     std::vector<float>(layer.bias.data(), layer.bias.data() + layer.bias.size())};
    for (const NamedTensor* tensor : {&weight, &bias}) {
      SECURE_CHECK(FindTensor(*file, tensor->name) == nullptr,
                   "AddMlp: the model already has a tensor '" << tensor->name << "'");
    }
    tensors.push_back(std::move(weight));
    tensors.push_back(std::move(bias));
  }
  file->metadata[prefix] = {{"input_dim", params.spec.input_dim},
                            {"hidden", params.spec.hidden},
                            {"output_dim", params.spec.output_dim},
                            {"activation", ToString(kActivationNames, params.spec.activation)}};
  for (NamedTensor& tensor : tensors) file->tensors.push_back(std::move(tensor));
}

MlpParams GetMlp(const std::string& prefix, const ModelFile& file, const std::string& source) {
  const auto entry = file.metadata.find(prefix);
  SECURE_CHECK(
      file.metadata.is_object() && entry != file.metadata.end(),
      source << ": no MLP '" << prefix << "' in the metadata (model kind '" << file.kind << "')");
  SECURE_CHECK(entry->is_object(), source << ": metadata '" << prefix
                                          << "' must be an object describing an MLP, not "
                                          << entry->type_name());
  MlpParams params;
  MlpSpec& spec = params.spec;
  spec.input_dim = PositiveInt(MetadataField(*entry, prefix, "input_dim", source),
                               prefix + ".input_dim", source);
  spec.output_dim = PositiveInt(MetadataField(*entry, prefix, "output_dim", source),
                                prefix + ".output_dim", source);
  const json& hidden = MetadataField(*entry, prefix, "hidden", source);
  SECURE_CHECK(hidden.is_array(), source << ": metadata field '" << prefix
                                         << ".hidden' = " << hidden.dump() << ", must be an array");
  for (std::size_t i = 0; i < hidden.size(); ++i)
    spec.hidden.push_back(
        PositiveInt(hidden[i], prefix + ".hidden[" + std::to_string(i) + "]", source));
  const json& activation = MetadataField(*entry, prefix, "activation", source);
  SECURE_CHECK(activation.is_string(), source << ": metadata field '" << prefix << ".activation' = "
                                              << activation.dump() << ", must be a string");
  spec.activation = FromString(kActivationNames, activation.get_ref<const std::string&>(),
                               source + ": metadata field '" + prefix + ".activation'");

  const std::vector<int> widths = LayerWidths(spec);
  for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
    const std::string name = prefix + ".layer" + std::to_string(i);
    const std::int64_t in = widths[i];
    const std::int64_t out = widths[i + 1];
    const NamedTensor& weight =
        ExpectTensor(file, name + ".weight", {out, in}, "from the stored architecture", source);
    const NamedTensor& bias =
        ExpectTensor(file, name + ".bias", {out}, "from the stored architecture", source);
    DenseLayer layer;
    layer.weight =
        Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
            weight.values.data(), out, in);
    layer.bias = Eigen::Map<const Eigen::VectorXf>(bias.values.data(), out);
    params.layers.push_back(std::move(layer));
  }
  // A leftover layer tensor means the stored architecture and weights disagree.
  const std::string extra = prefix + ".layer" + std::to_string(widths.size() - 1) + ".weight";
  SECURE_CHECK(FindTensor(file, extra) == nullptr,
               source << ": tensor '" << extra << "' is not part of the stored architecture ("
                      << widths.size() - 1 << " layers)");
  params.Validate(source);
  return params;
}

void AddNormalizer(const std::string& prefix, const Normalizer& normalizer, ModelFile* file) {
  SECURE_INTERNAL_CHECK(file != nullptr, "AddNormalizer needs a ModelFile");
  SECURE_CHECK(!prefix.empty(), "AddNormalizer: empty prefix");
  SECURE_CHECK(normalizer.mean.size() == normalizer.scale.size(),
               prefix << ": normalizer mean has " << normalizer.mean.size() << " values, scale has "
                      << normalizer.scale.size());
  normalizer.Validate(prefix);
  NamedTensor mean{
      prefix + ".mean",
      {normalizer.mean.size()},
      std::vector<float>(normalizer.mean.data(), normalizer.mean.data() + normalizer.mean.size())};
  NamedTensor scale{prefix + ".scale",
                    {normalizer.scale.size()},
                    std::vector<float>(normalizer.scale.data(),
                                       normalizer.scale.data() + normalizer.scale.size())};
  SECURE_CHECK(FindTensor(*file, mean.name) == nullptr && FindTensor(*file, scale.name) == nullptr,
               "AddNormalizer: the model already has a tensor '" << prefix << ".mean' or '"
                                                                 << prefix << ".scale'");
  file->tensors.push_back(std::move(mean));
  file->tensors.push_back(std::move(scale));
}

Normalizer GetNormalizer(const std::string& prefix, const ModelFile& file,
                         const std::string& source) {
  const NamedTensor* mean = FindTensor(file, prefix + ".mean");
  SECURE_CHECK(mean != nullptr, source << ": missing tensor '" << prefix << ".mean' (model kind '"
                                       << file.kind << "')");
  SECURE_CHECK(mean->shape.size() == 1, source << ": tensor '" << mean->name << "' has shape "
                                               << ShapeString(mean->shape)
                                               << ", expected a vector [dim]");
  const std::int64_t dim = mean->shape[0];
  ExpectTensor(file, mean->name, {dim}, "", source);
  const NamedTensor& scale =
      ExpectTensor(file, prefix + ".scale", {dim}, "(the shape of '" + mean->name + "')", source);
  for (std::size_t i = 0; i < scale.values.size(); ++i) {
    SECURE_CHECK(scale.values[i] > 0.0f, source << ": tensor '" << scale.name << "' has value "
                                                << scale.values[i] << " at index " << i
                                                << ", must be > 0");
  }
  Normalizer normalizer;
  normalizer.mean = Eigen::Map<const Eigen::VectorXf>(mean->values.data(), dim);
  normalizer.scale = Eigen::Map<const Eigen::VectorXf>(scale.values.data(), dim);
  normalizer.Validate(source);
  return normalizer;
}

}  // namespace secure::nn
