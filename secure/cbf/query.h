#pragma once
// Active label queries (issue 35; the paper's future work, Section 8): which k states of a pool of
// unlabelled candidates a person should label next, given the current barrier (or an ensemble of
// barriers). The caller labels them (a person, or a domain's labeller capability) and retrains
// with them (`secure cbf train --augment-from`).
//
// Strategies (QueryStrategy), each scoring every pool state, higher = ask first:
//   margin          -|h(s)|: the states the barrier is least sure about;
//   disagreement    the spread (population standard deviation) of h(s) over K barriers (seeds or
//                   bootstraps): where the ensemble disagrees;
//   shield-relevant -|h(s)| over a pool of states the closed-loop shield visited (the caller
//                   gathers the pool from shielded rollouts: `secure cbf query --domain`, the
//                   label-efficiency experiment); on any pool it is margin;
//   diversity       greedy k-centre (farthest-first) over the pool's features normalised by their
//                   standard deviation over the pool, from a seeded first state;
//   random          k distinct states drawn uniformly (seeded): the baseline.
// A diversity radius (> 0) makes any strategy a batch selection: states are taken in score order
// and a state closer than the radius (Euclidean, normalised features) to one already taken is
// skipped; so no two chosen states are closer than the radius, and a pool with fewer such states
// gives fewer than k (QueryResult::indices.size() says how many).
// Ties in a score go to the lower pool index; every strategy is deterministic for its seed.
//
// Cost: one batched barrier forward per barrier over the pool (in chunks of `chunk` states),
// then O(N) selection (nth_element), or O(N k d) for diversity and for a radius.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/data/data.h"

namespace secure::cbf {

enum class QueryStrategy { kMargin, kDisagreement, kShieldRelevant, kDiversity, kRandom };
inline constexpr EnumTable<QueryStrategy, 5> kQueryStrategyNames{{
    {QueryStrategy::kMargin, "margin"},
    {QueryStrategy::kDisagreement, "disagreement"},
    {QueryStrategy::kShieldRelevant, "shield-relevant"},
    {QueryStrategy::kDiversity, "diversity"},
    {QueryStrategy::kRandom, "random"},
}};

struct QueryOptions {
  QueryStrategy strategy = QueryStrategy::kMargin;
  long k = 50;                   // states to propose, in [1, pool size]
  std::uint64_t seed = 0;        // random, and diversity's first state
  double diversity_radius = 0;   // >= 0; > 0: no two chosen states closer (normalised features)
  /// @throws secure::Error naming the field and value ("QueryOptions::k = 0, must be >= 1").
  void Validate() const;
};

struct QueryResult {
  std::vector<long> indices;  // distinct pool columns, best first
  Eigen::VectorXf score;      // the strategy's score of each chosen state (same order)
  Eigen::VectorXf h;          // h of each chosen state (ensemble: the mean); NaN without barrier
  Eigen::VectorXf spread;     // ensemble spread of each chosen state (0 with one barrier)
};

/// h of every pool column under each barrier: (barriers x N), evaluated in chunks of `chunk`.
/// 1024 by default: a wide net's activations then stay in cache (Panda net, 100,000 states: 4.3 µs
/// per state at 1024 against 5.0 at 4096; docs/PERFORMANCE.md).
/// @throws secure::Error if a barrier's state_dim differs from pool.rows().
Eigen::MatrixXf EvaluatePool(const std::vector<Barrier*>& barriers,
                             const Eigen::Ref<const Eigen::MatrixXf>& pool, long chunk = 1024);

/// Proposes options.k states of `pool` (d x N, one state per column) by options.strategy.
/// `barriers`: one barrier (margin, shield-relevant), K >= 2 (disagreement), or none (diversity,
/// random; a barrier given there only fills QueryResult::h). Uses the barriers' evaluators (not
/// thread-safe; one call per thread).
/// @throws secure::Error on invalid options, k > pool size, an empty pool, a non-finite pool
///   value, or a wrong number of barriers for the strategy (naming the strategy).
QueryResult SelectQueries(const std::vector<Barrier*>& barriers,
                          const Eigen::Ref<const Eigen::MatrixXf>& pool,
                          const QueryOptions& options);

/// The same from precomputed h values (barriers x N, as EvaluatePool), for callers that reuse
/// them.
QueryResult SelectQueriesFromValues(const Eigen::Ref<const Eigen::MatrixXf>& h_values,
                                    const Eigen::Ref<const Eigen::MatrixXf>& pool,
                                    const QueryOptions& options);

/// The per-feature scale diversity measures distances in: the standard deviation of each pool row
/// (1 where a row is constant).
Eigen::VectorXf PoolScale(const Eigen::Ref<const Eigen::MatrixXf>& pool);

/// The column of a labelled query file (`secure cbf query` output after labelling; `secure cbf
/// label`): 1 safe, 0 near-dangerous, -1 not labelled (the row is skipped).
inline constexpr const char* kLabelColumn = "label";

/// States of a labelled query file, by label.
struct LabelledStates {
  data::StateSet safe, near_dangerous;
  long skipped = 0;  // rows labelled -1
};

/// Whether the CSV at `path` has a `label` column (its header names one). HDF5: false.
bool HasLabelColumn(const std::string& path);

/// Reads a labelled CSV: the `features` columns (by name) and `label`, each row into safe (1) or
/// near_dangerous (0), skipping -1. @throws secure::Error naming the file, line and value for any
/// other label, and as data::ReadCsv.
LabelledStates ReadLabelledStates(const std::string& path,
                                  const std::vector<std::string>& features);

}  // namespace secure::cbf
