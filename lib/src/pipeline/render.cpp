#include "tprf/pipeline/render.h"

#include "tprf/io/atomic_file.h"
#include "tprf/imaging/camera.h"
#include "tprf/transport/illumination.h"
#include "tprf/core/error.h"
#include "tprf/imaging/film.h"
#include "tprf/io/image_io.h"
#include "tprf/transport/links.h"
#include "tprf/io/npy.h"
#include "tprf/geometry/patches.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/io/sequences.h"
#include "tprf/transport/solver.h"
#include "tprf/transport/steady.h"
#include "tprf/geometry/visibility.h"

#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

namespace tprf {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Outputs are written into a hidden staging folder inside the output directory, then moved into place
// one by one once every one of them is complete; on failure the folder is removed.
class Staging {
public:
    explicit Staging(const std::filesystem::path& out) : m_out(out) {
        m_earlier_run = std::filesystem::exists(out / "render.json");
        m_dir = out / (".tprf-staging-" + std::to_string(::getpid()));
        std::filesystem::remove_all(m_dir);
        std::filesystem::create_directories(m_dir);
    }
    ~Staging() {
        std::error_code ec;
        std::filesystem::remove_all(m_dir, ec);
    }
    Staging(const Staging&) = delete;
    Staging& operator=(const Staging&) = delete;

    std::filesystem::path path(const std::string& name) {
        m_names.push_back(name);
        return m_dir / name;
    }

    /// Moves every staged output into place, then, when the directory held an earlier render, removes
    /// that run's outputs that this one did not write (`owned`: names, or prefixes ending in '*'), so
    /// that the directory never mixes two runs (a depth.npy of an earlier AMCW sensor beside gated
    /// measurements, say).
    void publish(const std::vector<std::string>& owned) {
        for (const std::string& name : m_names) {
            const std::filesystem::path to = m_out / name;
            if (std::filesystem::is_directory(to)) std::filesystem::remove_all(to);
            std::filesystem::rename(m_dir / name, to);
        }
        // Only in a directory that an earlier run wrote: a folder of the user's own named "frames" in
        // some other directory is not ours to remove.
        if (!m_earlier_run) return;
        for (const auto& entry : std::filesystem::directory_iterator(m_out)) {
            const std::string name = entry.path().filename().string();
            if (std::find(m_names.begin(), m_names.end(), name) != m_names.end()) continue;
            for (const std::string& o : owned) {
                const bool prefix = !o.empty() && o.back() == '*';
                if (prefix ? name.rfind(o.substr(0, o.size() - 1), 0) == 0 : name == o) {
                    std::filesystem::remove_all(entry.path());
                    break;
                }
            }
        }
    }
    const std::vector<std::string>& names() const { return m_names; }

private:
    std::filesystem::path m_out, m_dir;
    std::vector<std::string> m_names;
    bool m_earlier_run = false;
};

// What a sensor run writes, and what a render writes besides (SPEC.md, "Output directory"; docs/sensor.md).
const std::vector<std::string> kSensorOutputs = {"measurements.npy", "depth.npy", "sensor.json", "sensor_plot.png"};
std::vector<std::string> render_outputs() {
    std::vector<std::string> all = {"transient.npy", "steady.npy", "steady.exr", "preview.png", "render.json",
                                    "patches.csv", "patch_transient.npy", "patch_steady.npy", "frames", "streaks",
                                    "light_in_flight.mp4", "transient_bounce_*"};
    all.insert(all.end(), kSensorOutputs.begin(), kSensorOutputs.end());
    return all;
}

const char* unit_name(TimeUnit u) { return u == TimeUnit::Picoseconds ? "ps" : "m"; }

void write_patches_csv(const std::filesystem::path& path, const PatchSet& p) {
    std::ostringstream out;
    out.precision(9);
    out << "id,object,cx,cy,cz,nx,ny,nz,area\n";
    for (std::size_t i = 0; i < p.size(); ++i)
        out << i << ',' << p.object[i] << ',' << p.centroid[i].x() << ',' << p.centroid[i].y() << ','
            << p.centroid[i].z() << ',' << p.normal[i].x() << ',' << p.normal[i].y() << ',' << p.normal[i].z() << ','
            << p.area[i] << '\n';
    write_text_file(path, out.str());
}

// The plot pixel: the image centre by default; one outside the image is a bad flag.
std::array<int, 2> plot_pixel(const std::optional<std::array<int, 2>>& asked, int width, int height) {
    if (!asked) return {width / 2, height / 2};
    const auto [x, y] = *asked;
    if (x < 0 || y < 0 || x >= width || y >= height)
        throw Error("--plot-pixel " + std::to_string(x) + "," + std::to_string(y) + " is outside the " +
                    std::to_string(width) + " x " + std::to_string(height) + " image (x is the column, y the row)");
    return *asked;
}

// What the k-th measurement is, for sensor.json.
nlohmann::json measurement_axis(const SensorSettings& s, const TimeAxis& time) {
    nlohmann::json axis = nlohmann::json::array();
    const int K = measurement_count(s, time);
    for (int k = 0; k < K; ++k) {
        switch (s.exposure.type) {
            case ExposureType::Gates:
            case ExposureType::Windows: axis.push_back(s.exposure.windows[std::size_t(k)]); break;
            case ExposureType::Amcw: axis.push_back(s.exposure.phases_deg[std::size_t(k)]); break;
            case ExposureType::Spad: axis.push_back(time.start + k * time.bin_width); break;
        }
    }
    return axis;
}

// measurements.npy, depth.npy (amcw), sensor_plot.png and sensor.json: what a sensor block turns a
// cube (H, W, T, 3) into. Returns K.
int write_sensor_outputs(Staging& staging, const SensorSettings& sensor, const TimeAxis& time, const float* cube,
                         int height, int width, std::array<int, 2> pixel, int threads) {
    const int K = measurement_count(sensor, time);
    const std::size_t H = std::size_t(height), W = std::size_t(width);
    NpyMap measurements(staging.path("measurements.npy"), {H, W, std::size_t(K), 3});
    std::unique_ptr<NpyMap> depth;
    if (sensor.exposure.type == ExposureType::Amcw)
        depth = std::make_unique<NpyMap>(staging.path("depth.npy"), std::vector<std::size_t>{H, W});
    SensorOptions options;
    options.threads = threads;
    apply_sensor(sensor, time, cube, height, width, measurements.data(), depth ? depth->data() : nullptr, options);
    const std::size_t p = std::size_t(pixel[1]) * W + std::size_t(pixel[0]);
    write_sensor_plot(staging.path("sensor_plot.png"), sensor, time, cube + p * std::size_t(time.bins) * 3,
                      measurements.data() + p * std::size_t(K) * 3, pixel[0], pixel[1]);
    nlohmann::json j;
    j["exposure"] = exposure_name(sensor.exposure.type);
    j["measurements"] = K;
    j["axis"] = measurement_axis(sensor, time);
    j["clamp"] = sensor.clamp;
    if (sensor.exposure.type == ExposureType::Spad)
        j["spad"] = {{"photons", sensor.exposure.photons}, {"jitter_fwhm", sensor.exposure.jitter_fwhm},
                     {"dark_rate", sensor.exposure.dark_rate}, {"seed", sensor.exposure.seed}};
    else
        j["noise"] = {{"sigma", sensor.noise.sigma}, {"seed", sensor.noise.seed}};
    j["plot_pixel"] = pixel;
    write_text_file(staging.path("sensor.json"), j.dump(2) + "\n");
    measurements.commit();
    if (depth) depth->commit();
    return K;
}

}  // namespace

double peak_rss_mb() {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line))
        if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
    return 0.0;
}

RenderReport render_file(const std::filesystem::path& scene_file, const RenderOptions& options) {
    using clock = std::chrono::steady_clock;
    const auto start = clock::now();
    RenderReport report;
    const Scene scene = load_scene(scene_file);
    if (!scene.camera) fail_input(scene_file, "camera", "missing: tprf render needs a camera");
    if (options.video && !have_ffmpeg())
        throw Error("--video needs ffmpeg on the PATH (Debian: apt-get install ffmpeg); nothing was rendered");
    const Camera& camera = *scene.camera;
    const std::array<int, 2> pixel = plot_pixel(options.plot_pixel, camera.width, camera.height);
    check_output_dir(options.output);
    report.seconds.load = seconds_since(start);

    auto t = clock::now();
    PatchStats patch_stats;
    PatchOptions patch_options;
    patch_options.progress = options.progress;
    const PatchSet patches = build_patches(scene, patch_options, &patch_stats);
    report.patches = patches.size();
    report.dropped_degenerate = patch_stats.dropped_degenerate;
    report.seconds.patches = seconds_since(t);

    t = clock::now();
    const Visibility visibility(patches);
    LinkOptions link_options;
    link_options.threads = options.threads;
    link_options.progress = options.progress;
    const Links links = compute_links(patches, visibility, link_options);
    report.links = links.size();
    report.seconds.links = seconds_since(t);

    t = clock::now();
    EmitterOptions emitter_options;
    emitter_options.threads = options.threads;
    const Emission emission = compute_emission(scene, patches, links, visibility, emitter_options);
    CameraOptions camera_options;
    camera_options.threads = options.threads;
    camera_options.progress = options.progress;
    const CameraGather gather = prepare_camera(camera, scene, patches, visibility, camera_options);
    double gather_seconds = seconds_since(t);

    Staging staging(options.output);
    const std::size_t T = std::size_t(scene.time.bins), H = std::size_t(camera.height), W = std::size_t(camera.width);
    const std::size_t N = patches.size();
    report.bins = scene.time.bins;
    report.width = camera.width;
    report.height = camera.height;
    NpyMap cube(staging.path("transient.npy"), {H, W, T, 3});
    TransientFilm film(gather, emission, scene.time, scene.solver.delay, cube.data(), -1, false, options.threads);
    std::unique_ptr<NpyMap> patch_cube;
    if (options.patch_profiles) patch_cube = std::make_unique<NpyMap>(staging.path("patch_transient.npy"),
                                                                     std::vector<std::size_t>{N, T, 3});

    SolverOptions solver_options;
    solver_options.delay = scene.solver.delay;
    solver_options.max_bounces = scene.solver.max_bounces;
    const int terms = scene.solver.bounces ? (scene.solver.max_bounces >= 0 ? scene.solver.max_bounces + 1 : 5) : 0;
    solver_options.bounce_terms = terms;
    solver_options.threads = options.threads;
    solver_options.progress = options.progress;
    std::vector<std::unique_ptr<NpyMap>> term_cubes;
    std::vector<std::unique_ptr<TransientFilm>> term_films;
    for (int k = 0; k < terms; ++k) {
        term_cubes.push_back(std::make_unique<NpyMap>(staging.path("transient_bounce_" + std::to_string(k) + ".npy"),
                                                      std::vector<std::size_t>{H, W, T, 3}));
        const bool tail = scene.solver.max_bounces < 0 && k == terms - 1;
        term_films.push_back(std::make_unique<TransientFilm>(gather, emission, scene.time, scene.solver.delay,
                                                             term_cubes.back()->data(), k, tail, options.threads));
    }

    t = clock::now();
    double sink_seconds = 0.0;
    const SolveStats stats = solve_transient(patches, links, emission, scene.time, solver_options, [&](const SolveBlock& b) {
        const auto s0 = clock::now();
        film.add_block(b);
        for (auto& f : term_films) f->add_block(b);
        if (patch_cube)
            for (std::size_t i = 0; i < N; ++i)
                std::copy_n(b.radiosity + i * std::size_t(b.bins) * 3, std::size_t(b.bins) * 3,
                            patch_cube->data() + (i * T + std::size_t(b.first_bin)) * 3);
        sink_seconds += seconds_since(s0);
    });
    report.link_bin_updates = stats.link_bin_updates;
    report.seconds.solve = seconds_since(t) - sink_seconds;
    t = clock::now();
    film.add_direct();
    for (auto& f : term_films) f->add_direct();
    report.seconds.gather = gather_seconds + sink_seconds + seconds_since(t);

    t = clock::now();
    if (options.progress) options.progress("write", 0.0);
    const std::vector<Rgb> steady = solve_steady(patches, links, emission, scene.solver.max_bounces);
    const std::vector<float> image = steady_image(gather, emission, steady);
    write_npy(staging.path("steady.npy"), {H, W, 3}, image.data());
    write_exr(staging.path("steady.exr"), camera.width, camera.height, image.data());
    const std::vector<std::uint8_t> preview = tonemap(camera.width, camera.height, image.data());
    write_png(staging.path("preview.png"), camera.width, camera.height, preview.data());
    if (options.patch_profiles) {
        std::vector<float> flat(N * 3);
        for (std::size_t i = 0; i < N; ++i)
            for (int c = 0; c < 3; ++c) flat[i * 3 + std::size_t(c)] = float(steady[i][c]);
        write_npy(staging.path("patch_steady.npy"), {N, 3}, flat.data());
        write_patches_csv(staging.path("patches.csv"), patches);
    }
    if (options.frames) write_frames(staging.path("frames"), cube.data(), camera.height, camera.width, scene.time.bins);
    if (options.streaks) write_streaks(staging.path("streaks"), cube.data(), camera.height, camera.width, scene.time.bins);
    if (scene.sensor)
        report.measurements = write_sensor_outputs(staging, *scene.sensor, scene.time, cube.data(), camera.height,
                                                   camera.width, pixel, options.threads);
    if (options.video) {
        const std::filesystem::path mp4 = staging.path("light_in_flight.mp4");
        write_video(mp4, mp4.parent_path() / ".video-frames", cube.data(), camera.height, camera.width, scene.time.bins);
    }
    cube.commit();
    if (patch_cube) patch_cube->commit();
    for (auto& c : term_cubes) c->commit();
    report.seconds.write = seconds_since(t);
    report.seconds.total = seconds_since(start);
    report.peak_rss_mb = peak_rss_mb();

    nlohmann::json j;
    j["version"] = TPRF_VERSION;
    j["scene"] = scene_file.string();
    j["patches"] = report.patches;
    j["links"] = report.links;
    j["bins"] = report.bins;
    j["time"] = {{"bins", scene.time.bins}, {"bin_width", scene.time.bin_width}, {"start", scene.time.start},
                 {"unit", unit_name(scene.time.unit)}};
    j["camera"] = {{"width", camera.width}, {"height", camera.height}, {"spp", camera.spp}, {"unwarp", camera.unwarp}};
    j["solver"] = {{"delay", scene.solver.delay == DelayMode::Linear ? "linear" : "nearest"},
                   {"max_bounces", scene.solver.max_bounces}, {"bounce_terms", terms},
                   {"channels", stats.channels}, {"block_bins", stats.block_bins}, {"ring_bins", stats.ring_bins},
                   {"working_mb", double(stats.working_bytes) / 1e6}, {"link_bin_updates", stats.link_bin_updates}};
    j["seconds"] = {{"load", report.seconds.load},   {"patches", report.seconds.patches},
                    {"links", report.seconds.links}, {"solve", report.seconds.solve},
                    {"gather", report.seconds.gather}, {"write", report.seconds.write},
                    {"total", report.seconds.total}};
    if (scene.sensor)
        j["sensor"] = {{"exposure", exposure_name(scene.sensor->exposure.type)}, {"measurements", report.measurements}};
    j["peak_rss_mb"] = report.peak_rss_mb;
    j["dropped_degenerate_faces"] = report.dropped_degenerate;
    write_text_file(staging.path("render.json"), j.dump(2) + "\n");
    staging.publish(render_outputs());
    report.written = staging.names();
    if (options.progress) options.progress("write", 1.0);
    return report;
}

SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options) {
    SceneSummary s;
    auto t0 = std::chrono::steady_clock::now();
    PatchStats patch_stats;
    PatchOptions patch_options;
    patch_options.progress = options.progress;
    const PatchSet patches = build_patches(scene, patch_options, &patch_stats);
    s.patches = patches.size();
    s.dropped_degenerate = patch_stats.dropped_degenerate;
    s.max_edge = patch_stats.max_edge;
    s.seconds_patches = seconds_since(t0);

    t0 = std::chrono::steady_clock::now();
    const Visibility visibility(patches);
    LinkOptions link_options;
    link_options.threads = options.threads;
    link_options.progress = options.progress;
    LinkStats link_stats;
    const Links links = compute_links(patches, visibility, link_options, &link_stats);
    s.links = links.size();
    s.link_bytes = links.bytes();
    s.pairs_tested = link_stats.pairs_tested;
    s.seconds_links = seconds_since(t0);
    return s;
}

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
    report.measurements = write_sensor_outputs(staging, sensor, time, cube.data(), report.height, report.width, pixel,
                                               options.threads);
    staging.publish(kSensorOutputs);
    report.written = staging.names();
    if (options.progress) options.progress("sensor", 1.0);
    report.seconds = seconds_since(start);
    return report;
}

std::string describe_time(const TimeAxis& time) {
    const double start = time.start_m(), width = time.bin_width_m();
    const double end = start + width * time.bins;
    const double ns = 1e9 / kSpeedOfLight;
    char buf[256];
    std::snprintf(buf, sizeof buf, "%d bins of %.6g m from %.6g m to %.6g m of optical path (%.6g ns to %.6g ns)",
                  time.bins, width, start, end, start * ns, end * ns);
    return buf;
}

}  // namespace tprf
