#include "capture_outputs.h"

#include "tprf/core/error.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/geometry/patches.h"
#include "tprf/io/hdf5_capture.h"
#include "tprf/io/npy.h"
#include "tprf/pipeline/capture.h"
#include "tprf/scene/scene.h"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <sstream>

namespace tprf {
namespace {

CaptureGridData grid_data(const CaptureGrid& grid, const std::vector<WallPoint>& points) {
    CaptureGridData d;
    d.nu = grid.nu;
    d.nv = grid.nv;
    for (const WallPoint& w : points) {
        d.xyz.push_back(w.point);
        d.normals.push_back(w.normal);
    }
    return d;
}

// A YAML single-quoted scalar: only the quote itself is escaped (doubled).
std::string yaml_quoted(const std::string& text) {
    std::string out = "'";
    for (char c : text) out += c == '\'' ? std::string("''") : std::string(1, c);
    return out + "'";
}

// scene_info: a YAML mapping with the tprf version, the scene file and its text (a literal block).
std::string scene_info(const Scene& scene) {
    std::ostringstream yaml;
    yaml << "original_format: tprf\ntprf_version: " << yaml_quoted(TPRF_VERSION)
         << "\nscene_file: " << yaml_quoted(scene.file.string()) << "\nscene: |\n";
    std::ifstream in(scene.file);
    std::string line;
    bool any = false;
    while (std::getline(in, line)) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        yaml << "  " << line << "\n";
        any = true;
    }
    if (!any) yaml << "  (not read from a file)\n";
    return yaml.str();
}

// H time first: (T, nu, nv) or (T, nu_l, nv_l, nu_s, nv_s), as capture.hdf5 and capture.npy hold it.
std::vector<float> time_first(const CaptureResult& r) {
    const std::size_t T = std::size_t(r.bins);
    std::vector<float> out(r.H.size());
    for (std::size_t pair = 0; pair < r.pairs; ++pair)
        for (std::size_t t = 0; t < T; ++t) out[t * r.pairs + pair] = r.H[pair * T + t];
    return out;
}

std::vector<std::size_t> capture_shape(const Capture& c, int bins) {
    const auto n = [](int v) { return std::size_t(v); };
    if (c.type == CaptureType::Confocal) return {n(bins), n(c.sensor_grid.nu), n(c.sensor_grid.nv)};
    return {n(bins), n(c.laser_grid.nu), n(c.laser_grid.nv), n(c.sensor_grid.nu), n(c.sensor_grid.nv)};
}

// capture.hdf5 (files only) and capture.npy: H time first. Returns that array (kept by `arrays`).
const FloatArray& write_capture(const Scene& scene, const CaptureResult& r, Arrays& arrays) {
    const Capture& c = *scene.capture;
    FloatArray H{capture_shape(c, r.bins), time_first(r)};
    if (Staging* staging = arrays.staging()) {
        CaptureFile file;
        file.confocal = c.type == CaptureType::Confocal;
        file.shape = H.shape;
        file.H = H.data.data();
        file.sensor_grid = grid_data(c.sensor_grid, r.points.sensor);
        file.laser_grid = grid_data(c.laser_grid, r.points.laser);
        file.sensor_xyz = c.sensor_position;
        file.laser_xyz = c.laser_position;
        file.delta_t = scene.time.bin_width_m();
        file.t_start = scene.time.start_m();
        file.t_accounts_first_and_last_bounces = c.account_first_and_last_bounces;
        file.scene_info = scene_info(scene);
        write_capture_hdf5(staging->path("capture.hdf5"), file);
    }
    return arrays.put("capture", std::move(H));
}

// A sensor block on a capture without a camera: the capture as a cube of (rows, nv_s) "pixels"
// (capture_cube), so that the camera's sensor model applies unchanged.
int capture_measurements(const Scene& scene, const RenderOptions& options, const FloatArray& H, Arrays& arrays,
                         std::vector<std::string>& warnings) {
    const CaptureCube c = capture_cube(H.shape, H.data.data());
    const CubeView view{scene.time, c.cube.data(), c.height, c.width};
    if (Staging* staging = arrays.staging())
        return write_sensor_outputs(*staging, *scene.sensor, {view, plot_pixel(std::nullopt, c.width, c.height)},
                                    options, warnings);
    return measure_cube(*scene.sensor, view, options.threads, arrays).K;
}

// The capture's options for a render: threads, progress, the ranks, and what the march may use: the
// limit (--max-memory, or 80% of what is available) less what this process has held so far and the
// capture's H (twice: its copy while written).
CaptureOptions capture_options(const Scene& scene, const RenderOptions& options) {
    CaptureOptions capture_options;
    capture_options.threads = options.threads;
    capture_options.progress = options.progress;
    capture_options.ranks = options.ranks;
    const double held = peak_rss_mb() * 1e6 + 2.0 * 4.0 * double(scene.time.bins) * double(scene.capture->pairs());
    const double limit = double(memory_limit_bytes(options));
    if (limit > 0.0) capture_options.memory_bytes = std::size_t(std::max(1.0, limit - held));
    return capture_options;
}

}  // namespace

void check_capture_flags(const RenderOptions& options) {
    const char* flag = options.frames ? "--frames"
                       : options.streaks ? "--streaks"
                       : options.video ? "--video"
                       : options.patch_profiles ? "--patch-profiles"
                       : options.plot_pixel ? "--plot-pixel"
                       : options.aovs ? "--aov"
                                            : nullptr;
    if (flag)
        throw Error(std::string(flag) + " needs a camera: the scene has a capture block and no camera; nothing was "
                                        "rendered");
}

CaptureRecord render_capture(const Scene& scene, const RenderOptions& options, const CaptureInputs& in, Arrays& arrays,
                             RenderReport& report) {
    const CaptureResult r = compute_capture(scene, in.patches, in.visibility, in.links, capture_options(scene, options));
    const auto start = std::chrono::steady_clock::now();
    const FloatArray& H = write_capture(scene, r, arrays);
    if (scene.sensor && !scene.camera)
        report.measurements = capture_measurements(scene, options, H, arrays, report.warnings);
    report.seconds.write += seconds_since(start);
    report.seconds.solve += r.seconds_solve;
    report.seconds.gather += r.seconds_views + r.seconds_gather;
    report.link_bin_updates += r.link_bin_updates;
    report.capture_pairs = r.pairs;
    CaptureRecord record;
    record.type = scene.capture->type == CaptureType::Confocal ? "confocal" : "exhaustive";
    record.laser_points = r.points.laser.size();
    record.sensor_points = r.points.sensor.size();
    record.solved = r.solved;
    record.batch = r.batch;
    record.march_bin_factor = scene.capture->march_bin_factor;
    record.march_grid_step = scene.capture->march_grid_step;
    record.marches = r.marches;
    record.view_pairs = r.view_pairs;
    record.link_bin_updates = r.link_bin_updates;
    record.seconds_views = r.seconds_views;
    record.seconds_solve = r.seconds_solve;
    record.seconds_gather = r.seconds_gather;
    record.seconds_exchange = r.seconds_exchange;
    record.shares = r.shares;
    return record;
}

void share_capture(const Scene& scene, const RenderOptions& options, const CaptureInputs& in) {
    compute_capture(scene, in.patches, in.visibility, in.links, capture_options(scene, options));
}

}  // namespace tprf
