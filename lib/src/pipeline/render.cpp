#include "tprf/pipeline/render.h"

#include "arrays.h"
#include "capture_outputs.h"
#include "cubes.h"
#include "staging.h"
#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/imaging/camera.h"
#include "tprf/imaging/ground_truth.h"
#include "tprf/imaging/film.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/io/atomic_file.h"
#include "tprf/io/hdf5_capture.h"
#include "tprf/io/image_io.h"
#include "tprf/io/npy.h"
#include "tprf/io/sequences.h"
#include "tprf/pipeline/capture.h"
#include "tprf/pipeline/info.h"
#include "tprf/pipeline/ranks.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"
#include "tprf/transport/second_bounce.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/light_sources.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/solver.h"
#include "tprf/transport/steady.h"

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <exception>
#include <memory>
#include <new>
#include <optional>
#include <sstream>

namespace tprf {
namespace {

using Clock = std::chrono::steady_clock;

// Everything a render writes, so that a later run in the same directory can remove what it did not
// write again (docs/outputs.md).
std::vector<std::string> render_outputs() {
    std::vector<std::string> all = {"transient.npy", "steady.npy", "steady.exr", "preview.png", "render.json",
                                    "patches.csv", "patch_transient.npy", "patch_steady.npy", "frames", "streaks",
                                    "light_in_flight.mp4", "transient_bounce_*", "capture.hdf5", "capture.npy",
                                    "aov_*", "sensor-*"};  // sensor-NAME: `tprf sensor` on an earlier cube
    all.insert(all.end(), sensor_outputs().begin(), sensor_outputs().end());
    return all;
}

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

// The products of the stages before the solve, in data-flow order. Filled in place: the visibility
// structure points at the patches.
struct Transport {
    PatchSet patches;
    std::unique_ptr<Visibility> visibility;
    LinkSet links;
    LightSources sources;
    Illumination illumination;
    /// The second bounce, read at each sample's own time (camera.shift_second_bounce), or null.
    std::unique_ptr<SecondBounceLight> second_bounce;
    Gather gather;
};

// Ranks that all build the links (a capture that marches them) each refine a share of the hierarchy
// and exchange their links: the same link set on every rank, built in a rank's share of the time.
LinkShares link_shares(const Scene& scene, const RenderOptions& options) {
    LinkShares shares;
    const RankGroup* ranks = options.ranks;
    if (!ranks || ranks->size() == 1 || !capture_needs_links(scene)) return shares;
    shares.index = ranks->rank();
    shares.count = ranks->size();
    shares.exchange = [ranks](std::span<const std::byte> mine) { return ranks->all_gather(mine); };
    return shares;
}

// What the scene's reading found to say (Scene::warnings), and, when glossy objects get no directional
// cells, what they do then, said once per render that has one.
void note_scene(const Scene& scene, const PatchSet& patches, RenderReport& report) {
    report.warnings.insert(report.warnings.end(), scene.warnings.begin(), scene.warnings.end());
    for (std::string& w : unit_warnings(scene, report.meshes)) report.warnings.push_back(std::move(w));
    const std::size_t glossy = patches.glossy_patches();
    if (glossy == 0 || glossy_rings(scene.links.glossy_resolution, glossy, patches.size()) > 0) return;
    for (std::size_t k = 0; k < scene.objects.size(); ++k)
        if (scene.objects[k].material.glossy()) {
            char why[160];
            if (scene.links.glossy_resolution == kGlossyAuto)
                std::snprintf(why, sizeof why,
                              "links.glossy_resolution \"auto\": %zu glossy patches x %zu patches exceed %.3g pairs; "
                              "an integer 1 to 8 gives them cells",
                              glossy, patches.size(), kAutoGlossyPairs);
            else
                std::snprintf(why, sizeof why, "links.glossy_resolution 0");
            report.warnings.push_back(
                scene.object_path(k) +
                " is glossy: point lights, laser spots and emitters reach the camera, and a capture's laser spot "
                "its sensor points, through its BRDF; the light it passes on to other surfaces and what the camera "
                "sees of its indirect light take it for a Lambertian surface of its hemispherical albedo (" +
                why + "; docs/materials.md, \"Glossy surfaces\")");
            return;
        }
}

// Patches, visibility and (when `links`) the links: what every rank of a split render builds alike.
void build_geometry(const Scene& scene, const RenderOptions& options, bool links, Transport& t,
                    RenderReport& report) {
    auto start = Clock::now();
    PatchStats patch_stats;
    t.patches = build_patches(scene, {options.progress, options.notice}, &patch_stats);
    report.patches = t.patches.size();
    report.meshes = std::move(patch_stats.meshes);
    note_scene(scene, t.patches, report);
    report.seconds.patches = seconds_since(start);

    start = Clock::now();
    t.visibility = scene_visibility(scene, t.patches);
    if (links) {
        LinkOptions link_options;
        link_options.threads = options.threads;
        link_options.progress = options.progress;
        link_options.shares = link_shares(scene, options);
        const double bin_m = march_time(scene).bin_width_m();
        t.links = make_link_set(t.patches, *t.visibility, scene.links, bin_m, link_options);
        add_mirror_links(t.links, t.patches, *t.visibility, link_options, bin_m);
        report.links = t.links.links.size();
    }
    report.seconds.links = seconds_since(start);
}

// The sources' pulses into every row the march solves: with glossy rows (glossy_illumination), lit
// with every glossy patch's albedo taken as 1, so that its pulses carry the irradiance its rows share.
Illumination direct_light(const LightSources& sources, const PatchSet& patches, const GlossyRows& glossy,
                          const Visibility& visibility, const IlluminationOptions& options) {
    if (glossy.empty()) return illuminate(sources, patches, visibility, options);
    PatchSet unit = patches;
    for (std::uint32_t i : glossy.glossy) unit.albedo[i] = Rgb::Ones();
    return glossy_illumination(glossy, patches, sources, illuminate(sources, unit, visibility, options));
}

void build_transport(const Scene& scene, const RenderOptions& options, Transport& t, RenderReport& report) {
    build_geometry(scene, options, render_needs_links(scene), t, report);
    if (!scene.camera) return;  // a capture lights the patches from its own laser points
    const auto start = Clock::now();
    t.sources = light_sources(scene, t.patches, *t.visibility);
    IlluminationOptions light_options;
    light_options.threads = options.threads;
    light_options.merge_bins = &scene.time;
    t.illumination = direct_light(t.sources, t.patches, t.links.glossy, *t.visibility, light_options);
    report.seconds.illumination = seconds_since(start);
    GatherOptions gather_options;
    gather_options.threads = options.threads;
    gather_options.progress = options.progress;
    gather_options.time = &scene.time;
    gather_options.glossy = &t.links.glossy;
    if (scene.camera->shift_second_bounce && t.links.glossy.empty()) {
        t.second_bounce = make_second_bounce_light(t.patches, t.links, t.illumination, scene.time,
                                                   {.delay = scene.solver.delay,
                                                    .max_bounces = scene.solver.max_bounces,
                                                    .threads = options.threads},
                                                   !t.visibility->chains().empty());
        gather_options.second_bounce = t.second_bounce.get();
    }
    report.second_bounce_shifted = t.second_bounce != nullptr;
    t.gather = prepare_camera(*scene.camera, t.patches, t.sources, *t.visibility, gather_options);
    report.seconds.gather = seconds_since(start);
}

// The cubes the solve fills block by block: the transient cube, the per-bounce cubes and the patch
// profiles (Arrays: memory-mapped .npy files in the staging folder, or a result's memory), with the
// films that fill them.
struct Cubes {
    float* cube = nullptr;
    std::unique_ptr<TransientFilm> film;
    std::vector<std::unique_ptr<TransientFilm>> term_films;
    float* patch_cube = nullptr;
};

void open_cubes(const Scene& scene, const RenderOptions& options, const Transport& t, Arrays& arrays, Cubes& c) {
    for (const RenderCube& cube : render_cubes(scene, t.patches.size(), options.patch_profiles)) {
        float* data = arrays.open(cube.name, cube.shape);
        if (cube.kind == RenderCube::Kind::Patches) {
            c.patch_cube = data;
        } else if (cube.kind == RenderCube::Kind::Transient) {
            c.cube = data;
            c.film = std::make_unique<TransientFilm>(t.gather, t.illumination, scene.time, data,
                                                     FilmOptions{.delay = scene.solver.delay, .threads = options.threads});
            c.film->read_second_bounce_apart(t.second_bounce.get());
        } else {  // after the transient cube: its film's taps serve every order's
            c.term_films.push_back(std::make_unique<TransientFilm>(t.gather, t.illumination, scene.time, data,
                                                                   FilmOptions{.delay = scene.solver.delay,
                                                                               .order = cube.order,
                                                                               .last_is_tail = cube.tail,
                                                                               .threads = options.threads,
                                                                               .taps = c.film->taps()}));
            c.term_films.back()->read_second_bounce_apart(t.second_bounce.get(), c.film->shifted_taps());
        }
    }
}

// Bins before the window whose patch light the camera still sees inside it (bins_before_window).
int lead_bins(const TimeAxis& time, const Gather& gather) {
    float longest = 0.0f;
    for (const PixelTap& tap : gather.taps) longest = std::max(longest, tap.leg);
    return bins_before_window(time, double(longest));
}

// The patch profiles themselves (--patch-profiles), as a film whose outputs are the patches: each
// block's bins inside the window, as solved, into the (N, T, 3) cube.
class PatchProfiles : public Film {
public:
    PatchProfiles(float* cube, std::size_t patches, std::size_t bins) : m_cube(cube), m_patches(patches), m_bins(bins) {}
    void add_block(const SolveBlock& b) override {
        const int skip = std::clamp(-b.first_bin, 0, b.bins);  // bins before the window: not written
        for (std::size_t i = 0; i < m_patches; ++i)
            std::copy_n(b.radiosity + (i * std::size_t(b.bins) + std::size_t(skip)) * 3, std::size_t(b.bins - skip) * 3,
                        m_cube + (i * m_bins + std::size_t(b.first_bin + skip)) * 3);
    }
    void finish() override {}

private:
    float* m_cube;
    std::size_t m_patches, m_bins;
};

// Solves and films every block; then the exact direct light. Records the solve and gather times.
SolveStats solve_into_cubes(const Scene& scene, const RenderOptions& options, const Transport& t, Cubes& c,
                            RenderReport& report) {
    SolverOptions solver_options;
    solver_options.delay = scene.solver.delay;
    solver_options.max_bounces = scene.solver.max_bounces;
    solver_options.bounce_terms = bounce_cubes(scene.solver);
    solver_options.threads = options.threads;
    solver_options.progress = options.progress;
    // The patches' light from `lead` bins before the window on (the films read those bins too).
    const int lead = lead_bins(scene.time, t.gather);
    solver_options.first_bin = -lead;
    std::vector<Film*> films{c.film.get()};
    for (auto& f : c.term_films) films.push_back(f.get());
    PatchProfiles profiles(c.patch_cube, t.patches.size(), std::size_t(scene.time.bins));
    if (c.patch_cube) films.push_back(&profiles);
    auto start = Clock::now();
    double sink_seconds = 0.0;
    const SolveStats stats = solve_transient(t.patches, t.links, t.illumination, scene.time, solver_options,
                                             film_sink(films, sink_seconds));
    report.link_bin_updates = stats.link_bin_updates;
    report.seconds.solve = seconds_since(start) - sink_seconds;
    start = Clock::now();
    for (Film* f : films) f->finish();
    c.film->add_direct();
    for (auto& f : c.term_films) f->add_direct();
    report.seconds.gather += sink_seconds + seconds_since(start);
    return stats;
}

// steady.npy, steady.exr and preview.png (the images: files only); with patch profiles also
// patch_steady.npy and patches.csv.
const std::vector<float>& write_steady(const Scene& scene, const RenderOptions& options, const Transport& t,
                                       Arrays& arrays) {
    const Camera& camera = *scene.camera;
    const std::size_t H = std::size_t(camera.height), W = std::size_t(camera.width), N = t.patches.size();
    const std::vector<Rgb> steady = solve_steady(t.patches, t.links, t.illumination, scene.solver.max_bounces);
    const std::vector<float>& image =
        arrays.put("steady", {{H, W, 3}, steady_image(t.gather, t.illumination, steady)}).data;
    if (Staging* staging = arrays.staging()) {
        write_exr(staging->path("steady.exr"), camera.width, camera.height, image.data());
        const std::vector<std::uint8_t> preview = tonemap(camera.width, camera.height, image.data());
        write_png(staging->path("preview.png"), camera.width, camera.height, preview.data());
    }
    if (!options.patch_profiles) return image;
    FloatArray flat{{N, 3}, std::vector<float>(N * 3)};
    for (std::size_t i = 0; i < N; ++i)
        for (int ch = 0; ch < 3; ++ch) flat.data[i * 3 + std::size_t(ch)] = float(steady[i][ch]);
    arrays.put("patch_steady", std::move(flat));
    if (Staging* staging = arrays.staging()) write_patches_csv(staging->path("patches.csv"), t.patches);
    return image;
}

// The share of the light the camera sees (the steady image, which holds every path) that the cube's
// window does not: 1 - (the cube summed over pixels, bins and channels) / (the steady image summed).
// Rows are summed in parallel, each in its own order, and added in row order: the same number for
// any thread count. 0 for a dark image.
double light_outside_window(const float* cube, const std::vector<float>& steady, int height, int width, int bins,
                            int threads) {
    const std::size_t row = std::size_t(width) * std::size_t(bins) * 3;
    std::vector<double> rows(std::size_t(height), 0.0);
    parallel_for(std::size_t(height), {threads, 1, true}, [&](std::size_t r) {
        double sum = 0.0;
        for (std::size_t q = 0; q < row; ++q) sum += cube[r * row + q];
        rows[r] = sum;
    });
    double seen = 0.0, all = 0.0;
    for (const double r : rows) seen += r;
    for (const float v : steady) all += v;
    return all > 0.0 ? std::max(0.0, 1.0 - seen / all) : 0.0;
}

// One line for the user when more than 1% of the camera's light falls outside the window.
std::string window_warning(double share, const TimeAxis& time) {
    char line[400];
    std::snprintf(line, sizeof line,
                  "%.1f%% of the light the camera sees falls outside the time window [%.6g, %.6g] %s (its steady "
                  "image holds it all): more time.bins or a wider bin_width keep later light, an earlier "
                  "time.start earlier light (render.json: camera.light_outside_window)",
                  100.0 * share, time.start, time.end(), unit_name(time.unit));
    return line;
}

// The ground truth maps that options.aovs asks for (aov_*.npy), each pixel's centre ray.
void write_ground_truth(const Scene& scene, const RenderOptions& options, const Transport& t, Arrays& arrays) {
    if (!options.aovs) return;
    GroundTruth g = ground_truth(*scene.camera, t.patches, *t.visibility, options.aovs, options.threads);
    const std::size_t H = std::size_t(g.height), W = std::size_t(g.width);
    if (!g.depth.empty()) arrays.put("aov_depth", FloatArray{{H, W}, std::move(g.depth)});
    if (!g.normal.empty()) arrays.put("aov_normal", FloatArray{{H, W, 3}, std::move(g.normal)});
    if (!g.position.empty()) arrays.put("aov_position", FloatArray{{H, W, 3}, std::move(g.position)});
    if (!g.object.empty()) arrays.put("aov_object", Int32Array{{H, W}, std::move(g.object)});
    if (!g.albedo.empty()) arrays.put("aov_albedo", FloatArray{{H, W, 3}, std::move(g.albedo)});
}

// Frames, streaks, the sensor's measurements and the video: views of the finished cube. In memory,
// only the sensor's measurements.
void write_views(const Scene& scene, const RenderOptions& options, const float* cube, Arrays& arrays,
                 RenderReport& report) {
    const Camera& camera = *scene.camera;
    const int bins = scene.time.bins;
    Staging* staging = arrays.staging();
    const CubeView view{scene.time, cube, camera.height, camera.width};
    if (!staging) {
        if (scene.sensor) report.measurements = measure_cube(*scene.sensor, view, options.threads, arrays).K;
        return;
    }
    if (options.frames) write_frames(staging->path("frames"), cube, camera.height, camera.width, bins);
    if (options.streaks) write_streaks(staging->path("streaks"), cube, camera.height, camera.width, bins);
    if (scene.sensor)
        report.measurements = write_sensor_outputs(
            *staging, *scene.sensor, {view, plot_pixel(options.plot_pixel, camera.width, camera.height)}, options,
            report.warnings);
    if (options.video) {
        const std::filesystem::path mp4 = staging->path("light_in_flight.mp4");
        write_video(mp4, cube, camera.height, camera.width, bins);
    }
}

RenderRecord render_record(const std::filesystem::path& scene_file, const Scene& scene, const SolveStats& stats,
                           const RenderReport& report) {
    RenderRecord r;
    r.scene_file = scene_file;
    r.patches = report.patches;
    r.links = report.links;
    r.time = scene.time;
    r.camera = scene.camera;
    r.solver = scene.solver;
    r.bounce_terms = bounce_cubes(scene.solver);
    r.stats = stats;
    r.seconds = report.seconds;
    if (scene.sensor) r.sensor = scene.sensor->exposure.type;
    r.measurements = report.measurements;
    r.peak_rss_mb = report.peak_rss_mb;
    r.meshes = report.meshes;
    r.second_bounce_shifted = report.second_bounce_shifted;
    r.outside_window = report.outside_window;
    return r;
}

// Everything that can be wrong with a render of `scene` is found before any work: --max-edge applied,
// the camera or capture, ffmpeg for a video, the plot pixel and the estimated peak memory. The same
// checks for a render into a directory and one in memory.
void check_render(Scene& scene, const RenderOptions& options) {
    if (options.max_edge > 0.0) scene.max_edge = options.max_edge;
    if (!scene.camera && !scene.capture)
        fail_input(scene.file, "camera", "missing: tprf render needs a camera (or a capture block)");
    if (!scene.camera) check_capture_flags(options);
    if (options.video && !have_ffmpeg())
        throw Error("--video needs ffmpeg on the PATH (Debian: apt-get install ffmpeg); nothing was rendered");
    if (scene.camera) plot_pixel(options.plot_pixel, scene.camera->width, scene.camera->height);
    check_memory(scene, options, options.patch_profiles);  // before anything heavy is allocated
}

// The scene, loaded and checked (check_render), and (`writes`: on the rank that writes) the output
// directory.
Scene load_render_scene(const std::filesystem::path& scene_file, const RenderOptions& options, bool writes) {
    Scene scene = load_scene(scene_file, options.defines);
    check_render(scene, options);
    if (writes) check_output_dir(options.output);
    return scene;
}

// The scene, loaded and checked on every rank: when any rank fails, every rank stops here, before any
// collective work. The lowest failing rank throws its error (named by rank unless it is rank 0, which
// fails first for a bad scene), the others RankStopped.
Scene load_on_every_rank(const std::filesystem::path& scene_file, const RenderOptions& options,
                         const RankGroup& ranks) {
    if (ranks.size() == 1) return load_render_scene(scene_file, options, true);
    std::optional<Scene> scene;
    std::exception_ptr failure;
    try {
        scene = load_render_scene(scene_file, options, ranks.rank() == 0);
    } catch (...) {
        failure = std::current_exception();
    }
    const int first = ranks.first_failure(failure != nullptr);
    if (first == ranks.size()) return std::move(*scene);
    if (first != ranks.rank()) throw RankStopped("stopped: rank " + std::to_string(first) + " failed");
    if (first == 0) std::rethrow_exception(failure);
    try {
        std::rethrow_exception(failure);
    } catch (const Error& e) {
        throw Error("rank " + std::to_string(first) + " of " + std::to_string(ranks.size()) + ": " + e.what());
    }
}

// A rank other than 0: the patches, the visibility and (when the capture marches) the links, built as
// rank 0 builds them, then its share of the capture's laser points, sent to rank 0. No progress, no
// files.
void render_share(const Scene& scene, RenderOptions options) {
    if (!scene.capture) return;
    options.progress = nullptr;
    const bool links = capture_needs_links(scene);
    Transport t;
    RenderReport unused;
    build_geometry(scene, options, links, t, unused);
    share_capture(scene, options, {t.patches, *t.visibility, links ? &t.links : nullptr});
}

// The camera's outputs: the cubes filled block by block, then the steady image and the views.
SolveStats render_camera(const Scene& scene, const RenderOptions& options, const Transport& transport,
                         Arrays& arrays, RenderReport& report) {
    Cubes cubes;
    const auto open_start = Clock::now();
    open_cubes(scene, options, transport, arrays, cubes);
    report.seconds.gather += seconds_since(open_start);  // the films' taps (and the cubes' files)
    const SolveStats stats = solve_into_cubes(scene, options, transport, cubes, report);
    const auto write_start = Clock::now();
    if (options.progress) options.progress("write", 0.0);
    const std::vector<float>& steady = write_steady(scene, options, transport, arrays);
    const Camera& camera = *scene.camera;
    report.outside_window = light_outside_window(cubes.cube, steady, camera.height, camera.width, scene.time.bins,
                                                 options.threads);
    if (report.outside_window > kWindowLossWarning) report.warnings.push_back(window_warning(report.outside_window, scene.time));
    write_ground_truth(scene, options, transport, arrays);
    write_views(scene, options, cubes.cube, arrays, report);
    arrays.commit();
    report.seconds.write += seconds_since(write_start);
    return stats;
}

// A failure during the shared work (rethrown here): this rank says why, and the launcher ends every
// rank, with the status that the command gives the failure in one process (app/main.cpp).
[[noreturn]] void stop_every_rank(const RankGroup& ranks) {
    const int status = exit_status(std::current_exception());
    std::string what;
    try {
        throw;
    } catch (const Error& e) {
        what = e.what();
    } catch (const Cancelled& e) {
        what = e.what();
    } catch (const OutputError& e) {
        what = e.what();
    } catch (const std::bad_alloc&) {
        what = "out of memory";
    } catch (const std::exception& e) {
        what = std::string("internal error: ") + e.what();
    } catch (...) {
        what = "internal error: an unknown exception";
    }
    ranks.abort("rank " + std::to_string(ranks.rank()) + " of " + std::to_string(ranks.size()) + ": " + what +
                    " (every rank stopped; nothing of this run was kept)",
                status);
}

// The stages after loading, with the arrays going to `arrays` (files or memory); returns what
// render.json records.
RenderRecord run_stages(const std::filesystem::path& scene_file, const Scene& scene, const RenderOptions& options,
                        Clock::time_point start, Arrays& arrays, RenderReport& report) {
    report.seconds.load = seconds_since(start);
    report.bins = scene.time.bins;
    report.width = scene.camera ? scene.camera->width : 0;
    report.height = scene.camera ? scene.camera->height : 0;
    Transport transport;
    build_transport(scene, options, transport, report);
    SolveStats stats;
    if (scene.camera) stats = render_camera(scene, options, transport, arrays, report);
    std::optional<CaptureRecord> capture;
    if (scene.capture)
        capture = render_capture(scene, options,
                                 {transport.patches, *transport.visibility, render_needs_links(scene) ? &transport.links : nullptr},
                                 arrays, report);
    report.seconds.total = seconds_since(start);
    report.peak_rss_mb = peak_rss_mb();
    RenderRecord record = render_record(scene_file, scene, stats, report);
    record.capture = capture;
    return record;
}

// Rank 0 (or the only process): everything after loading, every output written.
RenderReport render_into_directory(const std::filesystem::path& scene_file, const Scene& scene,
                                   const RenderOptions& options, Clock::time_point start) {
    RenderReport report;
    // Before any heavy work: a second run into the same directory is refused now, not at the end.
    Staging staging(options.output);
    try {
        Arrays arrays(staging);
        const RenderRecord record = run_stages(scene_file, scene, options, start, arrays, report);
        write_render_json(staging.path("render.json"), record);
        staging.publish(render_outputs());
        report.written = staging.names();
    } catch (const OutputError& e) {
        throw OutputError(staging.public_message(e.what()));
    }
    if (options.progress) options.progress("write", 1.0);
    return report;
}

}  // namespace

RenderReport render_file(const std::filesystem::path& scene_file, const RenderOptions& options) {
    const auto start = Clock::now();
    const SingleRank alone;
    const RankGroup& ranks = options.ranks ? *options.ranks : alone;
    const Scene scene = load_on_every_rank(scene_file, options, ranks);
    if (ranks.size() == 1) return render_into_directory(scene_file, scene, options, start);
    // From here the ranks wait for each other: a failure on one must end them all, not leave them waiting.
    try {
        if (ranks.rank() == 0) return render_into_directory(scene_file, scene, options, start);
        render_share(scene, options);
        return {};
    } catch (...) {
        stop_every_rank(ranks);
    }
}

RenderResult render_scene(const Scene& given, const RenderOptions& options) {
    const auto start = Clock::now();
    Scene scene = given;
    check_render(scene, options);
    RenderResult result;
    result.time = scene.time;
    Arrays arrays(result);
    const RenderRecord record = run_stages(scene.file, scene, options, start, arrays, result.report);
    result.record = render_json_text(record);
    if (options.progress) options.progress("write", 1.0);
    return result;
}

std::map<std::string, FloatArray> measure(const SensorSettings& sensor, const RenderResult& result, int threads) {
    validate_sensor(sensor, result.time);
    // The camera's cube, or the capture's points as one (capture_cube).
    CaptureCube c;
    const float* cube = nullptr;
    if (const auto camera = result.arrays.find("transient"); camera != result.arrays.end()) {
        cube = camera->second.data.data();
        c.height = int(camera->second.shape[0]);
        c.width = int(camera->second.shape[1]);
    } else if (const auto capture = result.arrays.find("capture"); capture != result.arrays.end()) {
        c = capture_cube(capture->second.shape, capture->second.data.data());
        cube = c.cube.data();
    } else {
        throw Error("the result has neither a transient cube nor a capture to measure");
    }
    RenderResult out;
    Arrays arrays(out);
    measure_cube(sensor, {result.time, cube, c.height, c.width}, threads, arrays);
    return std::move(out.arrays);
}

}  // namespace tprf
