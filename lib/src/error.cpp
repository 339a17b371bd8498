#include "tprf/error.h"

namespace tprf {

void fail_input(const std::filesystem::path& file, std::string_view json_path, std::string_view what) {
    std::string msg = file.string();
    if (!json_path.empty()) {
        msg += ": ";
        msg += json_path;
    }
    msg += ": ";
    msg += what;
    throw Error(msg);
}

}  // namespace tprf
