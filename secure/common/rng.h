#pragma once
// Seeded random numbers that are the same on every platform and standard library.
//
// std::mt19937_64 is portable but the std distributions are not (their algorithms are
// implementation-defined), and the shield draws hundreds of normals per decision, so the
// generator is xoshiro256++ (Blackman & Vigna, public domain) seeded through splitmix64, with
// our own uniform and normal transforms. The state is 40 bytes and trivially copyable, which
// lets a workspace own one without allocating.

#include <cstdint>
#include <utility>

namespace secure {

class Rng {
 public:
  explicit Rng(std::uint64_t seed = 0) { Seed(seed); }

  /// Re-seeds; the stream after Seed(s) is a pure function of s.
  void Seed(std::uint64_t seed);

  /// Raw 64 random bits.
  std::uint64_t NextU64() {
    const std::uint64_t result = Rotl(s_[0] + s_[3], 23) + s_[0];
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = Rotl(s_[3], 45);
    return result;
  }

  /// Uniform in [0, 1) with 53 random bits.
  double Uniform() { return static_cast<double>(NextU64() >> 11) * 0x1.0p-53; }
  /// Uniform in [lo, hi).
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  /// Uniform integer in [0, n), n > 0 (Lemire's multiply-shift; bias < 2^-64 * n, negligible).
  std::uint64_t UniformIndex(std::uint64_t n) {
    return static_cast<std::uint64_t>((static_cast<unsigned __int128>(NextU64()) * n) >> 64);
  }
  /// Standard normal N(0, 1) (Box–Muller; the second value of each pair is kept for the next call).
  double Normal();

  /// Derives an independent child stream, e.g. one per seed or per worker thread.
  Rng Split() { return Rng(NextU64() ^ 0x9e3779b97f4a7c15ULL); }

 private:
  static std::uint64_t Rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

  std::uint64_t s_[4];
  double spare_normal_ = 0.0;
  bool has_spare_ = false;
};

/// Fisher–Yates shuffle of a random-access range with our generator (std::shuffle's use of the
/// generator is implementation-defined).
template <typename RandomIt>
void Shuffle(RandomIt first, RandomIt last, Rng& rng) {
  const auto n = last - first;
  for (auto i = n - 1; i > 0; --i) {
    const auto j = static_cast<decltype(i)>(rng.UniformIndex(static_cast<std::uint64_t>(i) + 1));
    using std::swap;
    swap(first[i], first[j]);
  }
}

}  // namespace secure
