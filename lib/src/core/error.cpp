#include "tprf/core/error.h"

#include "tprf/core/cancel.h"

#include <cerrno>
#include <csignal>
#include <sstream>
#include <system_error>

namespace tprf {

void fail_input(const std::filesystem::path& file, std::string_view json_path, std::string_view what) {
    std::ostringstream msg;
    msg << file.string() << ": ";
    if (!json_path.empty()) msg << json_path << ": ";
    msg << what;
    throw Error(msg.str());
}

int exit_status(const std::exception_ptr& failure) noexcept {
    try {
        std::rethrow_exception(failure);
    } catch (const Error&) {
        return 2;
    } catch (const Cancelled& e) {
        return 128 + (e.signal() > 0 ? e.signal() : SIGINT);
    } catch (...) {
        return 1;
    }
}

void fail_output(const std::filesystem::path& file, std::string_view what, int err) {
    std::string msg = file.string();
    msg += ": ";
    msg += what;
    msg += ": ";
    msg += std::system_category().message(err);
    // The one hint that turns an errno into an action.
    if (err == ENOSPC || err == EDQUOT) msg += " (free some space, or write elsewhere with -o)";
    if (err == EFBIG) msg += " (a file-size limit: see ulimit -f)";
    throw OutputError(msg);
}

}  // namespace tprf
