#pragma once
// Private to the pipeline: the MPI implementation of RankGroup (ranks_mpi.cpp, built only with MPI).

#include "tprf/pipeline/ranks.h"

#include <memory>

namespace tprf {

/// Initialises MPI (threads: funnelled, only the calling thread talks to MPI) and returns its world;
/// the group's destructor finalises MPI. Defined only when tprf is built with MPI.
std::unique_ptr<RankGroup> join_mpi_ranks();

}  // namespace tprf
