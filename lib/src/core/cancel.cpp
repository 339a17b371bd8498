#include "tprf/core/cancel.h"

#include <csignal>
#include <string>

namespace tprf {

namespace {

constexpr int kAsked = -1;  // a request without a signal

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

void request_cancel(int signal) noexcept {
    detail::cancel_request.store(signal > 0 ? signal : kAsked, std::memory_order_relaxed);
}

void clear_cancel() noexcept { detail::cancel_request.store(0, std::memory_order_relaxed); }

void detail::throw_cancelled(int request) { throw Cancelled(request > 0 ? request : 0); }

}  // namespace tprf
