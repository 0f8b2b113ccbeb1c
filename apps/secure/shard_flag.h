#pragma once
// The shard a process runs (docs/CLUSTER.md): --shard k/N, else a SLURM array element's or an
// mpirun rank's place. Used by `secure experiment` (experiment_commands.cc) and `secure
// reproduce` (reproduce_command.cc).
#include <string>

namespace secure::cli {

/// Which shard this process runs, and where that came from ("--shard",
/// "SLURM_ARRAY_TASK_ID/COUNT", "OMPI_COMM_WORLD_RANK/SIZE", ...).
struct Shard {
  int index = 0;
  int count = 1;
  std::string source;  // empty: not sharded
};

/// --shard k/N (`flag`, if not empty), else a SLURM array element (SLURM_ARRAY_TASK_ID -
/// SLURM_ARRAY_TASK_MIN of SLURM_ARRAY_TASK_COUNT), else an MPI rank (Open MPI's
/// OMPI_COMM_WORLD_RANK/SIZE, the PMI PMI_RANK/SIZE, PMIx's PMIX_RANK with PMI_SIZE or
/// OMPI_COMM_WORLD_SIZE); else not sharded. @throws secure::Error naming the flag or variable
/// and its value.
Shard ResolveShard(const std::string& flag);

}  // namespace secure::cli
