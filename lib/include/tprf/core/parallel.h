#pragma once
/// Exception-safe parallel loops. An exception that leaves an OpenMP region (or an Embree callback)
/// calls std::terminate; here every worker's exception is caught, the remaining iterations are
/// skipped, and the first exception is rethrown on the calling thread once all workers have stopped,
/// so that a bad mesh, an allocation failure or a cancelled run (checked before every iteration)
/// reaches the caller as an exception.
///
/// OpenMP stays inside the library's sources: nothing in this header needs it.

#include "tprf/core/cancel.h"

#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <type_traits>
#include <utility>

namespace tprf {

/// The number of worker threads for a stage: `requested` when positive, else all cores.
int thread_count(int requested);

/// Starts the worker threads of every later parallel region now, while the process's address space
/// is still free: the OpenMP runtime keeps them, and one that cannot create a thread later (its stack
/// refused under `ulimit -v` once the buffers are allocated) ends the process with its own message
/// instead of an error the program could report and clean up after. Call once, first thing.
void start_threads();

/// Holds the first exception thrown by any worker of a parallel region.
class ExceptionSlot {
public:
    /// Runs f() unless a worker has already failed or the run was cancelled (core/cancel.h: then
    /// Cancelled is kept); an exception from f() is kept, not propagated.
    template <class F>
    void run(F&& f) noexcept {
        if (failed()) return;
        try {
            check_cancelled();
            std::forward<F>(f)();
        } catch (...) {
            capture();
        }
    }
    /// True once some worker has thrown: the others skip their remaining work.
    [[nodiscard]] bool failed() const noexcept { return m_failed.load(std::memory_order_relaxed); }
    /// Rethrows the kept exception, if any. Call on the calling thread after the region.
    void rethrow();

private:
    void capture() noexcept;

    std::mutex m_mutex;
    std::exception_ptr m_error;
    std::atomic<bool> m_failed{false};
};

/// A non-owning reference to a callable `void(std::size_t)`: the loop body, without the allocation
/// of a std::function.
class IndexFn {
public:
    template <class F, class = std::enable_if_t<!std::is_same_v<std::decay_t<F>, IndexFn>>>
    IndexFn(F&& f) noexcept  // NOLINT: implicit on purpose, so that a lambda passes directly
        : m_object(const_cast<void*>(static_cast<const void*>(&f))),
          m_call([](void* o, std::size_t i) { (*static_cast<std::remove_reference_t<F>*>(o))(i); }) {}
    void operator()(std::size_t i) const { m_call(m_object, i); }

private:
    void* m_object;
    void (*m_call)(void*, std::size_t);
};

/// How parallel_for hands out iterations.
struct LoopSchedule {
    int threads = 0;        ///< 0: all cores
    int chunk = 1;          ///< iterations handed out at a time
    bool dynamic = true;    ///< dynamic (work-stealing) or static schedule
};

/// Runs body(i) for every i in [0, n) on schedule.threads threads. The first exception a body throws
/// is rethrown here after every thread has stopped; iterations not yet started are then skipped.
void parallel_for(std::size_t n, const LoopSchedule& schedule, IndexFn body);

}  // namespace tprf
