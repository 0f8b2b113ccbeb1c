#include "secure/common/rng.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "secure/common/random_order.h"

namespace secure {

void Rng::Seed(std::uint64_t seed) {
  // splitmix64 expands the seed into a well-mixed, never all-zero state.
  std::uint64_t z = seed;
  for (auto& word : s_) {
    z += 0x9e3779b97f4a7c15ULL;
    std::uint64_t x = z;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    word = x ^ (x >> 31);
  }
  has_spare_ = false;
  spare_normal_ = 0.0;
}

double Rng::Normal() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_normal_;
  }
  // 1 - Uniform() is in (0, 1], so the log is finite.
  const double u1 = 1.0 - Uniform();
  const double u2 = Uniform();
  const double radius = std::sqrt(-2.0 * std::log(u1));
  const double angle = 2.0 * M_PI * u2;
  spare_normal_ = radius * std::sin(angle);
  has_spare_ = true;
  return radius * std::cos(angle);
}

std::vector<long> RandomPermutation(long n, Rng& rng) {
  std::vector<long> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0L);
  Shuffle(order.begin(), order.end(), rng);
  return order;
}

std::vector<long> SortedRandomSubset(long n, long k, Rng& rng) {
  std::vector<long> order = RandomPermutation(n, rng);
  order.resize(static_cast<std::size_t>(k));
  std::sort(order.begin(), order.end());
  return order;
}

}  // namespace secure
