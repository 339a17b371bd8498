// The link stage: the exact point-to-polygon form factor (its innermost kernel), and the whole stage
// (visibility hierarchy + compute_links) on the Cornell box at about 1k, 4k and 16k patches.
#include "bench_util.h"

#include "tprf/core/random.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/transport/links.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"

#include <benchmark/benchmark.h>

#include <array>
#include <chrono>
#include <vector>

namespace {

constexpr int kThreads = 2;

// A 10 cm square 1 m above a point, tilted and off axis so that no term of the contour sum vanishes.
void BM_PointPolygonFormFactor(benchmark::State& state) {
    const std::array<tprf::Vec3, 4> quad = {tprf::Vec3(0.20, 0.10, 1.00), tprf::Vec3(0.20, 0.20, 1.02),
                                            tprf::Vec3(0.30, 0.20, 1.02), tprf::Vec3(0.30, 0.10, 1.00)};
    const tprf::Vec3 quad_normal = (quad[1] - quad[0]).cross(quad[2] - quad[0]).normalized();
    tprf::Vec3 x(0.0, 0.0, 0.0);
    const tprf::Vec3 n = tprf::Vec3(0.1, 0.0, 1.0).normalized();
    for (auto _ : state) {
        benchmark::DoNotOptimize(x);  // the inputs are opaque: no call is hoisted out of the loop
        benchmark::DoNotOptimize(tprf::point_polygon_form_factor(x, n, quad.data(), quad.size(), quad_normal));
    }
}
BENCHMARK(BM_PointPolygonFormFactor);

// Occlusion rays as the link stage casts them: 4 between random points of two patches of the Cornell
// box (about 4k patches; most pairs see each other, some are hidden by the blocks), one at a time
// (range 1) or in packets of 4 or 8 (Visibility::transmittances), one thread.
void BM_OcclusionRays(benchmark::State& state) {
    static const tprf::PatchSet patches = tprf::build_patches(tprf::bench::cornell_box(4000));
    static const tprf::Visibility visibility(patches);
    const int packet = int(state.range(0));
    constexpr std::size_t kRays = 1 << 16;
    std::vector<tprf::Vec3> a(kRays), b(kRays);
    tprf::Random rng(11);
    for (std::size_t k = 0; k < kRays; k += 4) {
        const std::size_t i = rng.next_u64() % patches.size(), j = rng.next_u64() % patches.size();
        for (std::size_t h = k; h < k + 4; ++h) {
            a[h] = tprf::patch_point(patches, i, rng.uniform(), rng.uniform()) + 1e-4 * patches.normal[i];
            b[h] = tprf::patch_point(patches, j, rng.uniform(), rng.uniform()) + 1e-4 * patches.normal[j];
        }
    }
    double passed_sum = 0.0;
    for (auto _ : state) {
        double passed[tprf::Visibility::kBatch];
        for (std::size_t k = 0; k < kRays; k += std::size_t(packet)) {
            if (packet == 1) {
                passed_sum += visibility.transmittance(a[k], b[k]);
                continue;
            }
            visibility.transmittances(a.data() + k, b.data() + k, packet, passed);
            for (int h = 0; h < packet; ++h) passed_sum += passed[h];
        }
    }
    state.counters["rays_per_s"] = benchmark::Counter(double(kRays), benchmark::Counter::kIsIterationInvariantRate);
    state.counters["passed"] = passed_sum / double(kRays) / double(state.iterations());
}
BENCHMARK(BM_OcclusionRays)->Arg(1)->Arg(4)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime();

// Visibility + compute_links, timed together; patch building is left out. Registered smallest first,
// and the peak RSS is reset before each case, so each case's peak is its own.
void BM_LinkStage(benchmark::State& state) {
    const int target = int(state.range(0));
    const tprf::Scene scene = tprf::bench::cornell_box(target);
    const tprf::PatchSet patches = tprf::build_patches(scene);
    const double n = double(patches.size());
    tprf::LinkOptions options;
    options.threads = kThreads;
    tprf::LinkStats stats;
    double seconds = 0.0, cpu_seconds = 0.0, links = 0.0, link_bytes = 0.0, rss_before = 0.0, rss_peak = 0.0;
    const bool peak_reset = tprf::bench::reset_peak_rss();
    for (auto _ : state) {
        rss_before = tprf::bench::proc_status_bytes("VmRSS");
        const double cpu0 = tprf::bench::process_cpu_seconds();
        const auto t0 = std::chrono::steady_clock::now();
        const tprf::Visibility visibility(patches);
        const tprf::Links result = tprf::compute_links(patches, visibility, options, &stats);
        seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        cpu_seconds = tprf::bench::process_cpu_seconds() - cpu0;
        rss_peak = tprf::bench::proc_status_bytes("VmHWM");
        links = double(result.size());
        link_bytes = double(result.bytes());
        benchmark::DoNotOptimize(result.ff.data());
    }
    const double considered = n * (n - 1.0) / 2.0;
    state.counters["patches"] = n;
    state.counters["max_edge_mm"] = scene.max_edge * 1e3;
    state.counters["pairs_considered"] = considered;
    state.counters["pairs_facing"] = double(stats.pairs_tested);
    state.counters["near_pairs"] = double(stats.near_pairs);
    state.counters["rays"] = double(stats.rays);
    state.counters["links"] = links;
    state.counters["link_MB"] = link_bytes / 1e6;
    state.counters["seconds"] = seconds;
    state.counters["pairs_per_s"] = considered / seconds;
    state.counters["cpu_util"] = cpu_seconds / (kThreads * seconds);
    // VmHWM is process-wide: without the reset it would carry the previous case's peak.
    state.counters["peak_rss_MB"] = peak_reset ? rss_peak / 1e6 : 0.0;
    state.counters["peak_over_start_MB"] = peak_reset ? (rss_peak - rss_before) / 1e6 : 0.0;
}
BENCHMARK(BM_LinkStage)
    ->Arg(1000)
    ->Arg(4000)
    ->Arg(16000)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

}  // namespace
