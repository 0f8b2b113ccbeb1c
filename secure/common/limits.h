#pragma once
// Upper limits on sizes that users give (flags, config files). The option structs' Validate()
// check them before any work, so that an impossible size is an error naming the field and the
// bound ("episodes = 2147483648, must be in [1, 1000000]") rather than an allocation failure,
// an overflow or a run that ends hours later. Each limit is far above what the experiments use.

namespace secure {

/// Episodes per method and seed (evaluation, shield runs, demonstrations).
inline constexpr long kMaxEpisodes = 1'000'000;
/// Seeds of one run (each seed trains and evaluates models).
inline constexpr long kMaxSeeds = 10'000;
/// States sampled or generated per class (one float per feature each).
inline constexpr long kMaxStates = 100'000'000;
/// Width of a hidden layer of a trained network (a width-w layer holds w x w weights).
inline constexpr int kMaxLayerWidth = 10'000;
/// Actions the shield samples or probes per round (its buffers hold this many).
inline constexpr int kMaxShieldSamples = 1'000'000;

}  // namespace secure
