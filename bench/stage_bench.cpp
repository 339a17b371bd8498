// The stages whose rates and sizes the resource estimate (pipeline/info.cpp, `tprf info`) is built
// from, one case per measured constant there: each reports the counter that info.cpp names beside the
// constant, in the constant's unit. `python3 bench/estimate_constants.py` runs them (with the solver,
// camera, link and mesh cases that measure the others) and prints each beside its constant.
#include "bench_util.h"

#include "tprf/core/time_axis.h"
#include "tprf/geometry/neighbours.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/io/npy.h"
#include "tprf/transport/second_bounce.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/light_sources.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/solver.h"
#include "tprf/transport/steady.h"

#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

constexpr int kThreads = 2;

double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

tprf::Scene sample_scene(const std::string& name) {
    return tprf::load_scene(std::string(TPRF_SOURCE_DIR) + "/" + name);
}

// The Cornell box at about 4k patches with flat links and its light, built once for the cases below.
const tprf::bench::BuiltCornell& cornell() {
    static const std::unique_ptr<tprf::bench::BuiltCornell> c = tprf::bench::built_cornell(4000, 0, kThreads, true);
    return *c;
}

// Cutting the Cornell box into about 16k patches.
void BM_BuildPatches(benchmark::State& state) {
    const tprf::Scene scene = tprf::bench::cornell_box(16000);
    std::size_t patches = 0;
    for (auto _ : state) {
        const tprf::PatchSet p = tprf::build_patches(scene);
        patches = p.size();
        benchmark::DoNotOptimize(p.centroid.data());
    }
    state.counters["patches"] = double(patches);
    state.counters["seconds_per_patch"] =
        benchmark::Counter(double(patches), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_BuildPatches)->Unit(benchmark::kMillisecond)->UseRealTime();

// Embree's scene over the Cornell box's 16k patches: its build's seconds and its peak bytes.
void BM_Visibility(benchmark::State& state) {
    const tprf::PatchSet patches = tprf::build_patches(tprf::bench::cornell_box(16000));
    const double n = double(patches.size());
    double seconds = 0.0, bytes = 0.0;
    for (auto _ : state) {
        const double before = tprf::bench::start_peak();
        const auto t0 = std::chrono::steady_clock::now();
        const tprf::Visibility visibility(patches);
        seconds = seconds_since(t0);
        bytes = tprf::bench::proc_status_bytes("VmHWM") - before;
        benchmark::DoNotOptimize(&visibility);
    }
    state.counters["patches"] = n;
    state.counters["seconds_per_patch"] = seconds / n;
    state.counters["bytes_per_patch"] = bytes / n;
}
BENCHMARK(BM_Visibility)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// The camera gather's neighbour index over the Cornell box's 16k centroids, at its peak.
void BM_NeighbourIndex(benchmark::State& state) {
    const tprf::PatchSet patches = tprf::build_patches(tprf::bench::cornell_box(16000));
    const double n = double(patches.size());
    double bytes = 0.0;
    for (auto _ : state) {
        const double before = tprf::bench::start_peak();
        const tprf::Neighbours found = tprf::radius_search(patches.centroid, {patches.centroid[0]}, 0.01, kThreads);
        bytes = tprf::bench::proc_status_bytes("VmHWM") - before;
        benchmark::DoNotOptimize(&found);
    }
    state.counters["patches"] = n;
    state.counters["bytes_per_patch"] = bytes / n;
}
BENCHMARK(BM_NeighbourIndex)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// Hierarchical link stages. "cornell": the Cornell box at 4k patches, tolerance 0.003 and 1 cm bins,
// where the link count and the stage's seconds follow the estimate's power laws (the script divides
// them by N^e sqrt(0.003 / tolerance)), and the share of a full ring that a node keeps. "near": the
// corner at 5 mm patches under 10 cm bins, whose links are nearly all single patches within a bin of
// each other (the near field).
void BM_HierarchicalLinkStage(benchmark::State& state) {
    const bool near = state.range(0) != 0;
    tprf::Scene scene = sample_scene(near ? "meshes/corner.json" : "meshes/cornell-box.json");
    scene.max_edge = near ? 0.005 : tprf::bench::cornell_max_edge(4000);
    scene.time.unit = tprf::TimeUnit::Metres;
    scene.time.bin_width = near ? 0.1 : 0.01;
    scene.links.method = tprf::LinkMethod::Hierarchical;
    scene.links.tolerance = near ? 0.01 : 0.003;
    const tprf::PatchSet patches = tprf::build_patches(scene);
    const tprf::Visibility visibility(patches);
    tprf::LinkOptions options;
    options.threads = kThreads;
    double seconds = 0.0;
    tprf::LinkSet set;
    for (auto _ : state) {
        const auto t0 = std::chrono::steady_clock::now();
        set = tprf::make_link_set(patches, visibility, scene.links, scene.time.bin_width_m(), options);
        seconds = seconds_since(t0);
    }
    const double n = double(patches.size()), links = double(set.links.size());
    state.counters["patches"] = n;
    state.counters["links"] = links;
    state.counters["tolerance"] = scene.links.tolerance;
    state.counters["seconds"] = seconds;
    state.counters["seconds_per_link"] = seconds / links;
    // The rings the march keeps against as many full rings (the longest link's) with their mirrors.
    tprf::SolverOptions solver;
    solver.threads = kThreads;
    const tprf::MarchSizing m = tprf::solve_sizing(patches, set, scene.time, solver, 1, 3);
    const double full = double(tprf::ring_bins(m.inputs.longest_lag, m.shape.block_bins));
    const double mirror = double(tprf::ring_mirror_bins(m.shape.window_bins));
    state.counters["ring_share"] = (double(m.lists.ring_bins) / double(m.shape.nodes) - mirror) / full;
}
BENCHMARK(BM_HierarchicalLinkStage)
    ->ArgName("near_field")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

// The pulses of the corner's point light (range(0) = 0) or the Cornell box's area light (1), merged on
// the scene's bins as a render merges them: seconds and bytes per pulse, pulses per patch and point
// source; for the area light, seconds per patch it lights.
void BM_Illuminate(benchmark::State& state) {
    const bool area = state.range(0) != 0;
    const tprf::Scene scene = area ? cornell().scene : sample_scene("meshes/corner.json");
    const tprf::PatchSet patches = area ? tprf::PatchSet{} : tprf::build_patches(scene);
    const tprf::PatchSet& p = area ? cornell().patches : patches;
    const tprf::Visibility visibility(p);
    const tprf::LightSources sources = tprf::light_sources(scene, p, visibility);
    tprf::IlluminationOptions options;
    options.threads = kThreads;
    options.merge_bins = &scene.time;
    double seconds = 0.0, bytes = 0.0;
    tprf::Illumination out;
    for (auto _ : state) {
        out = tprf::Illumination{};
        const double before = tprf::bench::start_peak();
        const auto t0 = std::chrono::steady_clock::now();
        out = tprf::illuminate(sources, p, visibility, options);
        seconds = seconds_since(t0);
        bytes = tprf::bench::proc_status_bytes("VmHWM") - before;
    }
    const double pulses = double(out.pulses.size());
    std::size_t lit = 0;
    for (std::size_t i = 0; i + 1 < out.row.size(); ++i) lit += out.row[i + 1] > out.row[i];
    state.counters["pulses"] = pulses;
    state.counters["lit_patches"] = double(lit);
    state.counters["seconds_per_pulse"] = seconds / pulses;
    state.counters["bytes_per_pulse"] = bytes / pulses;
    state.counters["pulses_per_patch_source"] = pulses / (double(lit) * double(std::max<std::size_t>(1, scene.lights.size())));
    state.counters["seconds_per_patch_source"] = seconds / double(lit);
}
BENCHMARK(BM_Illuminate)->ArgName("area_light")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// The second bounce read at the samples' own times (camera.shift_second_bounce) on the Cornell box:
// made once per render, per link.
void BM_SecondBounceLight(benchmark::State& state) {
    const tprf::bench::BuiltCornell& c = cornell();
    double seconds = 0.0;
    for (auto _ : state) {
        const auto t0 = std::chrono::steady_clock::now();
        const auto light = tprf::make_second_bounce_light(c.patches, c.links, c.emission, c.scene.time,
                                                          {.delay = c.scene.solver.delay, .threads = kThreads}, false);
        seconds = seconds_since(t0);
        benchmark::DoNotOptimize(light.get());
    }
    state.counters["links"] = double(c.links.links.size());
    state.counters["seconds_per_link"] = seconds / double(c.links.links.size());
}
BENCHMARK(BM_SecondBounceLight)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// links.spread_pieces = 4 on the Cornell box's flat links under 5 mm bins, per link spread.
void BM_SpreadPatchLinks(benchmark::State& state) {
    const tprf::bench::BuiltCornell& c = cornell();
    double seconds = 0.0;
    for (auto _ : state) {
        state.PauseTiming();
        tprf::LinkSet set = c.links;
        state.ResumeTiming();
        const auto t0 = std::chrono::steady_clock::now();
        tprf::spread_patch_links(set, c.patches, 0.005, 4, kThreads);
        seconds = seconds_since(t0);
        benchmark::DoNotOptimize(set.links.ff.data());
    }
    state.counters["links"] = double(c.links.links.size());
    state.counters["seconds_per_link"] = seconds / double(c.links.links.size());
}
BENCHMARK(BM_SpreadPatchLinks)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// The steady state of the Cornell box (BiCGSTAB on its flat links, 3 channels), per link.
void BM_SteadyState(benchmark::State& state) {
    const tprf::bench::BuiltCornell& c = cornell();
    double seconds = 0.0;
    for (auto _ : state) {
        const auto t0 = std::chrono::steady_clock::now();
        const std::vector<tprf::Rgb> b = tprf::solve_steady(c.patches, c.links, c.emission);
        seconds = seconds_since(t0);
        benchmark::DoNotOptimize(b.data());
    }
    state.counters["links"] = double(c.links.links.size());
    state.counters["seconds_per_link"] = seconds / double(c.links.links.size());
}
BENCHMARK(BM_SteadyState)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// Links through the mirror of examples/mirrors/hidden_mirror.json: the pairs of patches in front of it
// that become links, a second.
void BM_MirrorLinks(benchmark::State& state) {
    const tprf::Scene scene = sample_scene("examples/mirrors/hidden_mirror.json");
    const tprf::PatchSet patches = tprf::build_patches(scene);
    const std::unique_ptr<tprf::Visibility> owned = tprf::scene_visibility(scene, patches);
    const tprf::Visibility& visibility = *owned;
    tprf::LinkOptions options;
    options.threads = kThreads;
    const tprf::LinkSet base = tprf::make_link_set(patches, visibility, scene.links, scene.time.bin_width_m(), options);
    double seconds = 0.0, added = 0.0;
    for (auto _ : state) {
        state.PauseTiming();
        tprf::LinkSet set = base;
        state.ResumeTiming();
        const auto t0 = std::chrono::steady_clock::now();
        added = double(tprf::add_mirror_links(set, patches, visibility, options, scene.time.bin_width_m()));
        seconds = seconds_since(t0);
    }
    state.counters["mirror_links"] = added;
    state.counters["pairs_per_s"] = added / seconds;
}
BENCHMARK(BM_MirrorLinks)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

// A memory-mapped cube of 64 MB, filled, then written back to its file (NpyMap::commit), a second.
void BM_WriteCube(benchmark::State& state) {
    const std::vector<std::size_t> shape = {64, 64, 1024, 4};
    const fs::path file = fs::temp_directory_path() / "tprf_bench_cube.npy";
    double seconds = 0.0, bytes = 0.0;
    for (auto _ : state) {
        tprf::NpyMap cube(file, shape);
        for (std::size_t k = 0; k < cube.size(); ++k) cube.data()[k] = float(k & 1023);
        bytes = double(cube.size()) * sizeof(float);
        const auto t0 = std::chrono::steady_clock::now();
        cube.commit();
        seconds = seconds_since(t0);
    }
    fs::remove(file);
    state.counters["bytes_per_s"] = bytes / seconds;
}
BENCHMARK(BM_WriteCube)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

}  // namespace
