// The long-link kernels of the transient march (solver_plan.h): for one receiver and one tile of
// sources, every link's window of the source's ring multiplied into the block's sums. They are compiled
// twice where the compiler can (solver_kernels_body.h): for the library's instruction set and for
// AVX-512 with 512-bit vectors, and the plan takes the wider ones where the CPU has them. Each sum adds
// the same products in the same order either way, so the results are bit-identical.

#include "solver_plan.h"

#include <algorithm>
#include <cstdlib>
#include <string_view>

namespace tprf::solver_detail {

namespace base {
#define TPRF_KERNEL_TARGET
#include "solver_kernels_body.h"
#undef TPRF_KERNEL_TARGET
}  // namespace base

// Only over a base with FMA: GCC contracts a * b + c into one FMA wherever the target has it, so a base
// without it (TPRF_ARCH empty or x86-64-v2) would round the same sums differently.
#if defined(__GNUC__) && !defined(__clang__) && !defined(__INTEL_COMPILER) && defined(__x86_64__) && defined(__FMA__)
#define TPRF_WIDE_KERNELS 1
// x86-64-v4 is AVX-512 F, BW, CD, DQ and VL; GCC otherwise prefers 256-bit vectors even there.
namespace wide {
#define TPRF_KERNEL_TARGET __attribute__((target("arch=x86-64-v4,prefer-vector-width=512")))
#define TPRF_KERNEL_WIDE 1
#include "solver_kernels_body.h"
#undef TPRF_KERNEL_WIDE
#undef TPRF_KERNEL_TARGET
}  // namespace wide
#endif

// TPRF_NO_AVX512 (set, not empty, not "0") keeps every run on the library's own kernels: for CPUs that
// slow their clock for 512-bit work, and for comparing the two from the command line.
bool cpu_has_wide_kernels() {
#ifdef TPRF_WIDE_KERNELS
    static const bool has = [] {
        const char* off = std::getenv("TPRF_NO_AVX512");
        if (off && *off && std::string_view(off) != "0") return false;
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
               __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") &&
               __builtin_cpu_supports("avx512vl");
    }();
    return has;
#else
    return false;
#endif
}

// A table's kernel: the wide copy's where it runs, else the library's own.
#ifdef TPRF_WIDE_KERNELS
#define TPRF_FROM_TABLE(table, ...) (wide && cpu_has_wide_kernels() ? wide::table(__VA_ARGS__) : base::table(__VA_ARGS__))
#else
#define TPRF_FROM_TABLE(table, ...) ((void)wide, base::table(__VA_ARGS__))
#endif

RecentKernel recent_kernel_for(int C, int bins, bool wide) { return TPRF_FROM_TABLE(recent_table, C, bins); }

PackedKernel packed_kernel_for(int C, int bins, bool wide) { return TPRF_FROM_TABLE(packed_table, C, bins); }

// Lane counts with kernels of their own: one or three channels of one illumination, a grey batch of 8
// or 16. Any other count takes the generic kernels (gather_lanes, a run-time lane loop).
GatherKernel pick_kernel(int C, int bins, bool wide) { return TPRF_FROM_TABLE(long_table, C, bins); }

LaneKernel lane_kernel_for(int bins, bool wide) { return TPRF_FROM_TABLE(lane_table, bins); }

#undef TPRF_FROM_TABLE

// The same for windows longer than kLongestWindow without a specialisation (long blocks): summed
// straight into the accumulators, a bin's lanes at a time.
void gather_long_any(const LongCall& call) {
    const Links& links = *call.links;
    const std::uint64_t end = call.end;
    const std::uint32_t source_end = call.source_end;
    const float inv_bin = call.inv_bin;
    const DelayMode mode = call.mode;
    const float* const ring = call.ring;
    const RingSlot* const slots = call.slots;
    const std::int64_t b0 = call.b0;
    const int C = call.lanes, bt = call.bins;
    float* __restrict acc = call.acc;
    const std::size_t stride = call.stride;
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    std::uint64_t k = *call.cursor;
    for (; k < end && source[k] < source_end; ++k) {
        const DelayTaps t = delay_taps_f(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < bt) continue;
        const float* __restrict h =
            ring + slots[source[k]].offset + std::size_t(int((b0 - t.lag - 1) & slots[source[k]].mask)) * std::size_t(C);
        for (int b = 0; b < bt; ++b) {
            float* __restrict a = acc + std::size_t(b) * stride;
            const float* __restrict hb = h + std::size_t(b) * std::size_t(C);
            for (int c = 0; c < C; ++c) {  // two accumulations, as in gather_long
                a[c] += t.w0 * hb[c + C];
                a[c] += t.w1 * hb[c];
            }
        }
    }
    *call.cursor = k;
}

}  // namespace tprf::solver_detail
