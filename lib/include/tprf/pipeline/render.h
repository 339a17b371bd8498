#pragma once
/// `tprf render`: the pipeline that orders the stages (scene -> patches -> links -> illumination ->
/// solve -> gather -> film -> writers) and reports what it did. It holds no physics.

#include "tprf/io/json_records.h"
#include "tprf/pipeline/info.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace tprf {

class RankGroup;

/// What `tprf render` writes besides the cube and the steady image (docs/outputs.md).
struct RenderOptions : PipelineOptions {
    std::filesystem::path output;   ///< the output directory (created if missing)
    bool patch_profiles = false;    ///< patches.csv, patch_transient.npy, patch_steady.npy
    bool frames = false;            ///< frames/frame_NNNNN.exr, one per bin
    bool streaks = false;           ///< streaks/row_NNNN.exr, one x-t image per image row
    bool video = false;             ///< light_in_flight.mp4 through ffmpeg
    /// Ground truth maps (imaging/ground_truth.h, `--aov`): AovMap bits, 0 for none. Needs a camera.
    unsigned aovs = 0;
    /// The pixel (column x, row y) of sensor_plot.png when the scene has a sensor block; default:
    /// the image centre.
    std::optional<std::array<int, 2>> plot_pixel;
    /// The ranks that share the render (pipeline/ranks.h, docs/mpi.md; null: this process alone). Every
    /// rank calls render_file with the same scene and options; rank 0 renders the camera and writes
    /// every output, the others compute their share of the capture and write nothing.
    const RankGroup* ranks = nullptr;
};

/// A render whose camera misses more than this share of its light outside the time window warns.
inline constexpr double kWindowLossWarning = 0.01;

/// What a render did.
struct RenderReport {
    std::size_t patches = 0;
    std::size_t links = 0;
    int bins = 0;
    int width = 0;
    int height = 0;
    std::vector<MeshReport> meshes;    ///< one per mesh object: size and repairs
    PhaseSeconds seconds;
    double peak_rss_mb = 0.0;
    std::uint64_t link_bin_updates = 0;
    int measurements = 0;           ///< sensor measurements per pixel and channel (0: no sensor block)
    std::size_t capture_pairs = 0;  ///< (laser point, sensor point) pairs of the capture (0: none)
    bool second_bounce_shifted = false;  ///< whether the camera read the second bounce at its samples' times
    /// The share of the camera's light (its steady image) outside the cube's time window; -1: no camera.
    double outside_window = -1.0;
    std::vector<std::string> written;  ///< files and folders written, relative to the output directory
    std::vector<std::string> warnings; ///< lines for the user (a figure not drawn, and how to draw it)
};

/// A float32 array, C order (the last index varies fastest).
struct FloatArray {
    std::vector<std::size_t> shape;  ///< numpy's shape
    std::vector<float> data;         ///< product(shape) values
};

/// An int32 array, C order: labels (the ground truth's object map).
struct Int32Array {
    std::vector<std::size_t> shape;
    std::vector<std::int32_t> data;
};

/// What render_scene computes, kept in memory: the arrays that render_file writes as .npy files, by
/// the files' names without ".npy" (docs/outputs.md): "transient" (H, W, T, 3), "steady"
/// (H, W, 3), "transient_bounce_K" (solver.bounces), "patch_transient" (N, T, 3) and "patch_steady"
/// (N, 3) (RenderOptions::patch_profiles), "capture" (T, nu, nv) or (T, nu_l, nv_l, nu_s, nv_s), and
/// for a sensor block "measurements" (H, W, K, 3) and "depth" (H, W, amcw), and the ground truth maps
/// "aov_depth" (H, W), "aov_normal", "aov_position", "aov_albedo" (H, W, 3) that RenderOptions::aovs
/// asks for (aov_object in `labels`). The values are those of
/// render_file's files, bit for bit.
struct RenderResult {
    RenderReport report;
    TimeAxis time;                              ///< the scene's time axis
    std::map<std::string, FloatArray> arrays;   ///< by name, as above
    std::map<std::string, Int32Array> labels;   ///< int32 arrays by name: "aov_object" (RenderOptions::aovs)
    std::string record;                         ///< render.json's text
};

/// Renders a loaded, validated scene into memory: the stages of render_file and the same numbers, no
/// file written and no output directory (RenderOptions::output, frames, streaks, video and
/// plot_pixel are not used). Throws Error when the scene has neither camera nor capture or would
/// exceed the memory limit (before anything heavy is allocated), Cancelled when cancelled.
RenderResult render_scene(const Scene& scene, const RenderOptions& options);

/// A sensor block applied to a result, as `tprf sensor` applies it to a render directory: to the
/// camera's cube, or (a capture without a camera) to the capture's sensor points as rows of pixels.
/// Returns "measurements" (H, W, K, 3) and, for amcw, "depth" (H, W). Throws Error when the block
/// does not fit the result's time axis or image.
std::map<std::string, FloatArray> measure(const SensorSettings& sensor, const RenderResult& result, int threads = 0);

/// Renders a scene file into options.output: loads and validates the scene (tprf::Error before any
/// file is written), builds patches and links, solves, gathers the camera's view, and writes every
/// output under a staging name first, moving them all into place only once all are complete.
/// With several ranks: a scene that fails on any rank stops every rank before the shared work (the
/// lowest failing rank throws its Error, the others RankStopped); an exception during the shared work
/// ends every rank (RankGroup::abort). The report of a rank other than 0 is empty.
RenderReport render_file(const std::filesystem::path& scene_file, const RenderOptions& options);

}  // namespace tprf
