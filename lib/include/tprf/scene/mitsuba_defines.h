#pragma once
/// The `-D name=value` parameters of a Mitsuba XML scene (scene/parse_mitsuba.h) that the scene does
/// not use, for a warning.

#include "tprf/scene/parse_mitsuba.h"

#include <filesystem>
#include <string>
#include <vector>

namespace tprf {

/// The names of `defines` that no `$name` of the Mitsuba XML scene `file` refers to, in name order: a
/// `-D` that changes nothing (a misspelt name, most likely). Reads the file again; a file that cannot be
/// read or parsed throws tprf::Error as load_mitsuba_scene does.
std::vector<std::string> unused_defines(const std::filesystem::path& file, const XmlDefines& defines);

}  // namespace tprf
