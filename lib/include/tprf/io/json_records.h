#pragma once
/// The JSON records of an output directory: render.json (what a render did, docs/outputs.md), sensor.json (what each sensor measurement is, docs/sensor.md) and sensor_plot.json (the
/// data of sensor_plot.png). All appear
/// atomically under their final name. The JSON library stays inside this file's source.

#include "tprf/core/phase_seconds.h"
#include "tprf/core/time_axis.h"
#include "tprf/geometry/patches.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/scene/scene.h"
#include "tprf/scene/sensor_settings.h"
#include "tprf/transport/solver.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tprf {

/// One rank's part of a capture split across ranks (docs/mpi.md): its laser points and what it spent.
struct CaptureShare {
    std::size_t first_laser = 0;      ///< laser points [first_laser, first_laser + laser_points)
    std::size_t laser_points = 0;
    int marches = 0;
    std::size_t view_pairs = 0;       ///< (laser point, patch) pairs seen (confocal: the sensor points too)
    std::uint64_t link_bin_updates = 0;
    double seconds_views = 0.0, seconds_solve = 0.0, seconds_gather = 0.0;
};

/// What render.json records of a capture (docs/capture.md).
struct CaptureRecord {
    std::string type;                 ///< "confocal" or "exhaustive"
    std::size_t laser_points = 0;
    std::size_t sensor_points = 0;
    bool solved = false;              ///< later bounces marched
    int batch = 0;                    ///< illuminations per march
    int marches = 0;
    int march_bin_factor = 1;         ///< capture.march_bin_factor: the march's bins per scene bin
    int march_grid_step = 1;          ///< capture.march_grid_step: marched grid points, every S-th
    std::size_t view_pairs = 0;       ///< (wall point, patch) pairs seen
    std::uint64_t link_bin_updates = 0;
    double seconds_views = 0.0, seconds_solve = 0.0, seconds_gather = 0.0;  ///< rank 0's
    /// Rank 0's wait for the others' shares and their transfer (0 with one rank).
    double seconds_exchange = 0.0;
    std::vector<CaptureShare> shares;  ///< one per rank, in rank order (one: a single process)
};

/// Everything render.json records.
struct RenderRecord {
    std::filesystem::path scene_file;
    std::size_t patches = 0;
    std::size_t links = 0;
    TimeAxis time;
    std::optional<Camera> camera;         ///< absent for a capture without a camera
    std::optional<CaptureRecord> capture; ///< the scene's capture, if it has one
    SolverSettings solver;
    int bounce_terms = 0;
    SolveStats stats;
    PhaseSeconds seconds;
    std::optional<ExposureType> sensor;   ///< the sensor block's exposure, if the scene has one
    int measurements = 0;                 ///< the sensor's measurements per pixel and channel
    double peak_rss_mb = 0.0;
    std::vector<MeshReport> meshes;       ///< one per mesh object
    bool second_bounce_shifted = false;   ///< camera.shift_second_bounce applied (SecondBounceLight)
    double outside_window = -1.0;         ///< the camera's light outside the window, a share (-1: no camera)
};

/// render.json's text (JSON, indented, ending in a newline).
std::string render_json_text(const RenderRecord& record);

/// Writes render.json.
void write_render_json(const std::filesystem::path& path, const RenderRecord& record);

/// Writes sensor.json: the exposure, K, what each measurement k is (a window [start, width], a phase
/// in degrees or a histogram bin's start), the noise or SPAD settings and the plotted pixel.
void write_sensor_json(const std::filesystem::path& path, const SensorSettings& sensor, const TimeAxis& time,
                       int measurements, std::array<int, 2> plot_pixel);

/// Writes the data of sensor_plot.png (docs/sensor.md, "Outputs", lists the keys): what
/// `tprf_plots.py sensor DATA.json OUT.png` draws. Non-finite values are written as null.
void write_sensor_plot_json(const std::filesystem::path& path, const SensorPlot& plot);

}  // namespace tprf
