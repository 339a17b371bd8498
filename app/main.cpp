// The tprf command line: parse arguments, call one library entry point, print. No physics here.
#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/pipeline/capture.h"
#include "tprf/pipeline/info.h"
#include "tprf/pipeline/ranks.h"
#include "tprf/imaging/ground_truth.h"
#include "tprf/pipeline/render.h"
#include "tprf/pipeline/sensor_run.h"
#include "tprf/scene/parse_json.h"

#include <CLI/CLI.hpp>

#include <array>
#include <charconv>
#include <cmath>
#include <csignal>
#include <chrono>
#include <optional>
#include <cstdio>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <string_view>
#include <vector>

#include <unistd.h>

namespace {

// The phase that the run was in last, for the message of a cancelled run.
std::string g_phase = "load";

// The time line of `tprf info`, and the march's when a capture marches on wider bins.
void print_time(const tprf::Scene& scene) {
    std::printf("time     %s\n", tprf::describe_time(scene.time).c_str());
    if (scene.capture && scene.capture->march_bin_factor > 1)
        std::printf("march    %s (capture.march_bin_factor %d: the links and the march of orders 4 and up)\n",
                    tprf::describe_time(tprf::march_time(scene)).c_str(), scene.capture->march_bin_factor);
}

// Progress on stderr: a one-line bar with the time left, redrawn at most ten times a second, on a
// terminal; with --progress-lines, one line per phase and per tenth of it (for log files of batch jobs).
class ProgressBar {
public:
    // The bar is drawn only on a terminal: a log file gets the summary alone, not hundreds of redraws.
    ProgressBar(bool quiet, bool lines) : m_lines(lines), m_quiet(quiet || (!lines && !isatty(fileno(stderr)))) {}
    ~ProgressBar() { finish(); }

    void update(std::string_view phase, double fraction) {
        const auto now = std::chrono::steady_clock::now();
        if (phase != m_phase) {
            finish();
            m_phase = phase;
            g_phase = phase;
            m_start = now;
            m_last = {};
            m_tenths = -1;
        }
        if (m_quiet) return;
        const double elapsed = std::chrono::duration<double>(now - m_start).count();
        if (m_lines) {
            const int tenths = int(fraction * 10.0);
            if (tenths <= m_tenths) return;
            m_tenths = tenths;
            std::fprintf(stderr, "tprf: %s %3d%% %.1f s\n", m_phase.c_str(), 10 * tenths, elapsed);
            std::fflush(stderr);
            return;
        }
        if (fraction < 1.0 && now - m_last < std::chrono::milliseconds(100)) return;
        m_last = now;
        const int width = 30, filled = int(fraction * width + 0.5);
        std::string bar(std::size_t(filled), '#');
        bar.resize(std::size_t(width), '.');
        char left[32] = "";
        if (fraction > 0.02 && fraction < 1.0) std::snprintf(left, sizeof left, ", %.0f s left", elapsed * (1 - fraction) / fraction);
        std::fprintf(stderr, "\r%-8s [%s] %3.0f%% %.1f s%s   ", m_phase.c_str(), bar.c_str(), 100 * fraction, elapsed, left);
        std::fflush(stderr);
        m_drawn = true;
    }

    void finish() {
        if (m_drawn) std::fputc('\n', stderr);
        m_drawn = false;
    }

    // A line of its own between the bar's redraws (PipelineOptions::notice).
    void note(const std::string& text) {
        finish();
        std::fprintf(stderr, "tprf: note: %s\n", text.c_str());
        std::fflush(stderr);
    }

private:
    bool m_lines;
    bool m_quiet;
    bool m_drawn = false;
    int m_tenths = -1;
    std::string m_phase;
    std::chrono::steady_clock::time_point m_start{}, m_last{};
};

// SIGINT, SIGTERM and SIGHUP: the first asks the run to stop (every stage checks tprf's cancel flag
// and unwinds, removing its staging files); a second one ends the process at once (its staging folder
// is then removed by the next run into that directory).
extern "C" void on_stop_signal(int sig) {
    if (tprf::cancel_requested()) {
        std::signal(sig, SIG_DFL);
        std::raise(sig);
        return;
    }
    tprf::request_cancel(sig);
}

void install_signal_handlers() {
    struct sigaction stop {};
    stop.sa_handler = on_stop_signal;
    sigemptyset(&stop.sa_mask);
    stop.sa_flags = SA_RESTART;
    for (const int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &stop, nullptr);
    // A file-size limit (ulimit -f) would kill the process; ignored, a write past it fails with EFBIG
    // and the run reports which file could not be written.
    std::signal(SIGXFSZ, SIG_IGN);
}

// The estimate of a render (tprf::estimate_resources), printed before anything heavy runs.
tprf::ResourceEstimate print_estimate(const tprf::Scene& scene, const tprf::PipelineOptions& options) {
    const tprf::ResourceEstimate e = tprf::estimate_resources(scene, options);
    const double limit = double(tprf::memory_limit_bytes(options)), mb = 1e6;
    std::printf("estimate %zu patches, about %.4g links (%s); peak memory %.0f MB in the %s stage, %s %.0f MB\n",
                e.patches, double(e.links), scene.links.method == tprf::LinkMethod::Flat ? "flat" : "hierarchical",
                double(e.peak_bytes) / mb, e.peak_stage.c_str(),
                double(e.peak_bytes) > limit ? "OVER the render limit of" : "limit", limit / mb);
    std::printf("estimate MB: base %.0f, meshes %.0f, patches %.0f, visibility %.0f, links %.0f (+%.0f while built), "
                "pulses %.0f, camera %.0f, solver %.0f, cubes %.0f, write %.0f\n",
                double(e.base_bytes) / mb, double(e.mesh_bytes) / mb, double(e.patch_bytes) / mb,
                double(e.visibility_bytes) / mb, double(e.link_bytes) / mb, double(e.link_build_bytes) / mb,
                double(e.illumination_bytes) / mb, double(e.gather_bytes) / mb, double(e.solver_bytes) / mb,
                double(e.cube_bytes) / mb, double(e.write_bytes) / mb);
    const tprf::PhaseSeconds& s = e.seconds;
    std::printf("estimate seconds: patches %.2f, links %.2f, gather %.2f, solve %.2f, write %.2f, total %.2f\n",
                s.patches, s.links, s.gather, s.solve, s.write, s.total);
    if (e.capture_batch > 0)
        std::printf("estimate capture: %zu marches of up to %d laser points each (the batch that fits the limit)\n",
                    e.capture_marches, e.capture_batch);
    std::fflush(stdout);
    return e;
}

// What was dropped from each mesh file, one line per mesh (even with --quiet: the geometry is not
// quite what the file holds).
void print_mesh_repairs(const std::vector<tprf::MeshReport>& meshes) {
    for (const tprf::MeshReport& m : meshes)
        if (m.repairs.any())
            std::fprintf(stderr, "tprf: warning: mesh file '%s' (objects[%zu].file): dropped %s\n", m.file.c_str(),
                         m.object, tprf::describe(m.repairs).c_str());
}

// One line per mesh file: its size, its bounding box after the transform and what was dropped.
void print_meshes(const std::vector<tprf::MeshReport>& meshes) {
    for (const tprf::MeshReport& m : meshes) std::printf("mesh     %s\n", tprf::describe(m).c_str());
}

// Warnings are printed even with --quiet: they say that something asked for was not made.
void print_warnings(const std::vector<std::string>& warnings) {
    for (const std::string& w : warnings) std::fprintf(stderr, "tprf: warning: %s\n", w.c_str());
}

int run_info(const std::string& scene_file, tprf::PipelineOptions options, bool meshes_only, bool estimate_only,
             bool quiet, bool progress_lines) {
    tprf::Scene scene = tprf::load_scene(scene_file, options.defines);
    print_warnings(scene.warnings);
    if (options.max_edge > 0.0) scene.max_edge = options.max_edge;
    ProgressBar bar(quiet, progress_lines);
    if (!quiet) options.notice = [&](const std::string& text) { bar.note(text); };
    std::printf("scene    %s\n", scene_file.c_str());
    std::fflush(stdout);
    if (meshes_only) {
        const std::vector<tprf::MeshReport> meshes = tprf::describe_meshes(scene);
        print_meshes(meshes);
        print_mesh_repairs(meshes);
        return 0;
    }
    const tprf::ResourceEstimate e = print_estimate(scene, options);
    print_meshes(e.meshes);
    print_mesh_repairs(e.meshes);
    // Without the links (asked for, or when building them to count them would exceed the limit) the
    // counts stay estimates.
    const bool over = e.link_stage_bytes > tprf::memory_limit_bytes(options);
    if (estimate_only || over) {
        if (const std::string note = tprf::default_size_note(scene, e.diagonal); !note.empty() && options.notice)
            options.notice(note);
        print_warnings(tprf::unit_warnings(scene, e.meshes));
        std::printf("patches  %zu (counted; max_edge %.6g m)\n", e.patches, e.max_edge);
        if (!estimate_only)
            std::printf("links    not built: the link stage needs about %.0f MB, over the limit of %.0f MB\n",
                        double(e.link_stage_bytes) / 1e6, double(tprf::memory_limit_bytes(options)) / 1e6);
        print_time(scene);
        return 0;
    }
    options.progress = [&](std::string_view phase, double f) { bar.update(phase, f); };
    const tprf::SceneSummary s = tprf::describe_scene(scene, options);
    bar.finish();
    print_warnings(s.warnings);
    std::printf("patches  %zu (max_edge %.6g m)\n", s.patches, s.max_edge);
    if (scene.links.method == tprf::LinkMethod::Flat)
        std::printf("links    %zu (%.1f MB; %llu facing pairs tested)\n", s.links, double(s.link_bytes) / 1e6,
                    static_cast<unsigned long long>(s.pairs_tested));
    else
        std::printf("links    %zu (%.1f MB; %zu clusters; %llu patch-to-patch, %llu with a cluster in %llu node pairs "
                    "judged)\n",
                    s.links, double(s.link_bytes) / 1e6, s.clusters, static_cast<unsigned long long>(s.patch_links),
                    static_cast<unsigned long long>(s.cluster_links), static_cast<unsigned long long>(s.candidates));
    if (s.mirror_links > 0)
        std::printf("mirrors  %llu of the links go through mirrors and glass\n",
                    static_cast<unsigned long long>(s.mirror_links));
    if (s.glossy_rows > 0)
        std::printf("glossy   %zu patches with directional cells of %d rings, %zu rows of the march "
                    "(links.glossy_resolution %s)\n",
                    s.glossy_patches, s.glossy_rings, s.glossy_rows,
                    scene.links.glossy_resolution == tprf::kGlossyAuto ? "\"auto\""
                                                                        : std::to_string(scene.links.glossy_resolution).c_str());
    print_time(scene);
    std::printf("seconds  patches %.2f, links %.2f\n", s.seconds_patches, s.seconds_links);
    return 0;
}

int run_render(const std::string& scene_file, tprf::RenderOptions options, bool quiet, bool progress_lines) {
    quiet = quiet || options.ranks->rank() != 0;  // rank 0 alone prints
    ProgressBar bar(quiet, progress_lines);
    options.progress = [&](std::string_view phase, double f) { bar.update(phase, f); };
    if (!quiet) options.notice = [&](const std::string& text) { bar.note(text); };
    const tprf::RenderReport r = tprf::render_file(scene_file, options);
    bar.finish();
    print_mesh_repairs(r.meshes);
    if (options.ranks->rank() == 0) print_warnings(r.warnings);  // every rank reads the same scene
    if (!quiet && r.capture_pairs > 0)
        std::fprintf(stderr, "tprf: capture of %zu laser-sensor pairs x %d bins -> %s\n", r.capture_pairs, r.bins,
                     (options.output / "capture.hdf5").string().c_str());
    if (!quiet)
        std::fprintf(stderr,
                     "tprf: %zu patches, %zu links, %dx%d pixels x %d bins in %.2f s (patches %.2f, links %.2f, "
                     "solve %.2f, gather %.2f, write %.2f), peak %.0f MB -> %s\n",
                     r.patches, r.links, r.width, r.height, r.bins, r.seconds.total, r.seconds.patches,
                     r.seconds.links, r.seconds.solve, r.seconds.gather, r.seconds.write, r.peak_rss_mb,
                     options.output.string().c_str());
    return 0;
}

int run_sensor(const tprf::SensorRunOptions& options, bool quiet) {
    const tprf::SensorReport r = tprf::apply_sensor_file(options);
    print_warnings(r.warnings);
    if (!quiet)
        std::fprintf(stderr, "tprf: %dx%d pixels x %d measurements in %.2f s -> %s\n", r.width, r.height,
                     r.measurements, r.seconds, r.folder.string().c_str());
    return 0;
}

// "X,Y" -> {X, Y}, for --plot-pixel.
std::string parse_pixel(const std::string& text, std::optional<std::array<int, 2>>& out) {
    const std::string error = "expected X,Y (column, row: non-negative integers), got \"" + text + "\"";
    const std::size_t comma = text.find(',');
    if (comma == std::string::npos) return error;
    int xy[2] = {0, 0};
    const std::string parts[2] = {text.substr(0, comma), text.substr(comma + 1)};
    for (int k = 0; k < 2; ++k) {
        const char* first = parts[k].data();
        const char* last = first + parts[k].size();
        const auto [end, ec] = std::from_chars(first, last, xy[k]);
        if (ec != std::errc() || end != last) return error;
    }
    out = std::array<int, 2>{xy[0], xy[1]};
    return "";
}

// The message of a run that threw (rethrown here), and its exit status (tprf::exit_status).
int report_failure() {
    const int status = tprf::exit_status(std::current_exception());
    try {
        throw;
    } catch (const tprf::RankStopped&) {
        // another rank of an MPI run failed first and said why
    } catch (const tprf::Error& e) {
        std::fprintf(stderr, "tprf: error: %s\n", e.what());
    } catch (const tprf::Cancelled& e) {
        std::fprintf(stderr, "tprf: %s in the %s stage: nothing of this run was kept; earlier outputs are untouched\n",
                     e.what(), g_phase.c_str());
    } catch (const tprf::OutputError& e) {
        std::fprintf(stderr, "tprf: error: %s; nothing of this run was kept, earlier outputs are untouched\n", e.what());
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr,
                     "tprf: error: out of memory in the %s stage (the estimate of `tprf info` was exceeded, or other "
                     "processes took the memory); nothing of this run was kept. Lower --max-memory to have such "
                     "renders refused before they start, or make the scene smaller (patches.max_edge, time.bins)\n",
                     g_phase.c_str());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "tprf: internal error: %s\n", e.what());
    } catch (...) {
        std::fprintf(stderr, "tprf: internal error: an unknown exception\n");
    }
    return status;
}

// A flag's number must be positive and finite: "--max-edge: must be a positive, finite number, got -1".
CLI::Validator positive_finite() {
    return CLI::Validator(
        [](std::string& text) {
            char* end = nullptr;
            const double v = std::strtod(text.c_str(), &end);
            if (end == text.c_str() || *end != '\0' || !std::isfinite(v) || v <= 0.0)
                return "must be a positive, finite number, got " + text;
            return std::string();
        },
        "POSITIVE");
}

// --plot-pixel X,Y into `target`.
void add_plot_pixel(CLI::App& command, std::optional<std::array<int, 2>>& target) {
    command.add_option_function<std::string>(
        "--plot-pixel",
        [&target](const std::string& text) {
            const std::string error = parse_pixel(text, target);
            if (!error.empty()) throw CLI::ValidationError("--plot-pixel", error);
        },
        "pixel X,Y (column, row) of sensor_plot.png (default: the centre)");
}

// --plot-scale auto|log|linear: the y axes of sensor_plot.png.
void add_plot_scale(CLI::App& command, std::string& target) {
    command.add_option("--plot-scale", target,
                       "y axes of sensor_plot.png: auto (log where the values span more than 1e3), log or linear")
        ->check(CLI::IsMember({"auto", "log", "linear"}));
}

// -D name=value (repeatable) into `target`: the parameters of a Mitsuba XML scene ($name).
void add_defines(CLI::App& command, tprf::XmlDefines& target) {
    command
        .add_option_function<std::vector<std::string>>(
            "-D",
            [&target](const std::vector<std::string>& items) {
                for (const std::string& item : items) {
                    const std::size_t eq = item.find('=');
                    if (eq == std::string::npos || eq == 0)
                        throw CLI::ValidationError("-D", "expected name=value, got \"" + item + "\"");
                    target[item.substr(0, eq)] = item.substr(eq + 1);
                }
            },
            "name=value: a parameter of a Mitsuba XML scene ($name), over its <default>; repeatable")
        ->allow_extra_args(false);
}

// The flags of `tprf render` that choose its extra outputs and its memory limit.
void add_render_flags(CLI::App& rend, tprf::RenderOptions& render) {
    rend.add_flag("--patch-profiles", render.patch_profiles, "also write patches.csv, patch_transient.npy, patch_steady.npy");
    rend.add_flag("--frames", render.frames, "also write frames/frame_NNNNN.exr, one per time bin");
    rend.add_flag("--streaks", render.streaks, "also write streaks/row_NNNN.exr, one x-t image per image row");
    rend.add_flag("--video", render.video, "also write light_in_flight.mp4 (needs ffmpeg)");
    rend.add_option_function<std::string>(
        "--aov",
        [&render](const std::string& list) {
            try {
                render.aovs = tprf::parse_aov_list(list, "--aov");
            } catch (const tprf::Error& e) {
                throw CLI::ValidationError(e.what());
            }
        },
        "LIST: also write ground truth maps aov_NAME.npy for each pixel's centre ray: any of depth, normal, "
        "position, object, albedo (comma-separated), or all");
    rend.add_option("--max-memory", render.max_memory_gb,
                    "refuse (exit 2, before allocating) a render whose estimated peak memory exceeds GB "
                    "(default: 80% of the memory available)")
        ->check(positive_finite());
    add_plot_pixel(rend, render.plot_pixel);
    add_plot_scale(rend, render.plot_scale);
}

// `tprf sensor OUTDIR SENSOR.json` and its flags, into `sensor` (OUTDIR and the file into the strings).
CLI::App* add_sensor_command(CLI::App& app, tprf::SensorRunOptions& sensor, std::string& render_dir,
                             std::string& sensor_file) {
    auto* sens = app.add_subcommand("sensor", "apply a sensor block to a cube of an existing render, into OUTDIR/sensor-NAME/");
    sens->add_option("outdir", render_dir, "a directory written by tprf render")->required();
    sens->add_option("sensor", sensor_file, "sensor JSON: the block itself or {\"sensor\": block}")->required();
    add_plot_pixel(*sens, sensor.plot_pixel);
    add_plot_scale(*sens, sensor.plot_scale);
    sens->add_option("--cube", sensor.cube,
                     "the cube measured: transient (default), transient_bounce_K or capture (OUTDIR/NAME.npy)");
    sens->add_option("--name", sensor.name,
                     "the outputs go to OUTDIR/sensor-NAME/ (default: the sensor file's name without .json)");
    return sens;
}

// Everything but joining the ranks: parse the arguments, run the subcommand, print. `ranks`: the MPI
// ranks that share a render (docs/mpi.md), or this process alone; rank 0 alone runs info and sensor.
int run_tprf(int argc, char** argv, const tprf::RankGroup& ranks) {
    CLI::App app{"tprf: transient radiosity, light in flight"};
    app.require_subcommand(1);
    app.fallthrough();  // --threads and --quiet may also follow the subcommand
    app.set_version_flag("--version", "tprf " TPRF_VERSION, "print the version (tprf X.Y.Z) and exit");
    std::string scene_file;
    int threads = 0;
    bool quiet = false;
    app.add_option("--threads", threads, "worker threads (0: all cores)")->check(CLI::Range(0, 4096));
    app.add_flag("-q,--quiet", quiet, "no progress bar");
    double max_edge = 0.0;
    app.add_option("--max-edge", max_edge, "patch size L in metres: replaces the scene's patches.max_edge")
        ->check(positive_finite());
    bool progress_lines = false;
    app.add_flag("--progress-lines", progress_lines,
                 "progress as lines, one per stage and per tenth of it, even when stderr is not a terminal (logs)");
    auto* info = app.add_subcommand("info", "print the estimated peak memory and seconds of a render, then the patch "
                                            "count, link count, link memory and the time window");
    info->add_option("scene", scene_file, "scene file: JSON, or Mitsuba 3 XML (.xml)")->required();
    tprf::PipelineOptions info_options;
    info->add_option("--max-memory", info_options.max_memory_gb, "the render limit to compare the estimate with, GB")
        ->check(positive_finite());
    add_defines(*info, info_options.defines);
    bool info_meshes = false;
    info->add_flag("--meshes", info_meshes,
                   "only load the mesh files and print, per mesh, its vertices, faces, triangles, bounding box "
                   "and what was dropped (no estimate, no links)");
    bool info_estimate = false;
    info->add_flag("--estimate-only", info_estimate,
                   "print the estimate, the meshes, the patch count and the time window, and build no links (seconds "
                   "where the links of a large scene take minutes)");
    tprf::RenderOptions render;
    std::string output;
    auto* rend = app.add_subcommand("render", "render a scene: transient cube, steady image and the flagged extras");
    rend->add_option("scene", scene_file, "scene file: JSON, or Mitsuba 3 XML (.xml)")->required();
    add_defines(*rend, render.defines);
    rend->add_option("-o,--output", output, "output directory (created if missing)")->required();
    add_render_flags(*rend, render);
    tprf::SensorRunOptions sensor;
    std::string render_dir, sensor_file;
    CLI::App* sens = add_sensor_command(app, sensor, render_dir, sensor_file);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int rc = app.exit(e);
        return rc == 0 ? 0 : 2;
    }
    if (ranks.rank() != 0 && !rend->parsed()) return 0;
    render.ranks = &ranks;
    install_signal_handlers();
    try {
        if (info->parsed()) {
            info_options.threads = threads;
            info_options.max_edge = max_edge;
            return run_info(scene_file, info_options, info_meshes, info_estimate, quiet, progress_lines);
        }
        if (rend->parsed()) {
            render.output = output;
            render.threads = threads;
            render.max_edge = max_edge;
            return run_render(scene_file, render, quiet, progress_lines);
        }
        if (sens->parsed()) {
            sensor.render_dir = render_dir;
            sensor.sensor_file = sensor_file;
            sensor.threads = threads;
            return run_sensor(sensor, quiet);
        }
        return 2;
    } catch (...) {
        return report_failure();
    }
}

}  // namespace

// MPI is joined around everything else (under mpirun or srun; a plain run never initialises it) and
// finalised when the group goes.
int main(int argc, char** argv) {
    tprf::start_threads();
    std::unique_ptr<tprf::RankGroup> ranks;
    try {
        ranks = tprf::join_ranks();
    } catch (const tprf::Error& e) {
        std::fprintf(stderr, "tprf: error: %s\n", e.what());
        return 2;
    }
    return run_tprf(argc, argv, *ranks);
}
