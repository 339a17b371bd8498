/// tprf_harness: how the cost of `tprf render` grows with patches, time bins and pixels, and what
/// accuracy that cost buys, measured in one run on the Cornell box (meshes/cornell-box.json).
///
/// tprf_bench times the link and solver kernels in isolation; this harness times whole renders as a
/// user runs them, each one a separate `tprf render` process (so that render.json's peak RSS is that
/// render's own), and sets them against the machine's ceilings measured in the same run:
///  1. FMA peak and STREAM bandwidth on the render threads;
///  2. sweeps over max_edge (patches), time bins (bin_width fixed at the scene's 0.005 m, so more
///     bins = a longer window) and pixels, one row per distinct configuration: phase seconds, solver throughput
///     against the FMA peak, peak memory against what links + solver state + cube need;
///  3. the relative L2 error of the transient cube, of its 16-bin sums and of the steady image at
///     max_edge h against a render at h/2, set against the render's seconds;
///  4. harness.csv, accuracy.csv, scaling.png (drawn by python/tprf_plots.py: log-log, least-squares
///     exponents in the legends) and a section of bench/RESULTS.md between `<!-- harness:begin -->`
///     and `<!-- harness:end -->`.
/// Nothing is asserted: it measures and reports.

#include "machine.h"
#include "tprf/io/atomic_file.h"
#include "tprf/io/npy.h"
#include "tprf/io/plots.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

extern char** environ;

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

/// What a render changes in the scene; everything else (spp 4) is the scene's.
struct Config {
    double max_edge = 0.0;      ///< patches.max_edge, metres
    int bins = 0;               ///< time.bins (time.bin_width is the plan's, the same for every render)
    int width = 0, height = 0;  ///< camera pixels
    bool operator==(const Config&) const = default;
};

/// The configurations of one harness run.
struct Plan {
    double bin_width = 0.0;           ///< metres, for every bin count: more bins = a longer window
    std::vector<double> patch_edges;  ///< patches sweep, at patch_bins and small x small pixels
    int patch_bins = 0;
    std::vector<int> bin_counts;      ///< bins sweep, at each of bin_edges, small x small pixels
    std::vector<double> bin_edges;
    int small = 0;
    int large = 0;                    ///< pixels sweep: large x large at pixel_edge, each of pixel_bins
    double pixel_edge = 0.0;
    std::vector<int> pixel_bins;
    std::vector<double> accuracy_edges;  ///< accuracy: h against h/2, accuracy_bins, small x small
    int accuracy_bins = 0;
};

Plan full_plan() {
    return {0.005, {0.11, 0.077, 0.054, 0.038, 0.0265}, 2048, {512, 2048, 8192}, {0.054, 0.11}, 96,
            256, 0.054, {512, 2048}, {0.15, 0.11, 0.077, 0.054}, 2048};
}

// Wider bins than the scene's: 64 bins of 0.005 m end before the first light reaches the camera
// (1.9 m of path), and an all-zero reference cube has no relative error.
Plan quick_plan() {
    return {0.04, {0.2, 0.15}, 128, {64, 128}, {0.2, 0.15}, 24, 32, 0.2, {64, 128}, {0.2, 0.15}, 128};
}

/// Consecutive bins summed for the coarse-time error: what most comparisons look at.
constexpr int kCoarseBins = 16;

constexpr std::array<const char*, 7> kPhases{"load", "patches", "links", "solve", "gather", "write", "total"};
enum Phase { kLoad, kPatches, kLinks, kSolve, kGather, kWrite, kTotal };

/// A JSON file the harness wrote or ships (render.json, the Cornell box scene).
json read_json(const fs::path& file) {
    std::ifstream in(file);
    if (!in) throw std::runtime_error(file.string() + ": cannot read");
    return json::parse(in);
}

/// One render's render.json, and the sweeps it belongs to.
struct Run {
    std::string label;  ///< "patches", "bins", "pixels", joined with '+' when shared
    Config config;
    double patches = 0, links = 0;
    std::array<double, kPhases.size()> seconds{};
    double peak_rss_mb = 0, link_bin_updates = 0, working_mb = 0, channels = 0;
    bool linear_delay = true;
    fs::path dir{};  ///< the render's output directory, until the caller removes it
};

/// Relative L2 errors of a render at max_edge h against its reference at h/2.
struct Accuracy {
    double max_edge = 0, patches = 0, seconds = 0;
    double transient = 0, coarse = 0, steady = 0;
};

/// `v` with `decimals` digits after the point; general(): the shortest of 6 significant digits.
std::string num(double v, int decimals) {
    std::ostringstream os;
    os << std::fixed << std::setprecision(decimals) << v;
    return os.str();
}

std::string general(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

/// Values the CSV and the table derive from a run (units in the names).
struct Derived {
    double updates_per_s, gfma_s, fraction_of_peak, link_mb, cube_mb, needed_mb, peak_over_needed;
};

Derived derive(const Run& r, double peak_gfma) {
    Derived d{};
    d.updates_per_s = r.seconds[kSolve] > 0 ? r.link_bin_updates / r.seconds[kSolve] : 0.0;
    // The long-link kernel does two FMAs per bin and channel with linear delays, one with nearest.
    const double fma_per_update = (r.linear_delay ? 2.0 : 1.0) * r.channels;
    d.gfma_s = d.updates_per_s * fma_per_update / 1e9;
    d.fraction_of_peak = peak_gfma > 0 ? d.gfma_s / peak_gfma : 0.0;
    d.link_mb = r.links * 12.0 / 1e6;  // source (uint32), form factor and distance (float) per link
    d.cube_mb = double(r.config.width) * r.config.height * r.config.bins * 3 * 4 / 1e6;
    d.needed_mb = d.link_mb + r.working_mb + d.cube_mb;
    d.peak_over_needed = r.peak_rss_mb / d.needed_mb;
    return d;
}

/// Least-squares slope of log y against log x over the positive pairs; NaN with fewer than two.
double log_slope(const std::vector<double>& x, const std::vector<double>& y) {
    std::vector<std::array<double, 2>> p;
    for (std::size_t i = 0; i < std::min(x.size(), y.size()); ++i)
        if (x[i] > 0 && y[i] > 0) p.push_back({std::log(x[i]), std::log(y[i])});
    if (p.size() < 2) return std::numeric_limits<double>::quiet_NaN();
    double mx = 0, my = 0;
    for (const auto& [u, v] : p) mx += u, my += v;
    mx /= double(p.size()), my /= double(p.size());
    double sxy = 0, sxx = 0;
    for (const auto& [u, v] : p) sxy += (u - mx) * (v - my), sxx += (u - mx) * (u - mx);
    return sxx > 0 ? sxy / sxx : std::numeric_limits<double>::quiet_NaN();
}

std::string slope_text(double s) { return std::isfinite(s) ? num(s, 2) : "n/a"; }

/// Runs `args` (args[0] the program's path, no shell) and waits; throws unless it exits with 0.
void run_process(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    pid_t pid = 0;
    if (const int e = posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ); e != 0)
        throw std::runtime_error("cannot start " + args[0] + ": " + std::strerror(e));
    int status = 0;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) throw std::runtime_error("waitpid failed: " + std::string(std::strerror(errno)));
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return;
    std::string command;
    for (const std::string& a : args) command += (command.empty() ? "" : " ") + a;
    throw std::runtime_error(command + (WIFEXITED(status)
                                            ? ": exited with status " + std::to_string(WEXITSTATUS(status))
                                            : ": killed by signal " + std::to_string(WTERMSIG(status))));
}

/// A scratch directory inside the output directory (not /tmp, which may be RAM), removed with all
/// the render directories left in it when the harness ends, also on failure.
class Scratch {
public:
    explicit Scratch(const fs::path& parent) {
        std::string name = (parent / ".harness-scratch-XXXXXX").string();
        if (!mkdtemp(name.data())) throw std::runtime_error(name + ": cannot create: " + std::strerror(errno));
        m_dir = name;
    }
    ~Scratch() {
        std::error_code ec;
        fs::remove_all(m_dir, ec);
    }
    Scratch(const Scratch&) = delete;
    Scratch& operator=(const Scratch&) = delete;
    const fs::path& dir() const { return m_dir; }

private:
    fs::path m_dir;
};

/// A render's render.json.
Run read_run(const fs::path& dir, const Config& c, const std::string& label) {
    const json j = read_json(dir / "render.json");
    Run r;
    r.label = label;
    r.config = c;
    r.patches = j.at("patches").get<double>();
    r.links = j.at("links").get<double>();
    for (std::size_t k = 0; k < kPhases.size(); ++k) r.seconds[k] = j.at("seconds").at(kPhases[k]).get<double>();
    r.peak_rss_mb = j.at("peak_rss_mb").get<double>();
    const json& s = j.at("solver");
    r.link_bin_updates = s.at("link_bin_updates").get<double>();
    r.working_mb = s.at("working_mb").get<double>();
    r.channels = s.at("channels").get<double>();
    r.linear_delay = s.at("delay").get<std::string>() == "linear";
    r.dir = dir;
    return r;
}

/// Renders configurations of the Cornell box with `tprf render`, one process each, with a
/// progress line per render on stderr.
class Renderer {
public:
    Renderer(const fs::path& scratch, double bin_width, int threads, int total)
        : m_scratch(scratch), m_bin_width(bin_width), m_threads(threads), m_total(total) {
        const fs::path file = fs::path(TPRF_SOURCE_DIR) / "meshes" / "cornell-box.json";
        m_scene = read_json(file);
        for (json& object : m_scene.at("objects"))  // the copy lives elsewhere: mesh paths made absolute
            if (object.value("type", "") == "mesh" && fs::path(object.at("file").get<std::string>()).is_relative())
                object["file"] = (file.parent_path() / object.at("file").get<std::string>()).string();
    }

    /// Renders `c` into a fresh directory under the scratch directory (Run::dir, which the caller
    /// removes once read) and reads its render.json.
    Run render(const Config& c, const std::string& label, const std::string& what) {
        ++m_done;
        std::fprintf(stderr, "[%d/%d] %s: max_edge %s, %d bins, %dx%d ... ", m_done, m_total, what.c_str(),
                     general(c.max_edge).c_str(), c.bins, c.width, c.height);
        std::fflush(stderr);
        json scene = m_scene;
        scene["patches"]["max_edge"] = c.max_edge;
        scene["time"]["bins"] = c.bins;
        scene["time"]["bin_width"] = m_bin_width;
        scene["camera"]["width"] = c.width;
        scene["camera"]["height"] = c.height;
        const fs::path scene_file = m_scratch / ("scene-" + std::to_string(m_done) + ".json");
        const fs::path out = m_scratch / ("render-" + std::to_string(m_done));
        if (!(std::ofstream(scene_file) << scene.dump(2) << '\n'))
            throw std::runtime_error(scene_file.string() + ": cannot write");
        const auto t0 = std::chrono::steady_clock::now();
        try {
            run_process({TPRF_BINARY, "render", scene_file.string(), "-o", out.string(), "-q", "--threads",
                         std::to_string(m_threads)});
        } catch (const std::exception& e) {
            std::fprintf(stderr, "failed\n");
            throw std::runtime_error("render " + std::to_string(m_done) + " failed (tprf's own message, if any, is "
                                     "above): " + e.what());
        }
        const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        fs::remove(scene_file);
        Run r = read_run(out, c, label);
        std::fprintf(stderr, "%.1f s (%.0f patches)\n", wall, r.patches);
        return r;
    }

private:
    json m_scene;
    fs::path m_scratch;
    double m_bin_width;
    int m_threads, m_total, m_done = 0;
};

/// The sweeps' configurations in order, each distinct one once, labelled with every sweep it is in.
std::vector<Run> planned_sweeps(const Plan& p) {
    std::vector<Run> runs;
    auto add = [&](const std::string& label, Config c) {
        for (Run& r : runs)
            if (r.config == c) {
                r.label += "+" + label;
                return;
            }
        runs.push_back(Run{label, c});
    };
    for (double e : p.patch_edges) add("patches", {e, p.patch_bins, p.small, p.small});
    for (double e : p.bin_edges)
        for (int b : p.bin_counts) add("bins", {e, b, p.small, p.small});
    for (int b : p.pixel_bins) add("pixels", {p.pixel_edge, b, p.large, p.large});
    return runs;
}

const Run& find_run(const std::vector<Run>& runs, const Config& c) {
    for (const Run& r : runs)
        if (r.config == c) return r;
    throw std::logic_error("no run for a planned configuration");
}

/// Sums of squared differences and of squared reference values, for a relative L2 error.
struct L2 {
    double diff2 = 0, ref2 = 0;
    void add(double u, double ref) { diff2 += (u - ref) * (u - ref), ref2 += ref * ref; }
    /// NaN when the reference is all zero.
    double relative() const { return ref2 > 0 ? std::sqrt(diff2 / ref2) : std::numeric_limits<double>::quiet_NaN(); }
};

/// Relative L2 errors of `dir`'s transient cube (H, W, T, 3), of its sums over kCoarseBins
/// consecutive bins, and of its steady image, against `ref`'s. The cubes are memory-mapped.
Accuracy compare(const fs::path& dir, const fs::path& ref) {
    Accuracy a;
    {
        const tprf::NpyView c(dir / "transient.npy"), r(ref / "transient.npy");
        if (c.shape() != r.shape() || c.shape().size() != 4)
            throw std::runtime_error("transient.npy shapes differ between " + dir.string() + " and " + ref.string());
        const std::size_t pixels = c.shape()[0] * c.shape()[1], bins = c.shape()[2], ch = c.shape()[3];
        L2 fine, coarse;
        std::vector<double> sum_c(ch), sum_r(ch);
        for (std::size_t p = 0; p < pixels; ++p)
            for (std::size_t t0 = 0; t0 < bins; t0 += kCoarseBins) {
                std::fill(sum_c.begin(), sum_c.end(), 0.0);
                std::fill(sum_r.begin(), sum_r.end(), 0.0);
                for (std::size_t t = t0; t < std::min(bins, t0 + kCoarseBins); ++t)
                    for (std::size_t k = 0; k < ch; ++k) {
                        const std::size_t i = (p * bins + t) * ch + k;
                        fine.add(c.data()[i], r.data()[i]);
                        sum_c[k] += c.data()[i], sum_r[k] += r.data()[i];
                    }
                for (std::size_t k = 0; k < ch; ++k) coarse.add(sum_c[k], sum_r[k]);
            }
        a.transient = fine.relative(), a.coarse = coarse.relative();
    }
    const tprf::NpyView c(dir / "steady.npy"), r(ref / "steady.npy");
    if (c.shape() != r.shape()) throw std::runtime_error("steady.npy shapes differ");
    L2 steady;
    for (std::size_t i = 0; i < c.size(); ++i) steady.add(c.data()[i], r.data()[i]);
    a.steady = steady.relative();
    return a;
}

std::string harness_csv(const std::vector<Run>& runs, double peak_gfma) {
    std::ostringstream os;
    os << "label,max_edge,patches,links,bins,width,height";
    for (const char* phase : kPhases) os << ',' << phase << "_s";
    os << ",peak_rss_mb,link_bin_updates,updates_per_s,achieved_gfma_s,fraction_of_peak,link_mb,working_mb,"
          "cube_mb,needed_mb,peak_over_needed\n";
    os << std::setprecision(8);
    for (const Run& r : runs) {
        const Derived d = derive(r, peak_gfma);
        os << r.label << ',' << r.config.max_edge << ',' << r.patches << ',' << r.links << ',' << r.config.bins << ','
           << r.config.width << ',' << r.config.height;
        for (double s : r.seconds) os << ',' << s;
        os << ',' << r.peak_rss_mb << ',' << r.link_bin_updates << ',' << d.updates_per_s << ',' << d.gfma_s << ','
           << d.fraction_of_peak << ',' << d.link_mb << ',' << r.working_mb << ',' << d.cube_mb << ',' << d.needed_mb
           << ',' << d.peak_over_needed << '\n';
    }
    return os.str();
}

std::string accuracy_csv(const std::vector<Accuracy>& rows) {
    std::ostringstream os;
    os << "max_edge,patches,total_s,rel_l2_transient,rel_l2_transient_" << kCoarseBins << "bin,rel_l2_steady\n"
       << std::setprecision(8);
    for (const Accuracy& a : rows)
        os << a.max_edge << ',' << a.patches << ',' << a.seconds << ',' << a.transient << ',' << a.coarse << ','
           << a.steady << '\n';
    return os.str();
}

/// The fitted exponents of one group of runs against one axis (patches or bins).
struct Fit {
    std::string what;
    double total, links, solve;
};

/// Runs whose seconds are fitted against x (patches or bins), and what they have in common.
struct Group {
    std::string what;
    std::vector<const Run*> runs;
    std::vector<double> x;
};

/// The exponents of total, links and solve seconds against x, per group.
Fit fit_group(const Group& g) {
    auto slope = [&](Phase phase) {
        std::vector<double> y;
        for (const Run* r : g.runs) y.push_back(r->seconds[phase]);
        return log_slope(g.x, y);
    };
    return {g.what, slope(kTotal), slope(kLinks), slope(kSolve)};
}

/// The fitted exponents for RESULTS.md: against patches, and against bins at each bins-sweep max_edge.
/// (scaling.png, drawn by python/tprf_plots.py from harness.csv, fits the same least squares.)
std::vector<Fit> scaling_fits(const Plan& p, const std::vector<Run>& runs) {
    Group by_patch{"patches (" + std::to_string(p.patch_bins) + " bins)", {}, {}};
    for (double e : p.patch_edges) {
        by_patch.runs.push_back(&find_run(runs, {e, p.patch_bins, p.small, p.small}));
        by_patch.x.push_back(by_patch.runs.back()->patches);
    }
    std::vector<Fit> fits = {fit_group(by_patch)};
    for (double e : p.bin_edges) {
        Group g;
        for (int b : p.bin_counts) {
            g.runs.push_back(&find_run(runs, {e, b, p.small, p.small}));
            g.x.push_back(b);
        }
        g.what = "bins (max_edge " + general(e) + ", " + num(g.runs.front()->patches, 0) + " patches)";
        fits.push_back(fit_group(g));
    }
    return fits;
}

/// Draws scaling.png from the two CSVs with python/tprf_plots.py. Without a Python that has
/// matplotlib, says how to draw it later and removes an older scaling.png, which would not match the
/// CSVs. Returns whether it was drawn.
bool draw_scaling(const fs::path& harness, const fs::path& accuracy, const fs::path& png, const Plan& p) {
    const std::vector<std::string> args = {"scaling", harness.string(), accuracy.string(), png.string(),
                                           "--bin-width", general(p.bin_width), "--accuracy-bins",
                                           std::to_string(p.accuracy_bins)};
    std::string failure;
    if (tprf::run_plot_script(args, &failure)) return true;
    fs::remove(png);
    std::fprintf(stderr, "tprf_harness: %s\n", tprf::plot_not_drawn_message(png, args, failure).c_str());
    return false;
}

/// The first "KEY : value" line of a /proc file, value trimmed; empty when absent.
std::string proc_field(const char* file, const std::string& key) {
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line))
        if (line.compare(0, key.size(), key) == 0 && line.find(':') != std::string::npos) {
            const std::string v = line.substr(line.find(':') + 1);
            const auto b = v.find_first_not_of(" \t");
            return b == std::string::npos ? "" : v.substr(b);
        }
    return "";
}

std::string utc_date() {
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&now, &tm);
    char buf[16];
    std::strftime(buf, sizeof buf, "%Y-%m-%d", &tm);
    return buf;
}

/// The Markdown section that goes between the markers of RESULTS.md.
std::string results_section(const std::string& command, const Plan& plan, int threads, double peak_gfma,
                            double bandwidth, const std::vector<Run>& runs, const std::vector<Fit>& fits,
                            const std::vector<Accuracy>& accuracy, const std::string& png /* empty: not drawn */) {
    std::ostringstream os;
    const double mem_gib = std::atof(proc_field("/proc/meminfo", "MemTotal").c_str()) / (1024.0 * 1024.0);
    std::string cpu = proc_field("/proc/cpuinfo", "model name");
    os << "## Scaling harness, " << utc_date() << ": " << (cpu.empty() ? "unknown CPU" : cpu) << ", "
       << std::thread::hardware_concurrency() << " cores, " << num(mem_gib, 1) << " GiB\n\n"
       << "`" << command << "` (Cornell box, spp 4, bin width " << general(plan.bin_width) << " m, "
       << threads << " threads). Machine ceilings on " << threads << " threads: FMA peak " << num(peak_gfma, 1)
       << " GFMA/s, memory bandwidth " << num(bandwidth, 1) << " GB/s (STREAM triad).\n\n"
       << "| sweep | max_edge | patches | links | bins | pixels | load s | patches s | links s | solve s | gather s "
          "| write s | total s | peak MB | needed MB | peak/needed | GFMA/s | of peak |\n"
       << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Run& r : runs) {
        const Derived d = derive(r, peak_gfma);
        os << "| " << r.label << " | " << general(r.config.max_edge) << " | " << num(r.patches, 0) << " | "
           << num(r.links, 0) << " | " << r.config.bins << " | " << r.config.width << "x" << r.config.height;
        for (double s : r.seconds) os << " | " << num(s, 2);
        os << " | " << num(r.peak_rss_mb, 0) << " | " << num(d.needed_mb, 0) << " | " << num(d.peak_over_needed, 2)
           << " | " << num(d.gfma_s, 1) << " | " << num(100 * d.fraction_of_peak, 0) << "% |\n";
    }
    os << "\nFitted exponents (least-squares slope of log seconds against log x):\n\n";
    for (const Fit& f : fits)
        os << "- against " << f.what << ": total " << slope_text(f.total) << ", links " << slope_text(f.links)
           << ", solve " << slope_text(f.solve) << "\n";
    os << "\nAccuracy: relative L2 error against a render at max_edge / 2 (all pixels, bins and channels; "
       << kCoarseBins << "-bin sums: every " << kCoarseBins << " consecutive bins summed first):\n\n"
       << "| max_edge | patches | total s | transient | " << kCoarseBins << "-bin sums | steady |\n"
       << "|---|---|---|---|---|---|\n";
    for (const Accuracy& a : accuracy)
        os << "| " << general(a.max_edge) << " | " << num(a.patches, 0) << " | " << num(a.seconds, 2) << " | "
           << num(a.transient, 4) << " | " << num(a.coarse, 4) << " | " << num(a.steady, 4) << " |\n";
    if (png.empty())
        os << "\nPlots: not drawn (no Python with matplotlib; see bench/README.md).\n";
    else
        os << "\nPlots: [" << png << "](" << png << ")\n";
    return os.str();
}

/// Replaces what lies between the harness markers of `file` (both markers kept) with `section`, or
/// appends markers and section when the file or the markers are absent; the rest is kept as is.
void update_results(const fs::path& file, const std::string& section) {
    const std::string begin = "<!-- harness:begin -->", end = "<!-- harness:end -->";
    std::string text;
    if (fs::exists(file)) {
        std::ifstream in(file, std::ios::binary);
        text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
        if (!in.good() && !in.eof()) throw std::runtime_error(file.string() + ": cannot read");
    }
    const std::string block = begin + "\n" + section + end;
    const std::size_t b = text.find(begin), e = text.find(end);
    if (b == std::string::npos && e == std::string::npos) {
        if (!text.empty()) text += text.back() == '\n' ? "\n" : "\n\n";
        text += block + "\n";
    } else if (b == std::string::npos || e == std::string::npos || e < b) {
        throw std::runtime_error(file.string() + ": has one harness marker without the other (or end before begin)");
    } else {
        text.replace(b, e + end.size() - b, block);
    }
    tprf::write_text_file(file, text);
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"tprf_harness: how tprf render's seconds and memory grow with patches, bins and pixels"};
    bool quick = false, no_results = false;
    int threads = 0;
    std::string out_dir = std::string(TPRF_SOURCE_DIR) + "/bench/out";
    std::string results = std::string(TPRF_SOURCE_DIR) + "/bench/RESULTS.md";
    app.add_flag("--quick", quick, "a tiny sweep that tests the harness itself (seconds)");
    app.add_option("--threads", threads, "render and ceiling threads (0: all cores)")->check(CLI::NonNegativeNumber);
    app.add_option("--out", out_dir, "output directory for harness.csv, accuracy.csv, scaling.png")
        ->capture_default_str();
    app.add_option("--results", results, "Markdown file whose harness section is replaced")->capture_default_str();
    app.add_flag("--no-results", no_results, "do not touch the results file");
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int rc = app.exit(e);
        return rc == 0 ? 0 : 2;
    }
    if (threads == 0) threads = std::max(1, int(std::thread::hardware_concurrency()));
    std::string command = "tprf_harness";
    for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];

    try {
        const Plan plan = quick ? quick_plan() : full_plan();
        const fs::path out = fs::absolute(out_dir);
        tprf::check_output_dir(out);

        std::fprintf(stderr, "machine ceilings on %d threads ... ", threads);
        std::fflush(stderr);
        const double peak_gfma = tprf::bench::measure_fma_peak_gflops(threads);
        const double bandwidth = tprf::bench::measure_memory_bandwidth_gbs(threads);
        std::fprintf(stderr, "FMA peak %.1f GFMA/s, bandwidth %.1f GB/s\n", peak_gfma, bandwidth);

        std::vector<Run> runs = planned_sweeps(plan);
        const Scratch scratch(out);
        Renderer renderer(scratch.dir(), plan.bin_width, threads, int(runs.size() + 2 * plan.accuracy_edges.size()));
        for (Run& r : runs) {
            r = renderer.render(r.config, r.label, r.label + " sweep");
            fs::remove_all(r.dir);
        }

        std::vector<Accuracy> accuracy;
        for (double h : plan.accuracy_edges) {
            const Config c{h, plan.accuracy_bins, plan.small, plan.small};
            const Run ref = renderer.render({h / 2, c.bins, c.width, c.height}, "reference", "accuracy reference");
            const Run r = renderer.render(c, "accuracy", "accuracy");
            Accuracy a = compare(r.dir, ref.dir);
            a.max_edge = h, a.patches = r.patches, a.seconds = r.seconds[kTotal];
            accuracy.push_back(a);
            fs::remove_all(r.dir);
            fs::remove_all(ref.dir);
        }

        tprf::write_text_file(out / "harness.csv", harness_csv(runs, peak_gfma));
        tprf::write_text_file(out / "accuracy.csv", accuracy_csv(accuracy));
        const fs::path png = out / "scaling.png";
        const bool drawn = draw_scaling(out / "harness.csv", out / "accuracy.csv", png, plan);
        const std::vector<Fit> fits = scaling_fits(plan, runs);
        std::fprintf(stderr, "wrote %s, %s%s%s\n", (out / "harness.csv").c_str(), (out / "accuracy.csv").c_str(),
                     drawn ? ", " : "", drawn ? png.c_str() : "");
        if (!no_results) {
            const fs::path file = fs::absolute(results);
            const std::string link = drawn ? fs::relative(png, file.parent_path()).generic_string() : "";
            update_results(file,
                           results_section(command, plan, threads, peak_gfma, bandwidth, runs, fits, accuracy, link));
            std::fprintf(stderr, "updated %s\n", file.c_str());
        }
        for (const Fit& f : fits)
            std::printf("exponents against %s: total %s, links %s, solve %s\n", f.what.c_str(),
                        slope_text(f.total).c_str(), slope_text(f.links).c_str(), slope_text(f.solve).c_str());
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "tprf_harness: error: %s\n", e.what());
        return 1;
    }
}
