#pragma once
/// `tprf sensor OUTDIR SENSOR.json [--cube NAME] [--name NAME]`: a sensor block applied to a cube of an
/// earlier render, into a folder of its own.

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
    /// The cube measured: "transient" (the camera's), "transient_bounce_K" or "capture", its file
    /// OUTDIR/CUBE.npy.
    std::string cube = "transient";
    /// The outputs' folder is OUTDIR/sensor-NAME; empty: the sensor file's stem.
    std::string name;
};

/// What a sensor run did.
struct SensorReport {
    int measurements = 0;               ///< K
    int width = 0, height = 0;
    double seconds = 0.0;
    std::filesystem::path folder;       ///< where the outputs went: OUTDIR/sensor-NAME
    std::vector<std::string> written;   ///< relative to `folder`
    std::vector<std::string> warnings;  ///< lines for the user (a figure not drawn, and how to draw it)
};

/// Applies a sensor block to a cube of an existing render (its time axis from render.json, the cube
/// memory-mapped: a camera's (H, W, T, 3); or a capture's (T, ...), read, as rows of sensor points),
/// with the render's directory locked (DirectoryLock), and writes
/// measurements.npy, depth.npy and raw.npy (amcw), sensor.json and sensor_plot.png into
/// OUTDIR/sensor-NAME/, each atomically, leaving everything else in OUTDIR as it was. Bad input (the
/// block, a cube that is not there or does not fit render.json, a name that is no plain folder name)
/// throws tprf::Error first.
SensorReport apply_sensor_file(const SensorRunOptions& options);

}  // namespace tprf
