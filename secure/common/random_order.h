#pragma once
// Random orders and subsets of 0, 1, ..., n - 1 with our generator (Shuffle of rng.h): the
// draws the data generators and the validation splits share. Defined in rng.cc.
#include <vector>

#include "secure/common/rng.h"

namespace secure {

/// 0, 1, ..., n - 1 in a uniformly random order (Shuffle of the identity). n >= 0.
std::vector<long> RandomPermutation(long n, Rng& rng);

/// `k` of 0, 1, ..., n - 1 drawn uniformly without replacement (the first k of
/// RandomPermutation(n)), in increasing order. 0 <= k <= n.
std::vector<long> SortedRandomSubset(long n, long k, Rng& rng);

}  // namespace secure
