// The transient solve on the Cornell box at about 4k patches x 2048 bins, against the machine's FMA
// peak and memory bandwidth measured in the same run, a sweep of the time-block length, and batches of
// laser illuminations (one march for K of them against K marches); and the solve of the sample mesh
// scene (the statue), whose near field the Cornell box does not have.
#include "bench_util.h"
#include "machine.h"

#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"
#include "tprf/geometry/patches.h"
#include "tprf/transport/solver.h"
#include "tprf/geometry/visibility.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace {

constexpr int kThreads = 2;
constexpr int kPatches = 4000;
constexpr int kBins = 2048;
constexpr double kBinWidth = 0.005;  // metres of optical path

// Scene, patches, links and emission, built once for every solver case (the link stage alone
// takes seconds at this size and is measured in links_bench.cpp).
struct Problem {
    tprf::Scene scene;
    tprf::PatchSet patches;
    tprf::LinkSet links;
    tprf::Illumination emission;
};

// The Cornell box of the solver cases; `grey`: every albedo 0.73 and a white emitter, so that the
// scene is solved on one channel.
std::unique_ptr<Problem> make_problem(bool grey) {
    auto out = std::make_unique<Problem>();
    out->scene = tprf::bench::cornell_box(kPatches);
    if (grey)
        for (tprf::Object& o : out->scene.objects) {
            o.albedo = tprf::Rgb::Constant(0.73);
            if (o.emission.maxCoeff() > 0.0) o.emission = tprf::Rgb::Constant(12.0);
        }
    out->scene.time.bins = kBins;
    out->scene.time.bin_width = kBinWidth;
    out->scene.time.start = 0.0;
    out->scene.time.unit = tprf::TimeUnit::Metres;
    out->patches = tprf::build_patches(out->scene);
    const tprf::Visibility visibility(out->patches);
    tprf::LinkOptions link_options;
    link_options.threads = kThreads;
    out->links = tprf::flat_link_set(out->patches, visibility, link_options);
    tprf::IlluminationOptions emitter_options;
    emitter_options.threads = kThreads;
    out->emission = tprf::illuminate(tprf::light_sources(out->scene, out->patches, visibility), out->patches, visibility, emitter_options);
    return out;
}

const Problem& problem() {
    static const std::unique_ptr<Problem> p = make_problem(false);
    return *p;
}

const Problem& grey_problem() {
    static const std::unique_ptr<Problem> p = make_problem(true);
    return *p;
}

// The machine's ceilings, measured once per run by the first solver case and reused by the sweep.
// The FMA peak is the widest vectors' (AVX-512 where the CPU has it); the AVX2 one is shown beside it.
struct Ceilings {
    double fma_gflops = 0.0;
    double fma_gflops_256 = 0.0;
    double bandwidth_gbs = 0.0;
};

const Ceilings& ceilings() {
    static const Ceilings c{tprf::bench::measure_fma_peak_gflops(kThreads),
                            tprf::bench::measure_fma_peak_gflops(kThreads, 256),
                            tprf::bench::measure_memory_bandwidth_gbs(kThreads)};
    return c;
}

void run_solve(benchmark::State& state, const tprf::SolverOptions& options, const Problem& p = problem()) {
    const Ceilings& machine = ceilings();
    tprf::SolveStats stats;
    double seconds = 0.0, cpu_seconds = 0.0;
    for (auto _ : state) {
        const double cpu0 = tprf::bench::process_cpu_seconds();
        const auto t0 = std::chrono::steady_clock::now();
        stats = tprf::solve_transient(p.patches, p.links, p.emission, p.scene.time, options,
                                      [](const tprf::SolveBlock&) {});
        seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        cpu_seconds = tprf::bench::process_cpu_seconds() - cpu0;
    }
    // The long-link kernel is a[e] += w0 * h[e + C] + w1 * h[e] per bin and channel: two FMAs with
    // linear delays, one (w1 = 0) with nearest.
    const double fma_per_update = (options.delay == tprf::DelayMode::Linear ? 2.0 : 1.0) * double(stats.lanes);
    const double updates_per_s = double(stats.link_bin_updates) / seconds;
    const double gflops = updates_per_s * fma_per_update / 1e9;
    // Links shorter than a block are applied bin by bin from scattered history, not by the kernel above.
    const float inv_bin = p.scene.time.inv_bin_f();
    std::size_t short_links = 0;
    for (float d : p.links.links.distance)
        if (tprf::delay_taps_f(d, inv_bin, options.delay, 1.0f).lag < stats.block_bins) ++short_links;
    // Every block streams each link's source, form factor and distance once (12 bytes).
    const double blocks = std::ceil(double(kBins) / double(stats.block_bins));
    const double link_stream_gbs = 12.0 * double(p.links.links.size()) * blocks / seconds / 1e9;

    state.counters["patches"] = double(p.patches.size());
    state.counters["bins"] = double(p.scene.time.bins);
    state.counters["links"] = double(p.links.links.size());
    state.counters["channels"] = double(stats.channels);
    state.counters["seconds"] = seconds;
    state.counters["cpu_util"] = cpu_seconds / (kThreads * seconds);
    state.counters["link_bin_updates"] = double(stats.link_bin_updates);
    state.counters["updates_per_s"] = updates_per_s;
    state.counters["seconds_per_link_bin"] = seconds / double(stats.link_bin_updates);
    state.counters["fma_per_update"] = fma_per_update;
    state.counters["achieved_GFMA_s"] = gflops;
    state.counters["peak_GFMA_s"] = machine.fma_gflops;
    state.counters["peak_GFMA_s_avx2"] = machine.fma_gflops_256;
    state.counters["fraction_of_peak"] = machine.fma_gflops > 0.0 ? gflops / machine.fma_gflops : 0.0;
    state.counters["bandwidth_GB_s"] = machine.bandwidth_gbs;
    state.counters["link_stream_GB_s"] = link_stream_gbs;
    state.counters["short_link_fraction"] = double(short_links) / double(p.links.links.size());
    state.counters["working_MB"] = double(stats.working_bytes) / 1e6;
    state.counters["ring_bins"] = double(stats.ring_bins);
    state.counters["block_bins"] = double(stats.block_bins);
    state.counters["jacobi_max"] = double(stats.max_jacobi_iterations);
    state.counters["wide_kernels"] = stats.wide_kernels ? 1.0 : 0.0;
    state.counters["packed_links"] = double(stats.packed_links);
    // The long-link pass alone (where the link kernel runs; links shorter than a block are applied
    // bin by bin in the short pass), against the same peak.
    const double long_gflops = double(stats.link_bin_updates) * (1.0 - double(short_links) / double(p.links.links.size())) *
                               fma_per_update / stats.seconds_long / 1e9;
    state.counters["seconds_long"] = stats.seconds_long;
    state.counters["seconds_short"] = stats.seconds_short;
    state.counters["seconds_sink"] = stats.seconds_sink;
    state.counters["long_pass_GFMA_s"] = long_gflops;
    state.counters["long_pass_fraction_of_peak"] = machine.fma_gflops > 0.0 ? long_gflops / machine.fma_gflops : 0.0;
}

// Default options: linear delays, every bounce, the default block length; range(0) = 0 keeps the
// long-link kernels to the library's instruction set where the CPU also has AVX-512 (the same results).
void BM_TransientSolve(benchmark::State& state) {
    tprf::SolverOptions options;
    options.threads = kThreads;
    options.wide_vectors = state.range(0) != 0;
    run_solve(state, options);
}
BENCHMARK(BM_TransientSolve)->ArgName("wide")->Arg(1)->Arg(0)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// The same on the grey Cornell box: one channel.
void BM_TransientSolveGrey(benchmark::State& state) {
    tprf::SolverOptions options;
    options.threads = kThreads;
    options.wide_vectors = state.range(0) != 0;
    run_solve(state, options, grey_problem());
}
BENCHMARK(BM_TransientSolveGrey)->ArgName("wide")->Arg(1)->Arg(0)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// The same solve with block_bins = range(0): the block length that the default should take.
void BM_TransientSolveBlockBins(benchmark::State& state) {
    tprf::SolverOptions options;
    options.threads = kThreads;
    options.block_bins = int(state.range(0));
    run_solve(state, options);
}
BENCHMARK(BM_TransientSolveBlockBins)
    ->Arg(8)
    ->Arg(16)
    ->Arg(32)
    ->Arg(64)
    ->Arg(128)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

// Laser illuminations of the Cornell box (its emitter off): a laser at the camera aimed at a 4 x 4 grid
// of points on the back wall, as an NLOS capture scans a relay wall.
struct LaserBatch {
    const Problem* problem = nullptr;
    std::vector<tprf::Illumination> illuminations;
};

LaserBatch make_lasers(const Problem& p) {
    LaserBatch out;
    out.problem = &p;
    const tprf::Visibility visibility(p.patches);
    tprf::IlluminationOptions options;
    options.threads = kThreads;
    for (int k = 0; k < tprf::kMaxBatch; ++k) {
        tprf::Scene scene = p.scene;
        for (tprf::Object& o : scene.objects) o.emission = tprf::Rgb::Zero();
        tprf::Laser laser;
        laser.origin = tprf::Vec3(0.5, -1.35, 0.5);
        const tprf::Vec3 target(0.2 + 0.2 * (k % 4), 1.0, 0.2 + 0.2 * (k / 4));
        laser.direction = (target - laser.origin).normalized();
        laser.power = tprf::Rgb::Constant(1.0);
        scene.lights = {laser};
        out.illuminations.push_back(
            tprf::illuminate(tprf::light_sources(scene, p.patches, visibility), p.patches, visibility, options));
    }
    return out;
}

const LaserBatch& lasers(bool grey) {
    static const LaserBatch grey_batch = make_lasers(grey_problem()), coloured_batch = make_lasers(problem());
    return grey ? grey_batch : coloured_batch;
}

// K = range(0) laser illuminations in one march, on the grey (range(1) = 1: K lanes) or the coloured
// Cornell box (3 K lanes). seconds_per_illumination against the K = 1 case's seconds is the batch's gain;
// extra_cost_per_lane, a march of K against one of a single illumination (the K = 1 case, run first):
// seconds_K = seconds_1 (1 + (K - 1) extra_cost_per_lane).
void BM_TransientSolveBatch(benchmark::State& state) {
    static double single_seconds[2] = {0.0, 0.0};  // the K = 1 cases', coloured and grey
    const int K = int(state.range(0));
    const LaserBatch& batch = lasers(state.range(1) != 0);
    const Problem& p = *batch.problem;
    std::vector<const tprf::Illumination*> pointers;
    for (int k = 0; k < K; ++k) pointers.push_back(&batch.illuminations[std::size_t(k)]);
    tprf::SolverOptions options;
    options.threads = kThreads;
    tprf::SolveStats stats;
    double seconds = 0.0, cpu_seconds = 0.0;
    for (auto _ : state) {
        const double cpu0 = tprf::bench::process_cpu_seconds();
        const auto t0 = std::chrono::steady_clock::now();
        stats = tprf::solve_transient(p.patches, p.links, std::span<const tprf::Illumination* const>(pointers),
                                      p.scene.time, options, [](const tprf::SolveBlock&) {});
        seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        cpu_seconds = tprf::bench::process_cpu_seconds() - cpu0;
    }
    const double fma = 2.0 * double(stats.lanes) * double(stats.link_bin_updates);
    state.counters["illuminations"] = double(K);
    state.counters["lanes"] = double(stats.lanes);
    state.counters["seconds"] = seconds;
    state.counters["seconds_per_illumination"] = seconds / double(K);
    state.counters["seconds_long"] = stats.seconds_long;
    state.counters["seconds_short"] = stats.seconds_short;
    state.counters["cpu_util"] = cpu_seconds / (kThreads * seconds);
    state.counters["achieved_GFMA_s"] = fma / seconds / 1e9;
    state.counters["working_MB"] = double(stats.working_bytes) / 1e6;
    double& single = single_seconds[state.range(1) != 0 ? 1 : 0];
    if (K == 1) single = seconds;
    if (K > 1 && single > 0.0) state.counters["extra_cost_per_lane"] = (seconds / single - 1.0) / double(K - 1);
}
BENCHMARK(BM_TransientSolveBatch)
    ->ArgsProduct({{1, 8, 16}, {1, 0}})
    ->ArgNames({"K", "grey"})
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

// The sample mesh scene of issue 12 (meshes/statue-on-floor.json: a 52k-triangle statue on a floor
// before a wall, a point light; 1,024 bins of 1 cm) with hierarchical links at tolerance 0.01 (the
// tolerance of its render target in bench/RESULTS.md): patches, links and the light built once, then
// the solve alone, three times in a row, so that a change to the march is measured without the link
// stage's spread. Its near field (1.9M links under two bins, a same-bin system of 43k patches) is what
// the Cornell box above does not have. `fastest` is the least of the three.
const Problem& mesh_problem() {
    static const std::unique_ptr<Problem> p = [] {
        auto out = std::make_unique<Problem>();
        out->scene = tprf::load_scene(std::string(TPRF_SOURCE_DIR) + "/meshes/statue-on-floor.json");
        out->scene.links.tolerance = 0.01;
        out->patches = tprf::build_patches(out->scene);
        const tprf::Visibility visibility(out->patches);
        tprf::LinkOptions link_options;
        link_options.threads = kThreads;
        out->links = tprf::make_link_set(out->patches, visibility, out->scene.links, out->scene.time.bin_width_m(),
                                         link_options);
        tprf::IlluminationOptions light_options;
        light_options.threads = kThreads;
        light_options.merge_bins = &out->scene.time;
        out->emission = tprf::illuminate(tprf::light_sources(out->scene, out->patches, visibility), out->patches,
                                         visibility, light_options);
        return out;
    }();
    return *p;
}

void BM_MeshSceneSolve(benchmark::State& state) {
    const Problem& p = mesh_problem();
    tprf::SolverOptions options;
    options.threads = kThreads;
    options.delay = p.scene.solver.delay;
    options.wide_vectors = state.range(0) != 0;
    tprf::SolveStats stats;
    double seconds = 0.0, cpu_seconds = 0.0, fastest = 0.0;
    for (auto _ : state) {
        const double cpu0 = tprf::bench::process_cpu_seconds();
        const auto t0 = std::chrono::steady_clock::now();
        stats = tprf::solve_transient(p.patches, p.links, p.emission, p.scene.time, options,
                                      [](const tprf::SolveBlock&) {});
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        fastest = fastest > 0.0 ? std::min(fastest, s) : s;
        seconds += s;
        cpu_seconds += tprf::bench::process_cpu_seconds() - cpu0;
    }
    const double runs = double(state.iterations());
    state.counters["patches"] = double(p.patches.size());
    state.counters["links"] = double(p.links.links.size());
    state.counters["seconds"] = seconds / runs;
    state.counters["fastest"] = fastest;
    state.counters["seconds_long"] = stats.seconds_long;
    state.counters["seconds_short"] = stats.seconds_short;
    state.counters["cpu_util"] = cpu_seconds / (kThreads * seconds);
    state.counters["jacobi_sweeps"] = double(stats.jacobi_sweeps);
    state.counters["short_links"] = double(stats.short_links);
    const double bins = double(p.scene.time.bins);
    state.counters["seconds_per_patch_bin"] = seconds / runs / (double(p.patches.size()) * bins);
    state.counters["seconds_per_short_link_bin"] = stats.seconds_short / (double(stats.short_links) * bins);
    state.counters["working_MB"] = double(stats.working_bytes) / 1e6;
    state.counters["wide_kernels"] = stats.wide_kernels ? 1.0 : 0.0;
}
BENCHMARK(BM_MeshSceneSolve)->ArgName("wide")->Arg(1)->Arg(0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();

}  // namespace
