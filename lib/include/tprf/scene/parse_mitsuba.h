#pragma once
/// Mitsuba 3 XML scenes (docs/mitsuba.md) read into the same Scene as a JSON scene file. Only the
/// subset that describes what tprf renders is read: diffuse, conductor, roughconductor, plastic,
/// roughplastic and thindielectric BSDFs (and twosided around them), obj/ply/rectangle/cube shapes with
/// area emitters, point emitters, a perspective sensor with mitransient's transient_hdr_film, and the
/// transient_path or path integrator. Anything else (another BSDF, a texture, a medium, an unknown
/// attribute or child) is a tprf::Error "FILE:LINE: <element>: what is wrong"; nothing is silently
/// ignored. The XML library stays inside this stage's sources.

#include "tprf/scene/scene.h"

#include <filesystem>
#include <functional>
#include <map>
#include <string>

namespace tprf {

/// `-D name=value` on the command line: values of `$name` in the XML, which override its `<default>`s.
using XmlDefines = std::map<std::string, std::string, std::less<>>;

/// Reads a Mitsuba 3 XML scene file and validates the Scene (scene/validate.h). Throws tprf::Error
/// naming the file, the line, the element and the problem.
Scene load_mitsuba_scene(const std::filesystem::path& file, const XmlDefines& defines = {});

/// Parses Mitsuba 3 XML text as if read from `file` (messages name it; mesh file names are relative to
/// its folder) and validates the Scene.
Scene parse_mitsuba_scene(const std::string& text, const std::filesystem::path& file,
                          const XmlDefines& defines = {});

}  // namespace tprf
