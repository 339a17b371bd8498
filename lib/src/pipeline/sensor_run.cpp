#include "tprf/pipeline/sensor_run.h"

#include "arrays.h"
#include "staging.h"
#include "tprf/core/error.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/io/atomic_file.h"
#include "tprf/io/npy.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"

#include <algorithm>
#include <cctype>
#include <optional>

namespace tprf {

namespace {

// A folder name of letters, digits, '.', '_' and '-' (not "." or ".."): the name cannot leave OUTDIR.
bool plain_name(const std::string& name) {
    if (name.empty() || name == "." || name == ".." || name.size() > 200) return false;
    return std::all_of(name.begin(), name.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-';
    });
}

// The cubes of a render directory a sensor can measure, for the message that lists them.
std::string cubes_in(const std::filesystem::path& dir) {
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
        if (entry.path().extension() != ".npy") continue;
        const std::string stem = entry.path().stem().string();
        if (stem == "transient" || stem == "capture" || stem.rfind("transient_bounce_", 0) == 0) names.push_back(stem);
    }
    std::sort(names.begin(), names.end());
    std::string list;
    for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
    return list.empty() ? "none" : list;
}

}  // namespace

SensorReport apply_sensor_file(const SensorRunOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    const std::filesystem::path& dir = options.render_dir;
    // The sensor file first: its mistakes are the likelier ones.
    const SensorSettings sensor = load_sensor(options.sensor_file);
    const std::string name = options.name.empty() ? options.sensor_file.stem().string() : options.name;
    if (!plain_name(name))
        throw Error("--name \"" + name + "\": the outputs' folder is sensor-NAME, so NAME must be letters, digits, "
                    "'.', '_' or '-'" + (options.name.empty() ? " (it comes from the sensor file's name; give --name)" : ""));
    const std::filesystem::path info_file = dir / "render.json";
    if (!std::filesystem::exists(info_file))
        throw Error(dir.string() + ": not a tprf render directory (no render.json)");
    // The render's directory stays as it is while its cube is read and measured.
    const DirectoryLock render_lock(dir);
    const TimeAxis time = read_render_time(info_file);
    validate_sensor(sensor, time);
    const std::filesystem::path cube_file = dir / (options.cube + ".npy");
    if (!plain_name(options.cube) || !std::filesystem::is_regular_file(cube_file))
        throw Error("--cube " + options.cube + ": " + dir.string() + " has no " + options.cube +
                    ".npy (cubes there: " + cubes_in(dir) + ")");
    const NpyView view(cube_file);
    const std::vector<std::size_t>& shape = view.shape();
    const std::size_t T = std::size_t(time.bins);
    const bool capture = options.cube == "capture";
    // A capture's H is (T, ...), time first; it is measured as rows of sensor points (capture_cube).
    std::optional<CaptureCube> rows;
    if (capture) {
        if (shape.size() < 2 || shape[0] != T || view.size() == 0)
            fail_input(cube_file, "", "expected shape (" + std::to_string(T) + ", ...) to match render.json's time axis");
        rows = capture_cube(shape, view.data());
    } else if (shape.size() != 4 || shape[2] != T || shape[3] != 3 || shape[0] == 0 || shape[1] == 0) {
        fail_input(cube_file, "", "expected shape (H, W, " + std::to_string(T) + ", 3) to match render.json's time axis");
    }
    SensorReport report;
    report.height = rows ? rows->height : int(shape[0]);
    report.width = rows ? rows->width : int(shape[1]);
    const float* data = rows ? rows->cube.data() : view.data();
    const std::array<int, 2> pixel = plot_pixel(options.plot_pixel, report.width, report.height);
    report.folder = dir / ("sensor-" + name);
    check_output_dir(report.folder);
    Staging staging(report.folder, "sensor.json");
    if (options.progress) options.progress("sensor", 0.0);
    try {
        const CaptureSource source{dir / "capture.hdf5", shape};
        const CubeView measured{time, data, report.height, report.width};
        report.measurements =
            write_sensor_outputs(staging, sensor, {measured, pixel, capture ? &source : nullptr}, options, report.warnings);
        staging.publish(sensor_outputs());
    } catch (const OutputError& e) {
        throw OutputError(staging.public_message(e.what()));
    }
    report.written = staging.names();
    if (options.progress) options.progress("sensor", 1.0);
    report.seconds = seconds_since(start);
    return report;
}

}  // namespace tprf
