#include "secure/policy/internal/airl_checkpoint.h"

#include <cstdio>
#include <filesystem>
#include <limits>
#include <sstream>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/nn/model_file.h"

namespace secure::policy::internal {
namespace {

// Checkpoint file, version 2 (docs/FILE_FORMATS.md):
//   "secure-airl-checkpoint 2\n"   format name and version
//   <LibTorch archive bytes>        a zip (torch::serialize::OutputArchive::save_to)
//   "\ncrc32 xxxxxxxx\n"            CRC-32 (nn::Crc32) of everything before this trailer
// Version 1 was the bare archive (a zip, "PK\x03\x04..."), without a checksum: LibTorch's
// reader does not verify the zip's own CRCs, so a flipped byte in tensor data was accepted.
constexpr std::string_view kCheckpointTrailerPrefix = "\ncrc32 ";
constexpr std::size_t kCheckpointTrailerSize = kCheckpointTrailerPrefix.size() + 8 + 1;

std::string Hex8(std::uint32_t value) {
  char buffer[9];
  std::snprintf(buffer, sizeof buffer, "%08x", static_cast<unsigned>(value));
  return buffer;
}

torch::Tensor NormalizerTensor(const Eigen::VectorXf& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {v.size()}, torch::kFloat32).clone();
}

Eigen::VectorXf EigenVector(const torch::Tensor& t) {
  const torch::Tensor c = t.contiguous().to(torch::kFloat32);
  return Eigen::Map<const Eigen::VectorXf>(c.data_ptr<float>(), c.numel());
}

std::string FirstLine(const std::string& text) { return text.substr(0, text.find('\n')); }

}  // namespace

std::string FrameCheckpoint(const std::string& archive) {
  std::string out =
      std::string(kCheckpointFormat) + " " + std::to_string(kCheckpointVersion) + "\n" + archive;
  const std::uint32_t crc = nn::Crc32(out);
  out += kCheckpointTrailerPrefix;
  out += Hex8(crc);
  out += '\n';
  return out;
}

std::string_view UnframeCheckpoint(const std::string& bytes, const std::string& path) {
  const std::string_view all(bytes);
  SECURE_CHECK(all.substr(0, 4) != std::string_view("PK\x03\x04", 4),
               path << ": AIRL checkpoint version 1 (a bare LibTorch archive without a checksum, "
                       "written by an older build); this build reads version "
                    << kCheckpointVersion
                    << " only: delete the file to start afresh, or run without resume");
  const std::string prefix = std::string(kCheckpointFormat) + " ";
  constexpr std::size_t kMaxFormatLine = 64;
  const std::size_t line_end = all.substr(0, kMaxFormatLine).find('\n');
  const bool prefix_ok =
      all.substr(0, prefix.size()) == std::string_view(prefix).substr(0, all.size());
  SECURE_CHECK(!prefix_ok || line_end != std::string_view::npos || all.size() >= kMaxFormatLine,
               path << ": truncated AIRL checkpoint (" << all.size()
                    << " bytes, the format line is incomplete)");
  SECURE_CHECK(prefix_ok && line_end != std::string_view::npos,
               path << ": not an AIRL checkpoint (it does not start with '" << kCheckpointFormat
                    << " <version>')");
  const std::string_view version = all.substr(prefix.size(), line_end - prefix.size());
  SECURE_CHECK(version == std::to_string(kCheckpointVersion),
               path << ": AIRL checkpoint version " << version << ", this build reads version "
                    << kCheckpointVersion << " only");
  const std::size_t body = line_end + 1;
  SECURE_CHECK(all.size() >= body + kCheckpointTrailerSize,
               path << ": truncated AIRL checkpoint (" << all.size()
                    << " bytes, no room for the checksum trailer)");
  const std::size_t trailer_start = all.size() - kCheckpointTrailerSize;
  const std::string_view trailer = all.substr(trailer_start);
  std::uint32_t stored = 0;
  bool hex = true;
  for (const char c : trailer.substr(kCheckpointTrailerPrefix.size(), 8)) {
    const int digit = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
    hex = hex && digit >= 0;
    stored = (stored << 4) | static_cast<std::uint32_t>(digit & 0xf);
  }
  SECURE_CHECK(hex &&
                   trailer.substr(0, kCheckpointTrailerPrefix.size()) == kCheckpointTrailerPrefix &&
                   trailer.back() == '\n',
               path << ": truncated or corrupt AIRL checkpoint (it does not end with the "
                       "checksum trailer '\\ncrc32 xxxxxxxx\\n')");
  const std::uint32_t computed = nn::Crc32(all.substr(0, trailer_start));
  SECURE_CHECK(stored == computed, path << ": checksum mismatch (stored " << Hex8(stored)
                                        << ", computed " << Hex8(computed)
                                        << "): the checkpoint is corrupt");
  return all.substr(body, trailer_start - body);
}

std::uint64_t Fingerprint(const data::TrajectorySet& demos) {
  std::uint64_t h = 1469598103934665603ULL;
  auto mix = [&h](const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ULL;
  };
  mix(demos.states.data(), sizeof(float) * demos.states.size());
  mix(demos.actions.data(), sizeof(float) * demos.actions.size());
  mix(demos.episode_begin.data(), sizeof(long) * demos.episode_begin.size());
  for (const auto& f : demos.state_features) mix(f.data(), f.size() + 1);
  for (const auto& f : demos.action_features) mix(f.data(), f.size() + 1);
  return h;
}

nlohmann::json TrainingShapingOptions(const AirlOptions& o) {
  nlohmann::json j = o.ToJson();
  for (const char* key : {"iterations", "curve_path", "checkpoint_path", "checkpoint_every",
                          "resume", "stop_after_iterations"})
    j.erase(key);
  return j;
}

AirlIterationStats StatsFromJson(const nlohmann::json& j) {
  AirlIterationStats s;
  auto num = [&j](const char* key) {
    return j.contains(key) && j[key].is_number() ? j[key].get<double>()
                                                 : std::numeric_limits<double>::quiet_NaN();
  };
  s.iteration = static_cast<int>(num("iteration"));
  s.env_steps = static_cast<long>(num("env_steps"));
  s.episodes = static_cast<int>(num("episodes"));
  s.success_rate = num("success_rate");
  s.collision_rate = num("collision_rate");
  s.mean_collisions = num("mean_collisions");
  s.d_expert = num("d_expert");
  s.d_policy = num("d_policy");
  s.discriminator_loss = num("discriminator_loss");
  s.mean_reward = num("mean_reward");
  s.policy_loss = num("policy_loss");
  s.value_loss = num("value_loss");
  s.entropy = num("entropy");
  s.mean_sigma = num("mean_sigma");
  s.approx_kl = num("approx_kl");
  s.clip_fraction = num("clip_fraction");
  s.bc_nll = num("bc_nll");
  s.seconds = num("seconds");
  return s;
}

void SaveCheckpoint(const std::string& path, const CheckpointModules& modules,
                    const nlohmann::json& meta) {
  namespace ser = torch::serialize;
  ser::OutputArchive archive;
  auto nested = [&archive](const char* key, auto&& save) {
    ser::OutputArchive child(archive.compilation_unit());
    save(child);
    archive.write(key, child);
  };
  nested("policy", [&](ser::OutputArchive& a) { modules.policy->save(a); });
  nested("value", [&](ser::OutputArchive& a) { modules.value->save(a); });
  nested("discriminator", [&](ser::OutputArchive& a) { modules.disc->save(a); });
  nested("policy_adam", [&](ser::OutputArchive& a) { modules.policy_opt.save(a); });
  nested("value_adam", [&](ser::OutputArchive& a) { modules.value_opt.save(a); });
  nested("discriminator_adam", [&](ser::OutputArchive& a) { modules.disc_opt.save(a); });
  archive.write("normalizer_mean", NormalizerTensor(modules.normalizer.mean));
  archive.write("normalizer_scale", NormalizerTensor(modules.normalizer.scale));
  const std::string text = meta.dump();
  archive.write("meta", torch::from_blob(const_cast<char*>(text.data()),
                                         {static_cast<std::int64_t>(text.size())}, torch::kUInt8)
                            .clone());
  std::ostringstream bytes;
  archive.save_to(bytes);
  CreateDirectories(std::filesystem::path(path).parent_path().string());
  WriteFileAtomically(path, FrameCheckpoint(bytes.str()));
}

nlohmann::json LoadCheckpoint(const std::string& path, const CheckpointModules& modules,
                              const nlohmann::json& mine) {
  namespace ser = torch::serialize;
  const std::string file = ReadFile(path);
  const std::string_view bytes = UnframeCheckpoint(file, path);
  ser::InputArchive archive;
  nlohmann::json meta;
  try {
    std::istringstream in{std::string(bytes)};
    archive.load_from(in);
    torch::Tensor meta_tensor;
    archive.read("meta", meta_tensor);
    const torch::Tensor m = meta_tensor.contiguous();
    meta = nlohmann::json::parse(
        std::string(reinterpret_cast<const char*>(m.data_ptr<std::uint8_t>()), m.numel()));
  } catch (const c10::Error& e) {
    SECURE_THROW(path << ": not a readable AIRL checkpoint (" << FirstLine(e.what()) << ")");
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW(path << ": AIRL checkpoint metadata is not valid JSON (" << e.what() << ")");
  }
  SECURE_CHECK(meta.value("format", "") == kCheckpointFormat,
               path << ": not an AIRL checkpoint (format '" << meta.value("format", "") << "')");
  SECURE_CHECK(meta.value("version", 0) == kCheckpointVersion,
               path << ": AIRL checkpoint version " << meta.value("version", 0)
                    << ", this build reads version " << kCheckpointVersion);
  // Everything that shapes training must match.
  for (const char* key : {"demonstrations_fingerprint", "environment", "horizon",
                          "episodes_per_iteration", "policy_spec", "warm_started", "joint"}) {
    SECURE_CHECK(meta.contains(key) && meta[key] == mine[key],
                 path << ": cannot resume: the checkpoint's " << key << " is "
                      << (meta.contains(key) ? meta[key].dump() : "missing") << ", this run's is "
                      << mine[key].dump());
  }
  SECURE_CHECK(meta.contains("options") && meta["options"].is_object(),
               path << ": checkpoint has no options");
  for (const auto& [key, value] : mine["options"].items()) {
    SECURE_CHECK(meta["options"].contains(key) && meta["options"][key] == value,
                 path << ": cannot resume: the checkpoint was trained with AirlOptions::" << key
                      << " = "
                      << (meta["options"].contains(key) ? meta["options"][key].dump() : "(missing)")
                      << ", this run has " << value.dump());
  }
  try {
    auto nested = [&archive](const char* key, auto&& load) {
      ser::InputArchive child;
      archive.read(key, child);
      load(child);
    };
    nested("policy", [&](ser::InputArchive& a) { modules.policy->load(a); });
    nested("value", [&](ser::InputArchive& a) { modules.value->load(a); });
    nested("discriminator", [&](ser::InputArchive& a) { modules.disc->load(a); });
    nested("policy_adam", [&](ser::InputArchive& a) { modules.policy_opt.load(a); });
    nested("value_adam", [&](ser::InputArchive& a) { modules.value_opt.load(a); });
    nested("discriminator_adam", [&](ser::InputArchive& a) { modules.disc_opt.load(a); });
    torch::Tensor mean, scale;
    archive.read("normalizer_mean", mean);
    archive.read("normalizer_scale", scale);
    modules.normalizer.mean = EigenVector(mean);
    modules.normalizer.scale = EigenVector(scale);
    modules.normalizer.Validate(path + " normalizer");
  } catch (const c10::Error& e) {
    SECURE_THROW(path << ": corrupt AIRL checkpoint (" << FirstLine(e.what()) << ")");
  }
  return meta;
}

}  // namespace secure::policy::internal
