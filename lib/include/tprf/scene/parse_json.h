#pragma once
/// Scene and sensor files (docs/scene.md, "Sensor block") read into plain data. Parsing goes in
/// stages: JSON text -> JSON document -> Scene, then validate() (scene/validate.h). The parser checks
/// only what is about the JSON (syntax, unknown keys, types, array lengths, enum names, the files it
/// reads); validate() checks the values, so that a Scene built any other way gets the same checks.
/// Every error names the file, the JSON path (`objects[2].u`) and what is wrong, and is thrown as
/// tprf::Error. Where a file holds several errors, one of the parser's wins over one of validate()'s
/// even when it comes later in the file. The JSON library stays inside this stage's sources: nothing
/// here exposes it.

#include "tprf/core/time_axis.h"
#include "tprf/scene/parse_mitsuba.h"
#include "tprf/scene/scene.h"
#include "tprf/scene/sensor_settings.h"

#include <filesystem>
#include <string>
#include <string_view>

namespace tprf {

/// Reads a scene file and validates the Scene. Throws tprf::Error naming the file, the JSON path and
/// the problem. A file whose name ends in ".xml" (any case) is read as Mitsuba 3 XML
/// (scene/parse_mitsuba.h), any other as JSON.
Scene load_scene(const std::filesystem::path& file);

/// load_scene with the command line's `-D name=value`s for a Mitsuba XML scene; for a JSON scene,
/// non-empty `defines` are an Error.
Scene load_scene(const std::filesystem::path& file, const XmlDefines& defines);

/// Parses scene JSON text and validates the Scene; `file` is used in messages and to resolve relative
/// mesh paths.
Scene parse_scene(const std::string& text, const std::filesystem::path& file);

/// Reads a sensor file for `tprf sensor`: either the block itself or an object {"sensor": block}.
/// Checked on its own (validate_sensor without a time axis); the check against the render's time axis
/// is the caller's.
SensorSettings load_sensor(const std::filesystem::path& file);

/// Parses a `sensor` block given as JSON text, as if it stood at `json_path` of `file` (messages name
/// both; a table pulse's CSV is read relative to `file`), and checks it on its own as load_sensor does.
SensorSettings parse_sensor_block(const std::string& text, const std::filesystem::path& file,
                                  std::string_view json_path = "sensor");

/// A `time` block given as JSON text (`bins`, `bin_width`, `start`, `unit`, as in a scene), validated;
/// messages name `file` and `json_path`.
TimeAxis parse_time_block(const std::string& text, const std::filesystem::path& file, std::string_view json_path = "time");

/// The time axis recorded in a render directory's render.json (for `tprf sensor`), validated.
TimeAxis read_render_time(const std::filesystem::path& render_json);

}  // namespace tprf
