#include "tprf/core/parallel.h"

#include <omp.h>

namespace tprf {

int thread_count(int requested) { return requested > 0 ? requested : omp_get_max_threads(); }

void start_threads() {
    // An empty region: the runtime keeps its threads in a pool for the regions that follow.
#pragma omp parallel
    {
    }
}

void ExceptionSlot::capture() noexcept {
    std::lock_guard<std::mutex> lock(m_mutex);
    if (!m_error) m_error = std::current_exception();
    m_failed.store(true, std::memory_order_relaxed);
}

void ExceptionSlot::rethrow() {
    if (m_error) std::rethrow_exception(m_error);
}

void parallel_for(std::size_t n, const LoopSchedule& schedule, IndexFn body) {
    ExceptionSlot errors;
    const int threads = thread_count(schedule.threads);
    const int chunk = schedule.chunk > 0 ? schedule.chunk : 1;
    if (schedule.dynamic) {
#pragma omp parallel for schedule(dynamic, chunk) num_threads(threads)
        for (std::size_t i = 0; i < n; ++i) errors.run([&] { body(i); });
    } else {
#pragma omp parallel for schedule(static) num_threads(threads)
        for (std::size_t i = 0; i < n; ++i) errors.run([&] { body(i); });
    }
    errors.rethrow();
}

}  // namespace tprf
