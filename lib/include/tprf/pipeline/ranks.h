#pragma once
/// The processes that share one render (docs/mpi.md): MPI's ranks when an MPI launcher (`mpirun`,
/// `srun`) started tprf and it was built with MPI, else this process alone. A capture splits its laser
/// points between the ranks by whole batches (pipeline/capture.h); rank 0 writes every output.
///
/// MPI itself stays behind this interface: no public header includes mpi.h, and the stages before
/// pipeline/ know nothing of ranks.

#include "tprf/core/error.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <numeric>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace tprf {

/// The collective operations a split render needs. Every rank calls each of them in the same order.
class RankGroup {
public:
    virtual ~RankGroup() = default;

    /// This process's rank, 0 .. size() - 1. Rank 0 writes the outputs.
    virtual int rank() const = 0;
    /// The number of ranks.
    virtual int size() const = 0;
    /// Rank 0's `value`, on every rank.
    virtual std::int64_t broadcast(std::int64_t value) const = 0;
    /// The lowest rank whose `failed` is true, or size() when no rank's is: every rank learns whether
    /// all may go on.
    virtual int first_failure(bool failed) const = 0;
    /// On rank 0: every rank's `bytes`, in rank order; elsewhere: empty.
    virtual std::vector<std::size_t> gather_sizes(std::size_t bytes) const = 0;
    /// Copies every rank's `mine` into rank 0's `all`, one after another in rank order (`sizes`: what
    /// gather_sizes returned there; `all` holds their sum). Other ranks pass empty `sizes` and `all`.
    virtual void gather_bytes(std::span<const std::byte> mine, std::span<const std::size_t> sizes,
                              std::span<std::byte> all) const = 0;
    /// Rank 0's `data` into every rank's: every rank passes a span of the same size.
    virtual void broadcast_bytes(std::span<std::byte> data) const = 0;
    /// Ends every rank: prints "tprf: error: MESSAGE" on this one and makes the launcher stop the others,
    /// with exit status `status`. For a failure on one rank while the others may wait for it in a
    /// collective; with one rank it throws InternalError instead (nothing waits: the caller rethrows).
    [[noreturn]] void abort(const std::string& message, int status) const {
        abort_all(message, status);
        std::_Exit(status);  // abort_all does not return; should a launcher let it, this rank still ends
    }

    /// Every rank's values, concatenated in rank order, on rank 0 (empty elsewhere): the same bytes
    /// whatever the timing.
    template <class T>
    std::vector<T> gather(std::span<const T> mine) const {
        static_assert(std::is_trivially_copyable_v<T>);
        std::vector<std::size_t> sizes = gather_sizes(mine.size_bytes());
        const std::size_t total = std::accumulate(sizes.begin(), sizes.end(), std::size_t{0});
        TPRF_CHECK_EQ(total % sizeof(T), std::size_t{0});
        std::vector<T> all(total / sizeof(T));
        gather_bytes(std::as_bytes(mine), sizes, std::as_writable_bytes(std::span<T>(all)));
        return all;
    }

    /// Every rank's values, concatenated in rank order, on every rank (gather, then broadcast).
    template <class T>
    std::vector<T> all_gather(std::span<const T> mine) const {
        std::vector<T> all = gather(mine);
        all.resize(std::size_t(broadcast(std::int64_t(all.size()))));
        broadcast_bytes(std::as_writable_bytes(std::span<T>(all)));
        return all;
    }

protected:
    /// abort()'s work: prints and stops every rank (or throws).
    virtual void abort_all(const std::string& message, int status) const = 0;
};

/// This process alone: rank 0 of 1.
class SingleRank final : public RankGroup {
public:
    int rank() const override { return 0; }
    int size() const override { return 1; }
    std::int64_t broadcast(std::int64_t value) const override { return value; }
    int first_failure(bool failed) const override { return failed ? 0 : 1; }
    std::vector<std::size_t> gather_sizes(std::size_t bytes) const override { return {bytes}; }
    void gather_bytes(std::span<const std::byte> mine, std::span<const std::size_t> sizes,
                      std::span<std::byte> all) const override;
    void broadcast_bytes(std::span<std::byte>) const override {}

protected:
    void abort_all(const std::string& message, int status) const override;
};

/// Thrown on a rank that stops because another rank failed before the shared work began (that rank
/// printed why): the command exits with status 2 and prints nothing more.
class RankStopped : public Error {
public:
    using Error::Error;
};

/// The ranks this process was started with: MPI's world when an MPI launcher started it (its
/// environment holds OMPI_COMM_WORLD_SIZE, PMI_SIZE or PMIX_RANK) and tprf was built with MPI; this
/// process alone otherwise, and then MPI is never initialised (a plain run starts as fast as ever).
/// Destroying the group finalises MPI. Throws Error when a launcher started several ranks of a tprf
/// built without MPI (each would render the whole scene into the same folder).
std::unique_ptr<RankGroup> join_ranks();

/// Whether this tprf was built with MPI (CMake's TPRF_MPI found it).
bool built_with_mpi();

}  // namespace tprf
