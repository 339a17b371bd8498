#include "tprf/core/error.h"

#include <sstream>

namespace tprf {

void fail_input(const std::filesystem::path& file, std::string_view json_path, std::string_view what) {
    std::ostringstream msg;
    msg << file.string() << ": ";
    if (!json_path.empty()) msg << json_path << ": ";
    msg << what;
    throw Error(msg.str());
}

}  // namespace tprf
