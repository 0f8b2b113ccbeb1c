// libFuzzer target: AIRL checkpoints (policy::TrainAirl with resume). Inputs whose first byte is
// odd get a correct CRC trailer appended after the rest (the checkpoint's CRC-32 covers
// everything before its trailer), so that mutations reach the LibTorch archive and the metadata
// checks behind the checksum; the others are read as they are. The run asks for one iteration, so
// a checkpoint that resumes (the seed corpus holds a one-iteration checkpoint of this very setup)
// returns without training. Any input must resume or throw secure::Error.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "secure/common/error.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/nn/model_file.h"
#include "secure/policy/airl_trainer.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

namespace di = secure::domains::double_integrator;

// Two short expert-like episodes of the reach-avoid task (no files, no randomness).
secure::data::TrajectorySet Demos(const di::ReachAvoidEnv& env) {
  secure::data::TrajectorySet set;
  set.source = "fuzz demos";
  set.state_features = env.ObservationFeatures();
  set.action_features = env.ActionFeatures();
  const int steps = 8;
  set.states.resize(env.observation_dim(), 2 * steps);
  set.actions.resize(env.action_dim(), 2 * steps);
  for (int c = 0; c < 2 * steps; ++c) {
    for (int r = 0; r < env.observation_dim(); ++r) set.states(r, c) = 0.1f * (r + 1) + 0.05f * c;
    for (int r = 0; r < env.action_dim(); ++r) set.actions(r, c) = 0.2f * r - 0.1f;
  }
  set.episode_begin = {0, steps, 2 * steps};
  return set;
}

std::string WithValidTrailer(const std::string& body) {
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", static_cast<unsigned>(secure::nn::Crc32(body)));
  return body + "\ncrc32 " + hex + "\n";
}

secure::policy::AirlOptions FuzzAirlOptions() {
  secure::policy::AirlOptions o;
  o.iterations = 1;
  o.steps_per_iteration = 1;  // one episode
  o.policy_hidden = {8};
  o.value_hidden = {8};
  o.reward_hidden = {8};
  o.shaping_hidden = {8};
  o.ppo_epochs = 1;
  o.minibatch_size = 16;
  o.discriminator_updates = 1;
  o.discriminator_batch = 8;
  o.seed = 7;
  return o;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  static const di::ReachAvoidEnv env{di::ReachAvoidOptions{}};
  static const data::TrajectorySet demos = Demos(env);
  if (size == 0) {
    // An empty input writes the seed checkpoint of this setup (see README.md), then stops.
    if (const char* out = std::getenv("SECURE_FUZZ_WRITE_SEED")) {
      policy::AirlOptions o = FuzzAirlOptions();
      o.checkpoint_path = out;
      policy::TrainAirl(o, demos, env, nullptr, nullptr);
    }
    return 0;
  }
  std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1) bytes = WithValidTrailer(bytes);
  policy::AirlOptions o = FuzzAirlOptions();
  o.checkpoint_path = fuzz::WriteScratch(bytes, ".ckpt");
  o.resume = true;
  try {
    policy::TrainAirl(o, demos, env, nullptr, nullptr);
  } catch (const Error&) {
  }
  return 0;
}
