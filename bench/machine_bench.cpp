// Machine ceilings for the benchmarks (see machine.h). No BENCHMARK cases here: the kernels' own
// cases call these so that a kernel and its ceiling are measured in the same run, under the same load.
#include "machine.h"

#include <immintrin.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>

namespace tprf::bench {
namespace {

double now_seconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Independent FMA chains: a core issues two FMAs per cycle with a latency of four, so at least eight
// chains must be in flight; twelve leave slack and still fit, with the two constants, in the sixteen
// ymm registers (and in the 32 zmm ones).
constexpr int kChains = 12;
constexpr std::int64_t kIterations = 40'000'000;  // ~0.1 s per thread at 40 GFMA/s (8 lanes)
constexpr int kRepeats = 5;

// The chains converge to a / (1 - m) instead of overflowing; without -ffast-math the compiler may
// neither reassociate nor drop them, and the sum they return is kept in a volatile. Written once on
// vectors of 8 or 16 floats and inlined into a function per instruction set, which compiles them
// (a * m + a contracted into one FMA there).
typedef float Floats8 __attribute__((vector_size(32)));
typedef float Floats16 __attribute__((vector_size(64)));

template <class vec, int Lanes = sizeof(vec) / sizeof(float)>
[[gnu::always_inline]] inline float fma_chains(std::int64_t iterations, float seed) {
    vec acc[kChains];
    for (int k = 0; k < kChains; ++k) acc[k] = vec{} + (seed + float(k));
    const vec m = vec{} + 0.999999f, a = vec{} + 1e-6f;
    for (std::int64_t i = 0; i < iterations; ++i) {
#pragma GCC unroll 12
        for (int k = 0; k < kChains; ++k) acc[k] = acc[k] * m + a;
    }
    vec sum = acc[0];
    for (int k = 1; k < kChains; ++k) sum += acc[k];
    float total = 0.0f;
    for (int e = 0; e < Lanes; ++e) total += sum[e];
    return total;
}

__attribute__((target("avx2,fma"))) float fma_chains_256(std::int64_t iterations, float seed) {
    return fma_chains<Floats8>(iterations, seed);
}

// 16 lanes: on CPUs whose AVX-512 units are as wide as their registers (AMD Zen 5, Intel server cores)
// twice the AVX2 rate; on Zen 4 the two are equal.
__attribute__((target("avx512f"))) float fma_chains_512(std::int64_t iterations, float seed) {
    return fma_chains<Floats16>(iterations, seed);
}

volatile float g_fma_sink = 0.0f;
volatile double g_stream_sink = 0.0;

}  // namespace

double measure_fma_peak_gflops(int threads, int vector_bits) {
    if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) return 0.0;
    if (vector_bits == 0) vector_bits = __builtin_cpu_supports("avx512f") ? 512 : 256;
    if (vector_bits != 256 && vector_bits != 512) return 0.0;
    if (vector_bits == 512 && !__builtin_cpu_supports("avx512f")) return 0.0;
    const int lanes = vector_bits / 32;
    threads = std::max(threads, 1);
    const volatile float seed_source = 1.0f;  // opaque to the optimiser
    double best = 0.0;
    for (int r = 0; r < kRepeats; ++r) {
        double t0 = 0.0, t1 = 0.0;
        float sum = 0.0f;
#pragma omp parallel num_threads(threads) reduction(+ : sum)
        {
            const float seed = seed_source + float(omp_get_thread_num());
#pragma omp barrier
#pragma omp master
            t0 = now_seconds();
            sum += lanes == 16 ? fma_chains_512(kIterations, seed) : fma_chains_256(kIterations, seed);
#pragma omp barrier
#pragma omp master
            t1 = now_seconds();
        }
        g_fma_sink = sum;
        const double fmas = double(threads) * double(kIterations) * double(kChains * lanes);
        best = std::max(best, fmas / (t1 - t0) / 1e9);
    }
    return best;
}

double measure_memory_bandwidth_gbs(int threads) {
    threads = std::max(threads, 1);
    constexpr std::size_t kBytesPerArray = std::size_t(256) << 20;
    constexpr std::size_t n = kBytesPerArray / sizeof(double);
    constexpr int kPasses = 5;
    // new[] without value-initialisation, then a parallel first touch: the pages are faulted in
    // before the timed passes.
    std::unique_ptr<double[]> a(new double[n]), b(new double[n]), c(new double[n]);
    double* __restrict pa = a.get();
    double* __restrict pb = b.get();
    double* __restrict pc = c.get();
#pragma omp parallel for schedule(static) num_threads(threads)
    for (std::size_t i = 0; i < n; ++i) {
        pa[i] = 0.0;
        pb[i] = 1.0;
        pc[i] = 2.0;
    }
    const volatile double scale_source = 3.0;
    const double s = scale_source;
    double best = 0.0;
    for (int pass = 0; pass < kPasses; ++pass) {
        const double t0 = now_seconds();
#pragma omp parallel for schedule(static) num_threads(threads)
        for (std::size_t i = 0; i < n; ++i) pa[i] = pb[i] + s * pc[i];
        const double t1 = now_seconds();
        best = std::max(best, 3.0 * double(kBytesPerArray) / (t1 - t0) / 1e9);
    }
    g_stream_sink = pa[n / 2];
    if (g_stream_sink != 7.0) throw std::logic_error("stream triad produced a wrong value");
    return best;
}

}  // namespace tprf::bench
