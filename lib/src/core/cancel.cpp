#include "tprf/core/cancel.h"

#include <atomic>
#include <csignal>
#include <string>

namespace tprf {

namespace {

// 0: no request; a signal number; or kAsked for a request without a signal.
constexpr int kAsked = -1;
std::atomic<int> g_request{0};
static_assert(std::atomic<int>::is_always_lock_free, "request_cancel must be async-signal-safe");

std::string describe(int signal) {
    switch (signal) {
        case 0: return "cancelled";
        case SIGINT: return "cancelled by SIGINT";
        case SIGTERM: return "cancelled by SIGTERM";
        case SIGHUP: return "cancelled by SIGHUP";
        default: return "cancelled by signal " + std::to_string(signal);
    }
}

}  // namespace

Cancelled::Cancelled(int signal) : std::runtime_error(describe(signal)), m_signal(signal) {}

void request_cancel(int signal) noexcept { g_request.store(signal > 0 ? signal : kAsked, std::memory_order_relaxed); }

void clear_cancel() noexcept { g_request.store(0, std::memory_order_relaxed); }

bool cancel_requested() noexcept { return g_request.load(std::memory_order_relaxed) != 0; }

void check_cancelled() {
    const int r = g_request.load(std::memory_order_relaxed);
    if (r != 0) throw Cancelled(r > 0 ? r : 0);
}

}  // namespace tprf
