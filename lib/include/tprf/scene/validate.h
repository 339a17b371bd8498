#pragma once
/// Checks of a Scene however it was built (a JSON file today; Mitsuba XML and Python next), with the
/// messages the JSON parser gives: "FILE: JSON.PATH: what is wrong", thrown as tprf::Error. A parser
/// checks only what is about its own text (syntax, unknown keys, types, enum names, files it reads),
/// builds the plain data, then calls these; every later stage assumes checked data.

#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"
#include "tprf/scene/sensor_settings.h"

#include <filesystem>
#include <string_view>

namespace tprf {

/// Measurements per pixel a sensor block may ask for: beyond, the measurements alone would dwarf any
/// render. (A gates block is refused before its gates are expanded, so this bounds memory too.)
inline constexpr int kMaxSensorMeasurements = 1 << 20;
/// Modulation frequencies an AMCW block may measure in turn (cameras use 2 or 3).
inline constexpr int kMaxAmcwFrequencies = 16;
/// Wraps of an AMCW block's lowest frequency that its time window may hold (the depth's unwrapping tries
/// each): beyond, the frequencies are far too high for the window (Hz meant as kHz, say).
inline constexpr int kMaxAmcwCandidates = 100000;

/// Checks every value of a scene: finite numbers, ranges (bins > 0, albedo in [0, 1], ...), geometry
/// that is not degenerate (zero-length or parallel vectors, a singular transform), mesh files that can
/// be read, at least one object, and the sensor block on its own and against the time axis. Paths are
/// those of the scene file (`objects[2].u`): an object's from its json_path (or "objects[i]" when that
/// is empty), the sensor's from its json_path (or "sensor"). Throws tprf::Error naming scene.file (the
/// sensor's own file where it has one), the path and the problem; the first problem in document order.
void validate(const Scene& scene);

/// Checks a time axis as `json_path` of `file` (the scene's `time` block, or render.json's).
void validate_time(const TimeAxis& time, const std::filesystem::path& file, std::string_view json_path = "time");

/// Checks a sensor block on its own (finite numbers, ranges, a pulse table's shape), naming its file and
/// JSON path. `tprf sensor` checks it so before reading the render it applies to.
void validate_sensor(const SensorSettings& sensor);

/// Checks a sensor block on its own and against a render's time axis: the pulse (and a SPAD's jitter)
/// must reach no more than 64 windows from t = 0, and at least one gate or window must be able to
/// receive light of the window (a sensor that can measure nothing is a mistake). Throws tprf::Error
/// naming the block's file and JSON path. The sensor model assumes a checked block.
void validate_sensor(const SensorSettings& sensor, const TimeAxis& time);

}  // namespace tprf
