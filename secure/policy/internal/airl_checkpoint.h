#pragma once
// AIRL checkpoint files (docs/FILE_FORMATS.md, version 2): the framing (format line, LibTorch
// archive, CRC-32 trailer), the networks and optimiser states in the archive, and the metadata
// a resume is checked against. What the metadata holds is the trainer's (airl_trainer.cc).
// INTERNAL: includes <torch/torch.h>; include it only from secure/policy/*.cc.

#include <torch/torch.h>

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "secure/data/data.h"
#include "secure/nn/mlp.h"
#include "secure/nn/torch_mlp.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/internal/airl_ppo.h"
#include "secure/policy/internal/torch_policy.h"

namespace secure::policy::internal {

inline constexpr int kCheckpointVersion = 2;
inline constexpr const char* kCheckpointFormat = "secure-airl-checkpoint";

/// The checkpoint file's bytes: the format line, `archive`, the checksum trailer.
std::string FrameCheckpoint(const std::string& archive);
/// The archive inside a checkpoint file's `bytes`, after checking the format line, the version,
/// the trailer and the checksum; throws naming `path` and what is wrong.
std::string_view UnframeCheckpoint(const std::string& bytes, const std::string& path);

/// FNV-1a over the demonstration matrices, episode boundaries and feature names: identifies
/// the data a checkpoint was trained on.
std::uint64_t Fingerprint(const data::TrajectorySet& demos);
/// The options that shape the training trajectory (must match when resuming).
nlohmann::json TrainingShapingOptions(const AirlOptions& o);
/// A learning-curve row from its ToJson() (missing or non-numeric fields: NaN).
AirlIterationStats StatsFromJson(const nlohmann::json& j);

/// What a checkpoint's archive holds besides the metadata: what PPO updates (the policy, the
/// value net, the discriminator, their optimisers) and the discriminator's optimiser and the
/// normaliser.
struct CheckpointModules : PpoNets {
  torch::optim::Adam& disc_opt;
  nn::Normalizer& normalizer;
};

/// Writes `modules` and `meta` to `path` atomically (its directory is created).
void SaveCheckpoint(const std::string& path, const CheckpointModules& modules,
                    const nlohmann::json& meta);

/// Reads `path`: checks the framing, the metadata's format and version, and that every key of
/// `mine` (this run's metadata) that shapes training matches (demonstrations_fingerprint,
/// environment, horizon, episodes_per_iteration, policy_spec, warm_started, joint and every
/// option of mine["options"]); then loads `modules` and returns the metadata. Throws naming the
/// file and the first mismatch.
nlohmann::json LoadCheckpoint(const std::string& path, const CheckpointModules& modules,
                              const nlohmann::json& mine);

}  // namespace secure::policy::internal
