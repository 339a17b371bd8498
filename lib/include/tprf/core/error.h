#pragma once
/// Errors and invariant checks.
///
/// tprf::Error is bad input (a scene, a flag, a file): the app prints its message on one line and exits
/// with status 2. tprf::OutputError is a system that failed to take an output (a full disk): exit
/// status 1. tprf::InternalError is a broken invariant: exit status 1. A cancelled run throws
/// tprf::Cancelled (core/cancel.h). The library never exits.

#include <exception>
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tprf {

/// Bad input: the message names the file, the JSON path (where there is one) and what is wrong.
class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// An output that could not be written through no fault of the input: a full disk, a file-size limit,
/// an I/O error, a directory removed under the run. The message names the file and the system's reason.
class OutputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// A broken internal invariant (a bug in tprf, not in the user's input).
class InternalError : public std::logic_error {
public:
    using std::logic_error::logic_error;
};

/// Throws Error with the message "FILE: PATH: WHAT" (PATH left out when empty).
[[noreturn]] void fail_input(const std::filesystem::path& file, std::string_view json_path,
                             std::string_view what);

/// The command's exit status for a failure: 2 for bad input (Error), 128 + the signal for a cancelled
/// run (Cancelled, core/cancel.h; 130 when no signal asked), 1 for anything else (OutputError, out of
/// memory, a bug). The command line and a split render's abort of every rank both use it.
int exit_status(const std::exception_ptr& failure) noexcept;

/// Throws OutputError with the message "FILE: WHAT: the system's reason for errno `err`".
[[noreturn]] void fail_output(const std::filesystem::path& file, std::string_view what, int err);

namespace detail {
template <class A, class B>
[[noreturn]] void check_failed(const char* expr, const A& a, const B& b, const char* where, int line) {
    std::ostringstream os;
    os << "internal check failed at " << where << ":" << line << ": " << expr << " (" << a << " vs " << b
       << ")";
    throw InternalError(os.str());
}
}  // namespace detail

}  // namespace tprf

/// Invariant checks that print both operands. The TPRF_DCHECK_ variants vanish in release builds.
#define TPRF_CHECK_OP(a, b, op)                                                                   \
    do {                                                                                          \
        const auto& tprf_a_ = (a);                                                                \
        const auto& tprf_b_ = (b);                                                                \
        if (!(tprf_a_ op tprf_b_))                                                                \
            ::tprf::detail::check_failed(#a " " #op " " #b, tprf_a_, tprf_b_, __FILE__, __LINE__); \
    } while (0)
#define TPRF_CHECK_EQ(a, b) TPRF_CHECK_OP(a, b, ==)
#define TPRF_CHECK_LT(a, b) TPRF_CHECK_OP(a, b, <)
#define TPRF_CHECK_LE(a, b) TPRF_CHECK_OP(a, b, <=)
#define TPRF_CHECK(cond) TPRF_CHECK_OP(static_cast<bool>(cond), true, ==)
#ifdef NDEBUG
#define TPRF_DCHECK_EQ(a, b) ((void)0)
#define TPRF_DCHECK_LT(a, b) ((void)0)
#else
#define TPRF_DCHECK_EQ(a, b) TPRF_CHECK_EQ(a, b)
#define TPRF_DCHECK_LT(a, b) TPRF_CHECK_LT(a, b)
#endif
