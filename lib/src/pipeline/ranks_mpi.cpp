// The ranks of MPI_COMM_WORLD as a RankGroup (pipeline/ranks.h). The only file that includes mpi.h.
#include "ranks_mpi.h"

#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

namespace tprf {
namespace {

// MPI counts are ints: large transfers go in pieces of 1 GiB.
constexpr std::size_t kPiece = std::size_t(1) << 30;
constexpr int kGatherTag = 7301;

void check_mpi(int code, const char* call) {
    if (code == MPI_SUCCESS) return;
    char text[MPI_MAX_ERROR_STRING] = "";
    int length = 0;
    MPI_Error_string(code, text, &length);
    throw InternalError(std::string(call) + " failed: " + std::string(text, std::size_t(std::max(0, length))));
}

// Waits for a nonblocking operation without holding a core: Open MPI's blocking calls poll without
// pause, which on a machine that ranks share would take a core from the rank everyone waits for (rank
// 0 rendering the camera, a rank with one batch more). Pauses grow to 5 ms: a few milliseconds of
// latency on the handful of waits of a render.
int wait_politely(MPI_Request& request) {
    auto pause = std::chrono::microseconds(50);
    for (;;) {
        int done = 0;
        if (const int code = MPI_Test(&request, &done, MPI_STATUS_IGNORE); code != MPI_SUCCESS || done) return code;
        std::this_thread::sleep_for(pause);
        pause = std::min(2 * pause, std::chrono::microseconds(5000));
    }
}

// Every rank has arrived (waiting politely).
int barrier() {
    MPI_Request request;
    const int code = MPI_Ibarrier(MPI_COMM_WORLD, &request);
    return code == MPI_SUCCESS ? wait_politely(request) : code;
}

class MpiRanks final : public RankGroup {
public:
    MpiRanks() {
        int provided = 0;
        check_mpi(MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
        // Errors come back as codes (check_mpi turns them into InternalError) rather than ending the job.
        MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
        MPI_Comm_rank(MPI_COMM_WORLD, &m_rank);
        MPI_Comm_size(MPI_COMM_WORLD, &m_size);
    }
    // The barrier first: a rank done early waits there politely rather than in MPI_Finalize's polling.
    ~MpiRanks() override {
        barrier();
        MPI_Finalize();
    }
    MpiRanks(const MpiRanks&) = delete;
    MpiRanks& operator=(const MpiRanks&) = delete;

    int rank() const override { return m_rank; }
    int size() const override { return m_size; }

    std::int64_t broadcast(std::int64_t value) const override {
        MPI_Request request;
        check_mpi(MPI_Ibcast(&value, 1, MPI_INT64_T, 0, MPI_COMM_WORLD, &request), "MPI_Ibcast");
        check_mpi(wait_politely(request), "MPI_Ibcast");
        return value;
    }

    int first_failure(bool failed) const override {
        int mine = failed ? m_rank : m_size, first = m_size;
        MPI_Request request;
        check_mpi(MPI_Iallreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD, &request), "MPI_Iallreduce");
        check_mpi(wait_politely(request), "MPI_Iallreduce");
        return first;
    }

    // After a barrier: every rank is done with its share, so the transfers that follow wait for nothing
    // but the wire.
    std::vector<std::size_t> gather_sizes(std::size_t bytes) const override {
        check_mpi(barrier(), "MPI_Ibarrier");
        const std::uint64_t mine = bytes;
        std::vector<std::uint64_t> all(m_rank == 0 ? std::size_t(m_size) : 0);
        check_mpi(MPI_Gather(&mine, 1, MPI_UINT64_T, all.data(), 1, MPI_UINT64_T, 0, MPI_COMM_WORLD), "MPI_Gather");
        return {all.begin(), all.end()};
    }

    // Rank 0 receives from rank 1, then rank 2, ...: each rank's bytes land at their place in rank order.
    void gather_bytes(std::span<const std::byte> mine, std::span<const std::size_t> sizes,
                      std::span<std::byte> all) const override {
        if (m_rank != 0) {
            for (std::size_t at = 0; at < mine.size(); at += kPiece)
                check_mpi(MPI_Send(mine.data() + at, int(std::min(kPiece, mine.size() - at)), MPI_BYTE, 0, kGatherTag,
                                   MPI_COMM_WORLD),
                          "MPI_Send");
            return;
        }
        TPRF_CHECK_EQ(sizes.size(), std::size_t(m_size));
        TPRF_CHECK_EQ(sizes[0], mine.size());
        std::copy(mine.begin(), mine.end(), all.begin());
        std::size_t offset = mine.size();
        for (int r = 1; r < m_size; ++r) {
            TPRF_CHECK_LE(offset + sizes[std::size_t(r)], all.size());
            for (std::size_t at = 0; at < sizes[std::size_t(r)]; at += kPiece)
                check_mpi(MPI_Recv(all.data() + offset + at, int(std::min(kPiece, sizes[std::size_t(r)] - at)), MPI_BYTE,
                                   r, kGatherTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
                          "MPI_Recv");
            offset += sizes[std::size_t(r)];
        }
        TPRF_CHECK_EQ(offset, all.size());
    }

    // In pieces of at most 1 GiB, each waited for politely.
    void broadcast_bytes(std::span<std::byte> data) const override {
        for (std::size_t at = 0; at < data.size(); at += kPiece) {
            MPI_Request request;
            check_mpi(MPI_Ibcast(data.data() + at, int(std::min(kPiece, data.size() - at)), MPI_BYTE, 0, MPI_COMM_WORLD,
                                 &request),
                      "MPI_Ibcast");
            check_mpi(wait_politely(request), "MPI_Ibcast");
        }
    }

private:
    void abort_all(const std::string& message, int status) const override {
        std::fprintf(stderr, "tprf: error: %s\n", message.c_str());
        std::fflush(stderr);
        MPI_Abort(MPI_COMM_WORLD, status);
    }

    int m_rank = 0, m_size = 1;
};

}  // namespace

std::unique_ptr<RankGroup> join_mpi_ranks() { return std::make_unique<MpiRanks>(); }

}  // namespace tprf
