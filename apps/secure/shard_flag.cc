// The shard a process runs (shard_flag.h).
#include "shard_flag.h"

#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/limits.h"

namespace secure::cli {
namespace {

// A non-negative integer at most `max`, all digits; else an error naming `what` and the text.
bool ParseCount(const std::string& text, long max, long* value) {
  if (text.empty() || text.size() > 9) return false;
  for (char c : text)
    if (c < '0' || c > '9') return false;
  *value = std::stol(text);
  return *value <= max;
}

std::optional<std::string> Env(const char* name) {
  const char* v = std::getenv(name);
  if (v == nullptr) return std::nullopt;
  return std::string(v);
}

long EnvCount(const char* name, const std::string& value) {
  long n = 0;
  SECURE_CHECK(ParseCount(value, kMaxSeeds * 1000L, &n), "environment variable "
                                                             << name << " = '" << value
                                                             << "' is not a non-negative integer");
  return n;
}

// A rank/size pair from the environment (rank_var and one of size_vars), if rank_var is set.
std::optional<Shard> RankFromEnv(const char* rank_var, std::vector<const char*> size_vars,
                                 const char* label) {
  const std::optional<std::string> rank = Env(rank_var);
  if (!rank) return std::nullopt;
  for (const char* size_var : size_vars) {
    const std::optional<std::string> size = Env(size_var);
    if (!size) continue;
    const long r = EnvCount(rank_var, *rank), n = EnvCount(size_var, *size);
    SECURE_CHECK(n >= 1,
                 "environment variable " << size_var << " = '" << *size << "' must be >= 1");
    SECURE_CHECK(r < n, "environment variable " << rank_var << " = '" << *rank << "' must be below "
                                                << size_var << " = " << n);
    return Shard{static_cast<int>(r), static_cast<int>(n), label};
  }
  return std::nullopt;
}

}  // namespace

// --shard k/N, else a SLURM array element (SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN of
// SLURM_ARRAY_TASK_COUNT), else an MPI rank (Open MPI's OMPI_COMM_WORLD_RANK/SIZE, the PMI
// PMI_RANK/SIZE, PMIx's PMIX_RANK with PMI_SIZE or OMPI_COMM_WORLD_SIZE); else not sharded.
Shard ResolveShard(const std::string& flag) {
  if (!flag.empty()) {
    const std::size_t slash = flag.find('/');
    long k = -1, n = 0;
    const bool ok = slash != std::string::npos && ParseCount(flag.substr(0, slash), 1L << 30, &k) &&
                    ParseCount(flag.substr(slash + 1), 1L << 30, &n) && n >= 1 && k < n;
    SECURE_CHECK(ok, "--shard '" << flag
                                 << "': expected k/N with 0 <= k < N (0-based shard k of N, "
                                    "e.g. 0/4)");
    return {static_cast<int>(k), static_cast<int>(n), "--shard"};
  }
  std::optional<Shard> slurm;
  if (const std::optional<std::string> id = Env("SLURM_ARRAY_TASK_ID")) {
    const std::optional<std::string> count = Env("SLURM_ARRAY_TASK_COUNT");
    SECURE_CHECK(count.has_value(), "environment variable SLURM_ARRAY_TASK_ID = '"
                                        << *id << "' is set but SLURM_ARRAY_TASK_COUNT is not");
    long k = EnvCount("SLURM_ARRAY_TASK_ID", *id);
    const long n = EnvCount("SLURM_ARRAY_TASK_COUNT", *count);
    SECURE_CHECK(n >= 1,
                 "environment variable SLURM_ARRAY_TASK_COUNT = '" << *count << "' must be >= 1");
    std::string source = "SLURM_ARRAY_TASK_ID/COUNT";
    if (const std::optional<std::string> min = Env("SLURM_ARRAY_TASK_MIN")) {
      const long m = EnvCount("SLURM_ARRAY_TASK_MIN", *min);
      SECURE_CHECK(m <= k, "environment variable SLURM_ARRAY_TASK_MIN = '"
                               << *min << "' is above SLURM_ARRAY_TASK_ID = " << k);
      k -= m;
      source = "SLURM_ARRAY_TASK_ID-MIN/COUNT";
    }
    SECURE_CHECK(k < n, "environment variable SLURM_ARRAY_TASK_ID = '"
                            << *id << "' gives shard " << k
                            << ", not below SLURM_ARRAY_TASK_COUNT = " << n
                            << " (use a contiguous array, --array=0-" << n - 1 << ")");
    slurm = Shard{static_cast<int>(k), static_cast<int>(n), source};
  }
  std::optional<Shard> mpi =
      RankFromEnv("OMPI_COMM_WORLD_RANK", {"OMPI_COMM_WORLD_SIZE"}, "OMPI_COMM_WORLD_RANK/SIZE");
  if (!mpi) mpi = RankFromEnv("PMI_RANK", {"PMI_SIZE"}, "PMI_RANK/SIZE");
  if (!mpi) mpi = RankFromEnv("PMIX_RANK", {"PMI_SIZE", "OMPI_COMM_WORLD_SIZE"}, "PMIX_RANK/SIZE");
  if (slurm && mpi && slurm->count > 1 && mpi->count > 1) {
    SECURE_THROW("both " << slurm->source << " (shard " << slurm->index << "/" << slurm->count
                         << ") and " << mpi->source << " (" << mpi->index << "/" << mpi->count
                         << ") are set: give --shard k/N");
  }
  if (slurm && (slurm->count > 1 || !mpi)) return *slurm;
  if (mpi) return *mpi;
  return {};
}

}  // namespace secure::cli
