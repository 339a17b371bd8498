#include "tprf/pipeline/sensor_run.h"

#include "staging.h"
#include "tprf/core/error.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/io/atomic_file.h"
#include "tprf/io/npy.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"

namespace tprf {

SensorReport apply_sensor_file(const SensorRunOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    const std::filesystem::path& dir = options.render_dir;
    // The sensor file first: its mistakes are the likelier ones.
    const SensorSettings sensor = load_sensor(options.sensor_file);
    const std::filesystem::path info_file = dir / "render.json";
    if (!std::filesystem::exists(info_file))
        throw Error(dir.string() + ": not a tprf render directory (no render.json)");
    const TimeAxis time = read_render_time(info_file);
    validate_sensor(sensor, time);
    const NpyView cube(dir / "transient.npy");
    const std::vector<std::size_t>& shape = cube.shape();
    if (shape.size() != 4 || shape[2] != std::size_t(time.bins) || shape[3] != 3 || shape[0] == 0 || shape[1] == 0)
        fail_input(dir / "transient.npy", "", "expected shape (H, W, " + std::to_string(time.bins) +
                                                  ", 3) to match render.json's time axis");
    SensorReport report;
    report.height = int(shape[0]);
    report.width = int(shape[1]);
    const std::array<int, 2> pixel = plot_pixel(options.plot_pixel, report.width, report.height);
    check_output_dir(dir);
    Staging staging(dir);
    if (options.progress) options.progress("sensor", 0.0);
    try {
        report.measurements = write_sensor_outputs(staging, sensor, {time, cube.data(), report.height, report.width},
                                                   pixel, options, report.warnings);
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
