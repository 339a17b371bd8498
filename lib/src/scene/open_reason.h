#pragma once
/// Private to the scene stage (not installed): the system's reason why an input file could not be
/// opened, for the end of the message that names it.

#include <string>
#include <system_error>

namespace tprf {

/// ": " and the system's words for errno `err` ("No such file or directory"), or "" when `err` is 0.
/// Read errno right after the failed open (and set it to 0 before, so that an older value is not taken
/// for the reason).
inline std::string open_reason(int err) {
    std::string out;
    if (err == 0) return out;
    out += ": ";
    out += std::system_category().message(err);
    return out;
}

}  // namespace tprf
