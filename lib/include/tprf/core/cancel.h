#pragma once
/// Cancelling a run. A signal handler (or another thread, or the Python module) asks; every stage
/// checks at points a small fraction of a second apart and unwinds by throwing Cancelled, so that the
/// run's staging files are removed by their destructors on the way out and earlier outputs are left
/// as they were (docs/reliability.md).
///
/// The request is one process-wide flag: a signal stops every run of the process.

#include <atomic>
#include <stdexcept>

namespace tprf {

/// Thrown once a run was asked to stop. Not an Error: nothing was wrong with the input.
class Cancelled : public std::runtime_error {
public:
    /// `signal`: the signal that asked (SIGINT, SIGTERM, ...), or 0 when a caller asked.
    explicit Cancelled(int signal);
    [[nodiscard]] int signal() const noexcept { return m_signal; }

private:
    int m_signal;
};

namespace detail {
/// 0: no request; a signal number; or -1 for a request without a signal.
inline std::atomic<int> cancel_request{0};
static_assert(std::atomic<int>::is_always_lock_free, "request_cancel must be async-signal-safe");
[[noreturn]] void throw_cancelled(int request);
}  // namespace detail

/// Asks every running stage to stop. Async-signal-safe (one lock-free atomic store): call it from a
/// signal handler. `signal` is reported by Cancelled::signal().
void request_cancel(int signal = 0) noexcept;

/// Withdraws the request, so that a later run of the same process can go on (tests, the Python
/// module between renders). Not for signal handlers' processes: a signal that arrives before a run
/// starts must stop it.
void clear_cancel() noexcept;

/// True once a stop was asked. One relaxed atomic load, inline: cheap enough for every loop iteration.
[[nodiscard]] inline bool cancel_requested() noexcept {
    return detail::cancel_request.load(std::memory_order_relaxed) != 0;
}

/// Throws Cancelled when a stop was asked.
inline void check_cancelled() {
    if (const int r = detail::cancel_request.load(std::memory_order_relaxed); r != 0) detail::throw_cancelled(r);
}

}  // namespace tprf
