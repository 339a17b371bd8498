#pragma once
/// Machine ceilings that the benchmarks compare their kernels against, measured in the same run.

namespace tprf::bench {

/// Peak single-precision fused multiply-add rate on `threads` OpenMP threads, GFMA/s (fused
/// multiply-adds per second / 1e9, each SIMD lane counted): a register-resident loop of independent
/// FMA chains, best of a few repeats, with the widest vectors the CPU has (16-lane AVX-512 where it
/// has it, else 8-lane AVX2), or with `vector_bits` = 256 or 512 that one alone. 0 when the CPU lacks
/// the instructions (AVX2 + FMA, or AVX-512 F for 512) or for any other `vector_bits`.
double measure_fma_peak_gflops(int threads, int vector_bits = 0);

/// Sustained memory bandwidth on `threads` OpenMP threads, GB/s (1e9 bytes/s): a STREAM triad
/// a[i] = b[i] + s * c[i] over three 256 MB arrays, counting the bytes read and written (24 per
/// element; the write-allocate read of `a` is not counted, as in STREAM), best of a few passes.
double measure_memory_bandwidth_gbs(int threads);

}  // namespace tprf::bench
