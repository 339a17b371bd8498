// The camera stage on the Cornell box at about 4k patches: tracing the camera's samples into taps
// (prepare_camera), and filming one solved block of 32 bins (TransientFilm::add_block), the per-block
// work of the gather, at 96 x 96 and 256 x 256 pixels with the scene's 4 samples per pixel, and at
// 96 x 96 with 64 (issue 13's whole-image case). The area light is timed on the scene's bins.
#include "bench_util.h"

#include "tprf/imaging/camera.h"
#include "tprf/transport/illumination.h"
#include "tprf/imaging/film.h"
#include "tprf/transport/link_set.h"
#include "tprf/geometry/patches.h"
#include "tprf/transport/solver.h"
#include "tprf/geometry/visibility.h"

#include <benchmark/benchmark.h>

#include <memory>
#include <vector>

namespace {

constexpr int kThreads = 2;
constexpr int kBins = 2048;
constexpr int kBlockBins = 32;

// The Cornell box at about 4k patches on kBins bins, built once.
const tprf::bench::BuiltCornell& stage() {
    static const std::unique_ptr<tprf::bench::BuiltCornell> s = tprf::bench::built_cornell(4000, kBins, kThreads, false);
    return *s;
}

// A square camera of `pixels` on a side with `spp` samples per pixel (0: the scene's own).
tprf::Camera camera_of_size(int pixels, int spp) {
    tprf::Camera camera = *stage().scene.camera;
    camera.width = camera.height = pixels;
    if (spp > 0) camera.spp = spp;
    return camera;
}

// Primary rays, FLANN neighbours and interpolation weights for every sample.
void BM_PrepareCamera(benchmark::State& state) {
    const tprf::bench::BuiltCornell& s = stage();
    const tprf::Camera camera = camera_of_size(int(state.range(0)), int(state.range(1)));
    tprf::GatherOptions options;
    options.threads = kThreads;
    options.time = &s.scene.time;
    std::size_t taps = 0, lit = 0;
    double bytes = 0.0;
    for (auto _ : state) {
        const double before = tprf::bench::start_peak();
        const tprf::Gather gather = tprf::prepare_camera(camera, s.patches, s.sources, *s.visibility, options);
        bytes = tprf::bench::proc_status_bytes("VmHWM") - before;
        taps = gather.taps.size();
        lit = 0;
        for (std::size_t px = 0; px + 1 < gather.row.size(); ++px) lit += gather.row[px + 1] > gather.row[px];
        benchmark::DoNotOptimize(gather.taps.data());
    }
    // Samples of the pixels that see something: the others trace a ray and keep nothing.
    const double samples = double(camera.width) * camera.height * camera.spp;
    const double lit_samples = double(lit) * camera.spp;
    state.counters["samples"] = samples;
    state.counters["taps"] = double(taps);
    state.counters["taps_per_pixel"] = double(taps) / double(lit);
    state.counters["bytes_per_sample"] = bytes / lit_samples;
    state.counters["samples_per_s"] = benchmark::Counter(samples, benchmark::Counter::kIsIterationInvariantRate);
    state.counters["seconds_per_sample"] = benchmark::Counter(
        lit_samples, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_PrepareCamera)
    ->Args({96, 0})
    ->Args({96, 1})
    ->Args({256, 0})
    ->Args({96, 64})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// One block of patch profiles (made-up values: the cost does not depend on them) filmed into the cube.
void BM_FilmBlock(benchmark::State& state) {
    const tprf::bench::BuiltCornell& s = stage();
    const tprf::Camera camera = camera_of_size(int(state.range(0)), int(state.range(1)));
    tprf::GatherOptions options;
    options.threads = kThreads;
    options.time = &s.scene.time;
    const tprf::Gather gather = tprf::prepare_camera(camera, s.patches, s.sources, *s.visibility, options);
    std::vector<float> cube(std::size_t(camera.width) * camera.height * kBins * 3, 0.0f);
    tprf::TransientFilm film(gather, s.emission, s.scene.time, cube.data(),
                             {.delay = s.scene.solver.delay, .threads = kThreads});
    std::vector<float> radiosity(s.patches.size() * kBlockBins * 3, 1e-3f);
    tprf::SolveBlock block;
    block.first_bin = kBins / 2;
    block.bins = kBlockBins;
    block.patches = s.patches.size();
    block.radiosity = radiosity.data();
    for (auto _ : state) {
        film.add_block(block);
        film.finish();
        benchmark::DoNotOptimize(cube.data());
    }
    state.counters["taps"] = double(gather.taps.size());
    state.counters["tap_bins_per_s"] = benchmark::Counter(double(gather.taps.size()) * kBlockBins,
                                                          benchmark::Counter::kIsIterationInvariantRate);
    state.counters["seconds_per_tap_bin"] =
        benchmark::Counter(double(gather.taps.size()) * kBlockBins,
                           benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_FilmBlock)->Args({96, 0})->Args({256, 0})->Args({96, 64})->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
