#pragma once
/// `tprf sensor OUTDIR SENSOR.json`: a sensor block applied to an earlier render.

#include "tprf/pipeline/options.h"

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tprf {

/// What `tprf sensor OUTDIR SENSOR.json` does.
struct SensorRunOptions : PipelineOptions {
    std::filesystem::path render_dir;   ///< a directory written by `tprf render` (render.json, transient.npy)
    std::filesystem::path sensor_file;  ///< the sensor block, or {"sensor": block}
    std::optional<std::array<int, 2>> plot_pixel;  ///< as RenderOptions::plot_pixel
};

/// What a sensor run did.
struct SensorReport {
    int measurements = 0;               ///< K
    int width = 0, height = 0;
    double seconds = 0.0;
    std::vector<std::string> written;   ///< relative to the render directory
    std::vector<std::string> warnings;  ///< lines for the user (a figure not drawn, and how to draw it)
};

/// Applies a sensor block to an existing render (its time axis from render.json, its cube from
/// transient.npy, memory-mapped) and writes measurements.npy, depth.npy (amcw), sensor_plot.png
/// and sensor.json into the render directory, each atomically. Bad input throws tprf::Error first.
SensorReport apply_sensor_file(const SensorRunOptions& options);

}  // namespace tprf
