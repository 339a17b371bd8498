#pragma once
/// Pipeline entry points for the command line: each runs the stages in order and reports what it did.

#include "tprf/core/progress.h"
#include "tprf/scene/scene.h"

#include <array>
#include <cstdint>
#include <optional>
#include <filesystem>
#include <string>
#include <vector>

namespace tprf {

/// Options shared by the pipeline entry points.
struct PipelineOptions {
    int threads = 0;        ///< 0: all cores
    ProgressFn progress;    ///< may be empty
};

/// What `tprf info` prints: the scene's size without rendering it.
struct SceneSummary {
    std::size_t patches = 0;
    int dropped_degenerate = 0;     ///< mesh faces dropped (zero area, repeated vertices)
    double max_edge = 0.0;          ///< patch size used, metres
    std::size_t links = 0;
    std::size_t link_bytes = 0;
    std::uint64_t pairs_tested = 0; ///< unordered pairs facing each other
    double seconds_patches = 0.0;
    double seconds_links = 0.0;
};

/// Builds patches and links of a scene and measures them.
SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options = {});

/// What `tprf render` writes besides the cube and the steady image (SPEC.md, "Output directory").
struct RenderOptions : PipelineOptions {
    std::filesystem::path output;   ///< the output directory (created if missing)
    bool patch_profiles = false;    ///< patches.csv, patch_transient.npy, patch_steady.npy
    bool frames = false;            ///< frames/frame_NNNNN.exr, one per bin
    bool streaks = false;           ///< streaks/row_NNNN.exr, one x-t image per image row
    bool video = false;             ///< light_in_flight.mp4 through ffmpeg
    /// The pixel (column x, row y) of sensor_plot.png when the scene has a sensor block; default:
    /// the image centre.
    std::optional<std::array<int, 2>> plot_pixel;
};

/// Seconds spent in each phase of a render (render.json's `seconds`).
struct PhaseSeconds {
    double load = 0, patches = 0, links = 0, solve = 0, gather = 0, write = 0, total = 0;
};

/// What a render did.
struct RenderReport {
    std::size_t patches = 0;
    std::size_t links = 0;
    int bins = 0;
    int width = 0;
    int height = 0;
    int dropped_degenerate = 0;
    PhaseSeconds seconds;
    double peak_rss_mb = 0.0;
    std::uint64_t link_bin_updates = 0;
    int measurements = 0;           ///< sensor measurements per pixel and channel (0: no sensor block)
    std::vector<std::string> written;  ///< files and folders written, relative to the output directory
};

/// Renders a scene file into options.output: loads and validates the scene (tprf::Error before any
/// file is written), builds patches and links, solves, gathers the camera's view, and writes every
/// output under a staging name first, moving them all into place only once all are complete.
RenderReport render_file(const std::filesystem::path& scene_file, const RenderOptions& options);

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
};

/// Applies a sensor block to an existing render (its time axis from render.json, its cube from
/// transient.npy, memory-mapped) and writes measurements.npy, depth.npy (amcw), sensor_plot.png
/// and sensor.json into the render directory, each atomically. Bad input throws tprf::Error first.
SensorReport apply_sensor_file(const SensorRunOptions& options);

/// Peak resident memory of this process so far, MB (VmHWM).
double peak_rss_mb();

/// The scene's time window in words, e.g. "1024 bins of 0.005 m from 0 m to 5.12 m (0 to 17.08 ns)".
std::string describe_time(const TimeAxis& time);

}  // namespace tprf
