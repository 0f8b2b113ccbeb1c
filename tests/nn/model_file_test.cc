#include "secure/nn/model_file.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <boost/crc.hpp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"

namespace secure::nn {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

using secure::test::ErrorOf;

bool BitEqual(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void ExpectSameModel(const ModelFile& a, const ModelFile& b) {
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.metadata, b.metadata);
  ASSERT_EQ(a.tensors.size(), b.tensors.size());
  for (std::size_t i = 0; i < a.tensors.size(); ++i) {
    EXPECT_EQ(a.tensors[i].name, b.tensors[i].name);
    EXPECT_EQ(a.tensors[i].shape, b.tensors[i].shape);
    EXPECT_TRUE(BitEqual(a.tensors[i].values, b.tensors[i].values)) << a.tensors[i].name;
  }
}

bool SameModel(const ModelFile& a, const ModelFile& b) {
  if (a.kind != b.kind || a.metadata != b.metadata || a.tensors.size() != b.tensors.size())
    return false;
  for (std::size_t i = 0; i < a.tensors.size(); ++i) {
    if (a.tensors[i].name != b.tensors[i].name || a.tensors[i].shape != b.tensors[i].shape ||
        !BitEqual(a.tensors[i].values, b.tensors[i].values))
      return false;
  }
  return true;
}

std::string Hex8(std::uint32_t v) {
  char buffer[9];
  std::snprintf(buffer, sizeof(buffer), "%08x", static_cast<unsigned>(v));
  return buffer;
}

// Hand-assembles a file with a correct checksum around arbitrary header text and payload, to
// test the checks that run after the checksum. The CRC covers the header line including its
// newline, then the payload.
std::string MakeFileBytes(const std::string& header, const std::string& payload,
                          const std::string& format_line = "secure-model 1") {
  const std::string covered = header + "\n" + payload;
  boost::crc_32_type crc;
  crc.process_bytes(covered.data(), covered.size());
  return format_line + "\n" + covered + "\ncrc32 " + Hex8(crc.checksum()) + "\n";
}

std::string FloatBytes(const std::vector<float>& values) {
  std::string out(values.size() * 4, '\0');
  if (!values.empty()) std::memcpy(out.data(), values.data(), out.size());  // x86-64: LE
  return out;
}

ModelFile SampleModel() {
  ModelFile file;
  file.kind = "barrier_mlp";
  file.metadata = {{"domain", "pendulum"},
                   {"lr", 0.1},
                   {"epochs", 300},
                   {"big", std::numeric_limits<std::uint64_t>::max()},
                   {"negative", -7},
                   {"flags", {true, false, nullptr}},
                   {"nested", {{"unicode", "\xc3\xa9t\xc3\xa9 \xe2\x9c\x93"}, {"tiny", 1e-300}}},
                   {"text", "line one\nline two\t\"quoted\""}};
  file.tensors.push_back({"a", {2, 3}, {1.0f, -0.0f, 3.5f, 1e-40f, -2.25f, 6.0f}});
  file.tensors.push_back({"scalar", {}, {42.0f}});
  file.tensors.push_back({"empty", {0, 3}, {}});
  file.tensors.push_back({"b",
                          {4},
                          {std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest(),
                           std::numeric_limits<float>::denorm_min(), 0.3f}});
  return file;
}

MlpParams RandomParams(const MlpSpec& spec, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> dist(-1.0f, 1.0f);
  MlpParams params;
  params.spec = spec;
  std::vector<int> widths{spec.input_dim};
  widths.insert(widths.end(), spec.hidden.begin(), spec.hidden.end());
  widths.push_back(spec.output_dim);
  for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
    DenseLayer layer;
    layer.weight.resize(widths[i + 1], widths[i]);
    layer.bias.resize(widths[i + 1]);
    for (Eigen::Index k = 0; k < layer.weight.size(); ++k) layer.weight.data()[k] = dist(rng);
    for (Eigen::Index k = 0; k < layer.bias.size(); ++k) layer.bias[k] = dist(rng);
    params.layers.push_back(std::move(layer));
  }
  return params;
}

MlpSpec SmallSpec() {
  MlpSpec spec;
  spec.input_dim = 2;
  spec.hidden = {3, 5};
  spec.output_dim = 1;
  spec.activation = Activation::kTanh;
  return spec;
}

// A fresh directory under the system temp dir, removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("secure_model_file_test_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  std::string File(const std::string& name) const { return (path_ / name).string(); }
  std::vector<std::string> Entries() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(path_))
      names.push_back(entry.path().filename().string());
    return names;
  }

 private:
  fs::path path_;
};

// ---------------------------------------------------------------------------------------------
// Round trips.

TEST(ModelFileTest, SerializeParseRoundTripIsBitExact) {
  const ModelFile original = SampleModel();
  const std::string bytes = SerializeModelFile(original);
  const ModelFile parsed = ParseModelFile(bytes, "model.bin");
  ExpectSameModel(original, parsed);
  // Serialisation is deterministic, so a re-serialised file is byte-identical.
  EXPECT_EQ(SerializeModelFile(parsed), bytes);
}

TEST(ModelFileTest, LayoutMatchesTheDocumentedFormat) {
  ModelFile file;
  file.kind = "k";
  file.tensors.push_back({"t", {2}, {1.0f, -2.0f}});
  const std::string bytes = SerializeModelFile(file);

  const std::string magic = "secure-model 1\n";
  ASSERT_EQ(bytes.compare(0, magic.size(), magic), 0);
  const std::size_t header_end = bytes.find('\n', magic.size());
  ASSERT_NE(header_end, std::string::npos);
  const json header = json::parse(bytes.substr(magic.size(), header_end - magic.size()));
  EXPECT_EQ(header["kind"], "k");
  EXPECT_EQ(header["payload_bytes"], 8);
  EXPECT_EQ(header["tensors"], json::parse(R"([{"name":"t","shape":[2]}])"));
  EXPECT_EQ(header["metadata"], json::object());
  // Little-endian float32 payload: 1.0f = 00 00 80 3f, -2.0f = 00 00 00 c0.
  EXPECT_EQ(bytes.substr(header_end + 1, 8), std::string("\x00\x00\x80\x3f\x00\x00\x00\xc0", 8));
  // Trailer: CRC-32 of the header line (with its newline) and the payload.
  const std::string covered = bytes.substr(magic.size(), header_end + 1 + 8 - magic.size());
  boost::crc_32_type crc;
  crc.process_bytes(covered.data(), covered.size());
  EXPECT_EQ(bytes.substr(header_end + 1 + 8), "\ncrc32 " + Hex8(crc.checksum()) + "\n");
}

TEST(ModelFileTest, EmptyModelRoundTrips) {
  ModelFile file;
  file.kind = "nothing";
  ExpectSameModel(file, ParseModelFile(SerializeModelFile(file), "empty.bin"));
}

TEST(ModelFileTest, MlpRoundTripsExactlyIncludingNonSquareWeights) {
  const MlpParams params = RandomParams(SmallSpec(), 7);
  ModelFile file;
  file.kind = "barrier_mlp";
  AddMlp("barrier", params, &file);

  EXPECT_EQ(file.metadata["barrier"],
            json::parse(R"({"input_dim":2,"hidden":[3,5],"output_dim":1,"activation":"tanh"})"));
  // Row-major storage: element (r, c) of the (out x in) weight is at r * in + c.
  const NamedTensor& w1 = file.Tensor("barrier.layer1.weight");
  ASSERT_EQ(w1.shape, (std::vector<std::int64_t>{5, 3}));
  for (int r = 0; r < 5; ++r)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(w1.values[r * 3 + c], params.layers[1].weight(r, c));
  EXPECT_EQ(file.Tensor("barrier.layer2.bias").shape, (std::vector<std::int64_t>{1}));

  const ModelFile parsed = ParseModelFile(SerializeModelFile(file), "model.bin");
  const MlpParams back = GetMlp("barrier", parsed, "model.bin");
  EXPECT_EQ(back.spec.input_dim, 2);
  EXPECT_EQ(back.spec.hidden, (std::vector<int>{3, 5}));
  EXPECT_EQ(back.spec.output_dim, 1);
  EXPECT_EQ(back.spec.activation, Activation::kTanh);
  ASSERT_EQ(back.layers.size(), params.layers.size());
  for (std::size_t i = 0; i < params.layers.size(); ++i) {
    ASSERT_EQ(back.layers[i].weight.rows(), params.layers[i].weight.rows());
    ASSERT_EQ(back.layers[i].weight.cols(), params.layers[i].weight.cols());
    EXPECT_TRUE(back.layers[i].weight == params.layers[i].weight) << "layer " << i;
    EXPECT_TRUE(back.layers[i].bias == params.layers[i].bias) << "layer " << i;
  }
}

TEST(ModelFileTest, ReluActivationAndTwoMlpsInOneFile) {
  MlpSpec policy_spec;
  policy_spec.input_dim = 4;
  policy_spec.hidden = {6};
  policy_spec.output_dim = 2;
  policy_spec.activation = Activation::kRelu;
  ModelFile file;
  file.kind = "gaussian_policy";
  AddMlp("mean", RandomParams(policy_spec, 1), &file);
  AddMlp("barrier", RandomParams(SmallSpec(), 2), &file);
  const ModelFile parsed = ParseModelFile(SerializeModelFile(file), "p.bin");
  EXPECT_EQ(GetMlp("mean", parsed, "p.bin").spec.activation, Activation::kRelu);
  EXPECT_EQ(GetMlp("barrier", parsed, "p.bin").spec.hidden, (std::vector<int>{3, 5}));
  // The same prefix twice would silently mix two networks.
  EXPECT_HAS(ErrorOf([&] { AddMlp("mean", RandomParams(policy_spec, 3), &file); }), "'mean'");
}

TEST(ModelFileTest, NormalizerRoundTrips) {
  Normalizer normalizer;
  normalizer.mean = Eigen::Vector3f(0.5f, -1.0f, 2.0f);
  normalizer.scale = Eigen::Vector3f(1.0f, 0.25f, 3.0f);
  ModelFile file;
  file.kind = "barrier_mlp";
  AddNormalizer("input", normalizer, &file);
  EXPECT_EQ(file.Tensor("input.mean").shape, (std::vector<std::int64_t>{3}));
  const Normalizer back =
      GetNormalizer("input", ParseModelFile(SerializeModelFile(file), "n.bin"), "n.bin");
  EXPECT_TRUE(back.mean == normalizer.mean);
  EXPECT_TRUE(back.scale == normalizer.scale);
}

TEST(ModelFileTest, GetNormalizerRejectsBadScaleAndMismatchedDims) {
  ModelFile file;
  file.kind = "k";
  file.tensors.push_back({"input.mean", {2}, {0.0f, 0.0f}});
  file.tensors.push_back({"input.scale", {2}, {1.0f, 0.0f}});
  std::string msg = ErrorOf([&] { GetNormalizer("input", file, "n.bin"); });
  EXPECT_HAS(msg, "n.bin: ");
  EXPECT_HAS(msg, "'input.scale'");
  EXPECT_HAS(msg, "index 1");

  file.tensors[1] = {"input.scale", {3}, {1.0f, 1.0f, 1.0f}};
  msg = ErrorOf([&] { GetNormalizer("input", file, "n.bin"); });
  EXPECT_HAS(msg, "'input.scale' has shape [3], expected [2]");

  file.tensors.pop_back();
  EXPECT_HAS(ErrorOf([&] { GetNormalizer("input", file, "n.bin"); }), "'input.scale'");
}

// ---------------------------------------------------------------------------------------------
// Files on disk.

TEST(ModelFileTest, WriteThenReadAndAtomicOverwrite) {
  TempDir dir;
  const std::string path = dir.File("model.bin");
  ModelFile first = SampleModel();
  WriteModelFile(path, first);
  ExpectSameModel(first, ReadModelFile(path));

  ModelFile second;
  second.kind = "gaussian_policy";
  AddMlp("mean", RandomParams(SmallSpec(), 11), &second);
  WriteModelFile(path, second);  // overwrites
  ExpectSameModel(second, ReadModelFile(path));
  // No temporary files are left behind.
  EXPECT_EQ(dir.Entries(), std::vector<std::string>{"model.bin"});
}

TEST(ModelFileTest, ReadingAMissingFileNamesThePath) {
  TempDir dir;
  const std::string path = dir.File("does_not_exist.bin");
  EXPECT_HAS(ErrorOf([&] { ReadModelFile(path); }), path);
}

TEST(ModelFileTest, WritingIntoAMissingDirectoryNamesThePath) {
  TempDir dir;
  const std::string path = dir.File("no/such/dir/model.bin");
  EXPECT_HAS(ErrorOf([&] { WriteModelFile(path, SampleModel()); }), path);
}

TEST(ModelFileTest, NonFiniteValuesAreRejectedOnWriteAndLeaveNoFile) {
  TempDir dir;
  const std::string path = dir.File("model.bin");
  ModelFile file = SampleModel();
  file.tensors[0].values[4] = std::numeric_limits<float>::quiet_NaN();
  std::string msg = ErrorOf([&] { WriteModelFile(path, file); });
  EXPECT_HAS(msg, path + ": ");
  EXPECT_HAS(msg, "tensor 'a'");
  EXPECT_HAS(msg, "index 4");
  EXPECT_TRUE(dir.Entries().empty());

  file.tensors[0].values[4] = 0.0f;
  file.tensors[3].values[1] = -std::numeric_limits<float>::infinity();
  msg = ErrorOf([&] { SerializeModelFile(file); });
  EXPECT_HAS(msg, "tensor 'b'");
  EXPECT_HAS(msg, "index 1");
}

TEST(ModelFileTest, InvalidModelsAreRejectedOnWrite) {
  ModelFile file = SampleModel();
  file.tensors[1].name = "a";
  EXPECT_HAS(ErrorOf([&] { SerializeModelFile(file); }), "duplicate tensor name 'a'");

  file = SampleModel();
  file.tensors[0].shape = {3, 3};
  EXPECT_HAS(ErrorOf([&] { SerializeModelFile(file); }), "tensor 'a' has 6 values");

  file = SampleModel();
  file.tensors[0].shape = {-2, -3};
  EXPECT_HAS(ErrorOf([&] { SerializeModelFile(file); }), "tensor 'a'");

  file = SampleModel();
  file.kind = "";
  EXPECT_HAS(ErrorOf([&] { SerializeModelFile(file); }), "kind");

  file = SampleModel();
  file.metadata["nested"]["bad"] = std::nan("");
  EXPECT_HAS(ErrorOf([&] { SerializeModelFile(file); }), "/nested/bad");

  file = SampleModel();
  file.metadata = json::array();
  EXPECT_HAS(ErrorOf([&] { SerializeModelFile(file); }), "metadata");
}

// ---------------------------------------------------------------------------------------------
// Corrupt and malformed files.

TEST(ModelFileTest, WrongMagicIsNotAModelFile) {
  std::string msg = ErrorOf([] { ParseModelFile("hello world\n{}\n", "model.bin"); });
  EXPECT_HAS(msg, "model.bin: not a secure model file (first line is 'hello world')");
  msg = ErrorOf([] { ParseModelFile(std::string("\x89PNG\r\n\x1a\n", 8), "img.png"); });
  EXPECT_HAS(msg, "img.png: not a secure model file");
  EXPECT_HAS(ErrorOf([] { ParseModelFile("", "empty.bin"); }), "empty.bin: ");
}

TEST(ModelFileTest, OtherVersionIsUnsupported) {
  std::string bytes = SerializeModelFile(SampleModel());
  bytes[std::string("secure-model ").size()] = '2';
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(bytes, "model.bin"); }),
             "model.bin: unsupported format version 2 (this build reads version 1)");
  const std::string v7 = MakeFileBytes("{}", "", "secure-model 7");
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(v7, "m"); }),
             "m: unsupported format version 7 (this build reads version 1)");
}

TEST(ModelFileTest, EveryTruncationThrows) {
  const std::string bytes = SerializeModelFile(SampleModel());
  for (std::size_t size = 0; size < bytes.size(); ++size) {
    EXPECT_THROW(ParseModelFile(bytes.substr(0, size), "model.bin"), secure::Error)
        << "cut at " << size << " of " << bytes.size();
  }
}

TEST(ModelFileTest, TruncationMessagesSayWhereTheFileEnds) {
  const std::string bytes = SerializeModelFile(SampleModel());
  const std::size_t header_start = bytes.find('\n') + 1;
  const std::size_t payload_start = bytes.find('\n', header_start) + 1;
  const std::size_t payload_bytes = 4 * (6 + 1 + 0 + 4);
  const std::size_t payload_end = payload_start + payload_bytes;
  ASSERT_EQ(bytes.size(), payload_end + 16);

  // Inside the JSON header.
  std::string msg = ErrorOf([&] { ParseModelFile(bytes.substr(0, header_start + 10), "m.bin"); });
  EXPECT_HAS(msg, "m.bin: truncated");
  // Inside the payload.
  msg = ErrorOf([&] { ParseModelFile(bytes.substr(0, payload_start + 5), "m.bin"); });
  EXPECT_HAS(msg, "m.bin: truncated: header announces " + std::to_string(payload_bytes) +
                      " payload bytes, file has 5");
  // Inside the trailer, and with the trailer missing altogether.
  for (const std::size_t size : {payload_end, payload_end + 1, payload_end + 9, payload_end + 15}) {
    msg = ErrorOf([&] { ParseModelFile(bytes.substr(0, size), "m.bin"); });
    EXPECT_HAS(msg, "m.bin: truncated or corrupt trailer");
  }
  // Extra bytes after the trailer are corruption too.
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(bytes + "x", "m.bin"); }), "corrupt trailer");
}

TEST(ModelFileTest, FlippedPayloadByteIsAChecksumMismatch) {
  std::string bytes = SerializeModelFile(SampleModel());
  const std::size_t payload_start = bytes.find('\n', bytes.find('\n') + 1) + 1;
  bytes[payload_start + 3] ^= 0x10;
  const std::string msg = ErrorOf([&] { ParseModelFile(bytes, "model.bin"); });
  EXPECT_HAS(msg, "model.bin: checksum mismatch (stored ");
  EXPECT_HAS(msg, "): file is corrupt");
}

TEST(ModelFileTest, FlippedHeaderByteIsCaught) {
  const std::string original = SerializeModelFile(SampleModel());
  const std::size_t header_start = original.find('\n') + 1;
  // A flip that keeps the JSON valid ("pendulum" -> "pendulun") must hit the checksum.
  std::string bytes = original;
  const std::size_t pos = bytes.find("pendulum");
  ASSERT_NE(pos, std::string::npos);
  bytes[pos + 7] = 'n';
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(bytes, "model.bin"); }), "model.bin: checksum mismatch");
  // A flip that breaks the JSON is reported by the JSON parser.
  bytes = original;
  bytes[header_start] = '[';
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(bytes, "model.bin"); }),
             "model.bin: malformed JSON header: ");
}

TEST(ModelFileTest, CorruptStoredChecksumIsCaught) {
  std::string bytes = SerializeModelFile(SampleModel());
  char& digit = bytes[bytes.size() - 2];
  digit = digit == '0' ? '1' : '0';
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(bytes, "m"); }), "m: checksum mismatch");
  bytes[bytes.size() - 2] = 'g';
  EXPECT_HAS(ErrorOf([&] { ParseModelFile(bytes, "m"); }), "m: truncated or corrupt trailer");
}

TEST(ModelFileTest, MalformedHeadersNameTheProblem) {
  const std::string payload = FloatBytes({1.0f, 2.0f});
  const auto parse_error = [&](const std::string& header) {
    return ErrorOf([&] { ParseModelFile(MakeFileBytes(header, payload), "model.bin"); });
  };
  const std::string good = R"({"kind":"k","metadata":{},"tensors":[{"name":"t","shape":[2]}],)"
                           R"("payload_bytes":8})";
  EXPECT_NO_THROW(ParseModelFile(MakeFileBytes(good, payload), "model.bin"));

  EXPECT_HAS(parse_error(R"({"kind": "k",)"), "model.bin: malformed JSON header: ");
  EXPECT_HAS(parse_error("[1,2]"), "model.bin: malformed JSON header");
  EXPECT_HAS(parse_error(R"({"kind":"k","metadata":{},"tensors":[]})"),
             "missing header field 'payload_bytes'");
  EXPECT_HAS(parse_error(R"({"metadata":{},"tensors":[],"payload_bytes":8})"),
             "missing header field 'kind'");
  EXPECT_HAS(parse_error(R"({"kind":"k","tensors":[],"payload_bytes":8})"),
             "missing header field 'metadata'");
  EXPECT_HAS(parse_error(R"({"kind":"k","metadata":{},"payload_bytes":8})"),
             "missing header field 'tensors'");
  EXPECT_HAS(parse_error(R"({"kind":"","metadata":{},"tensors":[],"payload_bytes":8})"), "'kind'");
  EXPECT_HAS(parse_error(R"({"kind":"k","metadata":[],"tensors":[],"payload_bytes":8})"),
             "'metadata'");
  EXPECT_HAS(parse_error(R"({"kind":"k","metadata":{},"tensors":[],"payload_bytes":-8})"),
             "'payload_bytes'");
  EXPECT_HAS(parse_error(R"({"kind":"k","metadata":{},"tensors":[{"shape":[2]}],)"
                         R"("payload_bytes":8})"),
             "missing header field 'name'");
  EXPECT_HAS(parse_error(R"({"kind":"k","metadata":{},"tensors":[{"name":"t"}],)"
                         R"("payload_bytes":8})"),
             "missing header field 'shape'");
}

TEST(ModelFileTest, TensorShapesMustAccountForThePayload) {
  const std::string payload = FloatBytes({1.0f, 2.0f, 3.0f, 4.0f});
  const auto parse_error = [&](const std::string& tensors) {
    const std::string header =
        R"({"kind":"k","metadata":{},"tensors":)" + tensors + R"(,"payload_bytes":16})";
    return ErrorOf([&] { ParseModelFile(MakeFileBytes(header, payload), "model.bin"); });
  };
  std::string msg = parse_error(R"([{"name":"w","shape":[2,-2]}])");
  EXPECT_HAS(msg, "model.bin: tensor 'w'");
  EXPECT_HAS(msg, "non-negative");
  EXPECT_HAS(parse_error(R"([{"name":"w","shape":[2,1.5]}])"), "tensor 'w'");
  msg = parse_error(R"([{"name":"w","shape":[2]},{"name":"v","shape":[3]}])");
  EXPECT_HAS(msg, "model.bin: tensor 'v' with shape [3] extends past the end");
  msg = parse_error(R"([{"name":"w","shape":[1]},{"name":"v","shape":[2]}])");
  EXPECT_HAS(msg, "'v'");
  EXPECT_HAS(msg, "use only 12");
  // An absurd shape must not overflow into a small count.
  EXPECT_HAS(parse_error(R"([{"name":"w","shape":[4294967296,4294967296,4]}])"), "tensor 'w'");
  EXPECT_HAS(parse_error(R"([{"name":"w","shape":[2]},{"name":"w","shape":[2]}])"),
             "model.bin: duplicate tensor name 'w'");
}

TEST(ModelFileTest, NonFiniteValuesInAFileNameTheTensorAndIndex) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const std::string header = R"({"kind":"k","metadata":{},"tensors":[{"name":"ok","shape":[1]},)"
                             R"({"name":"w","shape":[2,2]}],"payload_bytes":20})";
  std::string msg = ErrorOf([&] {
    ParseModelFile(MakeFileBytes(header, FloatBytes({0.0f, 1.0f, 2.0f, nan, 4.0f})), "m.bin");
  });
  EXPECT_HAS(msg, "m.bin: tensor 'w' has a non-finite value");
  EXPECT_HAS(msg, "index 2");
  msg = ErrorOf([&] {
    ParseModelFile(MakeFileBytes(header, FloatBytes({-inf, 1.0f, 2.0f, 3.0f, 4.0f})), "m.bin");
  });
  EXPECT_HAS(msg, "tensor 'ok'");
  EXPECT_HAS(msg, "index 0");
}

TEST(ModelFileTest, GetMlpChecksShapesAgainstTheStoredSpec) {
  ModelFile file;
  file.kind = "barrier_mlp";
  AddMlp("barrier", RandomParams(SmallSpec(), 3), &file);
  for (NamedTensor& tensor : file.tensors) {
    if (tensor.name == "barrier.layer1.weight") tensor.shape = {3, 5};  // transposed
  }
  // Through a file, as a user would meet it.
  const ModelFile parsed = ParseModelFile(SerializeModelFile(file), "model.bin");
  EXPECT_HAS(ErrorOf([&] { GetMlp("barrier", parsed, "model.bin"); }),
             "model.bin: tensor 'barrier.layer1.weight' has shape [3,5], expected [5,3] from the "
             "stored architecture");
}

TEST(ModelFileTest, GetMlpNamesMissingTensorsAndMetadata) {
  ModelFile file;
  file.kind = "barrier_mlp";
  AddMlp("barrier", RandomParams(SmallSpec(), 4), &file);

  ModelFile missing = file;
  missing.tensors.erase(missing.tensors.begin() + 3);  // barrier.layer1.bias
  std::string msg = ErrorOf([&] { GetMlp("barrier", missing, "model.bin"); });
  EXPECT_HAS(msg, "model.bin: ");
  EXPECT_HAS(msg, "'barrier.layer1.bias'");

  msg = ErrorOf([&] { GetMlp("policy", file, "model.bin"); });
  EXPECT_HAS(msg, "model.bin: ");
  EXPECT_HAS(msg, "'policy'");

  ModelFile bad_spec = file;
  bad_spec.metadata["barrier"].erase("hidden");
  EXPECT_HAS(ErrorOf([&] { GetMlp("barrier", bad_spec, "model.bin"); }), "barrier.hidden");
  bad_spec = file;
  bad_spec.metadata["barrier"]["activation"] = "sigmoid";
  msg = ErrorOf([&] { GetMlp("barrier", bad_spec, "model.bin"); });
  EXPECT_HAS(msg, "model.bin: ");
  EXPECT_HAS(msg, "'sigmoid'");
  bad_spec = file;
  bad_spec.metadata["barrier"]["hidden"][1] = 0;
  EXPECT_HAS(ErrorOf([&] { GetMlp("barrier", bad_spec, "model.bin"); }), "barrier.hidden[1]");
  bad_spec = file;
  bad_spec.metadata["barrier"]["hidden"] = {3};  // layer2 tensors are now left over
  EXPECT_THROW(GetMlp("barrier", bad_spec, "model.bin"), secure::Error);
}

TEST(ModelFileTest, TensorLookupNamesTheTensorAndKind) {
  const ModelFile file = SampleModel();
  EXPECT_EQ(file.Tensor("b").values.size(), 4u);
  const std::string msg = ErrorOf([&] { file.Tensor("nope"); });
  EXPECT_HAS(msg, "'nope'");
  EXPECT_HAS(msg, "barrier_mlp");
}

// Random single-byte corruptions and truncations: parsing throws secure::Error or, if the byte
// did not matter, returns exactly the original model. Never a crash, never garbage.
TEST(ModelFileTest, FuzzedCorruptionsThrowOrRoundTrip) {
  ModelFile original = SampleModel();
  AddMlp("barrier", RandomParams(SmallSpec(), 5), &original);
  const std::string bytes = SerializeModelFile(original);
  std::mt19937 rng(12345);
  int rejected = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::string corrupt = bytes;
    const std::size_t pos = std::uniform_int_distribution<std::size_t>(0, bytes.size() - 1)(rng);
    switch (trial % 4) {
      case 0:
        corrupt.resize(pos);
        break;
      case 1:
        corrupt[pos] = static_cast<char>(corrupt[pos] ^ (1 << (rng() % 8)));
        break;
      case 2:
        corrupt[pos] = static_cast<char>(corrupt[pos] ^ (1 + rng() % 255));
        break;
      default:
        corrupt.insert(pos, 1, static_cast<char>(rng() % 256));
        break;
    }
    try {
      const ModelFile parsed = ParseModelFile(corrupt, "fuzz.bin");
      EXPECT_TRUE(SameModel(parsed, original)) << "trial " << trial << " at byte " << pos;
    } catch (const secure::Error& e) {
      EXPECT_EQ(std::string(e.what()).rfind("fuzz.bin: ", 0), 0u) << e.what();
      ++rejected;
    }
  }
  EXPECT_GT(rejected, 190);  // a CRC-32 catches every single-byte change
}

TEST(ModelFileTest, WithoutTimingRemovesWallClockFieldsAtAnyDepth) {
  const json summary = {{"epochs", 3},
                        {"wall_seconds", 1.5},
                        {"seconds", 2.0},
                        {"ppo_seconds", 0.5},
                        {"env_steps_per_second", 1e4},
                        {"stop_reason", "max_epochs"},
                        {"seconds_budget_note", "kept: not a *_seconds suffix"},
                        {"last", {{"iteration", 2}, {"seconds", 3.0}, {"loss", 0.25}}},
                        {"rows", json::array({{{"seconds", 1.0}, {"x", 1}}})}};
  const json expected = {{"epochs", 3},
                         {"stop_reason", "max_epochs"},
                         {"seconds_budget_note", "kept: not a *_seconds suffix"},
                         {"last", {{"iteration", 2}, {"loss", 0.25}}},
                         {"rows", json::array({{{"x", 1}}})}};
  EXPECT_EQ(WithoutTiming(summary), expected);
  EXPECT_EQ(WithoutTiming(json(4)), json(4));
}

}  // namespace
}  // namespace secure::nn
