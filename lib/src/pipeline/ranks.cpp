#include "tprf/pipeline/ranks.h"

#include "ranks_mpi.h"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cstring>

namespace tprf {
namespace {

// The rank count an MPI launcher put in the environment: Open MPI's mpirun sets OMPI_COMM_WORLD_SIZE,
// MPICH's hydra and Slurm's PMI-1/PMI-2 set PMI_SIZE; a PMIx launcher (srun --mpi=pmix) sets PMIX_RANK
// and no count (then -1). 0: not started by a launcher.
int launched_ranks() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"}) {
        const char* text = std::getenv(name);
        if (text == nullptr || *text == '\0') continue;
        int n = 0;
        const char* end = text + std::strlen(text);
        const auto [last, ec] = std::from_chars(text, end, n);
        if (ec == std::errc() && last == end && n > 0) return n;
    }
    return std::getenv("PMIX_RANK") != nullptr ? -1 : 0;
}

}  // namespace

void SingleRank::gather_bytes(std::span<const std::byte> mine, std::span<const std::size_t> sizes,
                              std::span<std::byte> all) const {
    TPRF_CHECK_EQ(sizes.size(), std::size_t{1});
    TPRF_CHECK_EQ(all.size(), mine.size());
    std::copy(mine.begin(), mine.end(), all.begin());
}

void SingleRank::abort_all(const std::string& message, int) const {
    throw InternalError("a single rank was asked to abort the group: " + message);
}

bool built_with_mpi() {
#ifdef TPRF_WITH_MPI
    return true;
#else
    return false;
#endif
}

std::unique_ptr<RankGroup> join_ranks() {
    const int launched = launched_ranks();
    if (launched == 0) return std::make_unique<SingleRank>();
#ifdef TPRF_WITH_MPI
    return join_mpi_ranks();
#else
    if (launched > 1)
        throw Error("started by an MPI launcher as one of " + std::to_string(launched) +
                    " ranks, but this tprf was built without MPI (each rank would render the whole scene): run "
                    "it without mpirun, or rebuild it with MPI (Debian: libopenmpi-dev; docs/mpi.md)");
    return std::make_unique<SingleRank>();
#endif
}

}  // namespace tprf
