#include "tprf/transport/solver.h"

#include "tprf/transport/illumination.h"
#include "tprf/core/error.h"
#include "tprf/transport/links.h"
#include "tprf/geometry/patches.h"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

namespace tprf {
namespace {

// A link's delay as two taps: B_src[t - lag] * w0 + B_src[t - lag - 1] * w1. Nearest rounds the delay
// to a whole bin; linear spreads a bin of the source (taken as uniform over the bin) over the two
// bins it overlaps once shifted, so that the mean arrival time is exact and no energy is lost.
struct Taps {
    int lag;
    float w0;
    float w1;
};

// In single precision: it runs once per link and block in the hot loop. Delays stay below 2^24 bins, so
// the fraction keeps at least a few thousandths of a bin.
inline Taps link_taps(float distance, float inv_bin, DelayMode mode, float ff) {
    const float d = distance * inv_bin;
    if (mode == DelayMode::Nearest) return {int(d + 0.5f), ff, 0.0f};
    const int lag = int(d);  // d >= 0: truncation is the floor
    const float frac = d - float(lag);
    return {lag, ff * (1.0f - frac), ff * frac};
}

struct ShortLink {
    std::uint32_t source;
    int lag;     // < block length; lag 0 keeps only its w1 tap here (w0 is in the same-bin list)
    float w0;
    float w1;
};

struct SameBinLink {
    std::uint32_t source;
    float w;
};

// Which rings exist, what each gathers from and where each pulse order goes (see SolveBlock).
struct LayerPlan {
    std::vector<int> source;  // per layer: the layer it gathers from, -1 for none
    int total = -1;           // layer that holds every order, or -1 when the total is the sum of layers
    int exact = 0;            // layers 0..exact-1 hold exactly one order each
    int terms = 0;            // per-order terms in the output

    int layers() const { return int(source.size()); }
};

LayerPlan plan_layers(int max_bounces, int bounce_terms) {
    LayerPlan plan;
    if (max_bounces >= 0) {
        plan.exact = max_bounces + 1;
        for (int l = 0; l < plan.exact; ++l) plan.source.push_back(l - 1);
        plan.terms = bounce_terms > 0 ? plan.exact : 0;
    } else if (bounce_terms > 1) {
        plan.exact = bounce_terms - 1;
        for (int l = 0; l < plan.exact; ++l) plan.source.push_back(l - 1);
        plan.total = plan.exact;
        plan.source.push_back(plan.total);
        plan.terms = bounce_terms;
    } else {
        plan.total = 0;
        plan.source.push_back(0);
    }
    return plan;
}

bool scene_is_grey(const PatchSet& patches, const Emission& emission) {
    auto grey = [](const Rgb& c) { return c[0] == c[1] && c[1] == c[2]; };
    for (const Rgb& a : patches.albedo)
        if (!grey(a)) return false;
    for (const Pulse& p : emission.pulses)
        if (!grey(p.energy)) return false;
    return true;
}

// The long-link kernel for one receiver and one source tile: the block's sums stay in registers
// (C * BT floats) across all the receiver's links, and go to memory once at the end.
template <int C, int BT>
void gather_long(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end, float inv_bin,
                 DelayMode mode, const float* ring, std::size_t stride, int rmask, std::int64_t b0, float* acc) {
    // Locals, not the reference and the vectors: a store through `cursor` would make the compiler
    // reload every array pointer once per link.
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    float local[C * BT] = {};
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < BT) continue;
        const float* __restrict h = ring + std::size_t(source[k]) * stride + std::size_t(int((b0 - t.lag - 1) & rmask)) * C;
        // Two separate accumulations: written as one sum, the compiler (no -ffast-math) must round
        // w0 h + w1 h first, which costs a multiply, an FMA and an add instead of two FMAs.
        for (int e = 0; e < C * BT; ++e) {
            local[e] += t.w0 * h[e + C];
            local[e] += t.w1 * h[e];
        }
    }
    cursor = k;
    for (int e = 0; e < C * BT; ++e) acc[e] += local[e];
}

// The same for block lengths without a specialisation.
void gather_long_any(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end,
                     float inv_bin, DelayMode mode, const float* ring, std::size_t stride, int rmask, std::int64_t b0,
                     int C, int bt, float* __restrict acc) {
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    const int len = C * bt;
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < bt) continue;
        const float* __restrict h =
            ring + std::size_t(source[k]) * stride + std::size_t(int((b0 - t.lag - 1) & rmask)) * std::size_t(C);
        for (int e = 0; e < len; ++e) {  // two accumulations, as in gather_long
            acc[e] += t.w0 * h[e + C];
            acc[e] += t.w1 * h[e];
        }
    }
    cursor = k;
}

using GatherKernel = void (*)(const Links&, std::uint64_t&, std::uint64_t, std::uint32_t, float, DelayMode,
                              const float*, std::size_t, int, std::int64_t, float*);

GatherKernel pick_kernel(int C, int bt) {
    if (C == 1 && bt == 16) return gather_long<1, 16>;
    if (C == 1 && bt == 32) return gather_long<1, 32>;
    if (C == 1 && bt == 64) return gather_long<1, 64>;
    if (C == 3 && bt == 16) return gather_long<3, 16>;
    if (C == 3 && bt == 32) return gather_long<3, 32>;
    return nullptr;
}

// Tiles of the long-link pass (see step 1 of the march): 32 receivers' block accumulators (at most
// 32 x 3 x bt floats) and 128 sources' rings (128 x ring x 3 floats, under 1 MB for rings of 512) fit
// in a core's L2 together.
constexpr std::size_t kReceiverTile = 256;
constexpr std::size_t kSourceTile = 64;

int next_pow2(int v) {
    int r = 1;
    while (r < v) r <<= 1;
    return r;
}

}  // namespace

SolveStats solve_transient(const PatchSet& patches, const Links& links, const Emission& emission,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink) {
    const std::size_t n = patches.size();
    TPRF_CHECK_EQ(links.receivers(), n);
    TPRF_CHECK_EQ(emission.row.size(), n + 1);
    const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
    const int bt = next_pow2(std::clamp(options.block_bins, 1, 4096));
    const int C = scene_is_grey(patches, emission) ? 1 : 3;
    const double bin_m = time.bin_width_m(), start_m = time.start_m();
    const double inv_bin = 1.0 / bin_m;
    const float inv_bin_f = float(inv_bin);
    const LayerPlan plan = plan_layers(options.max_bounces, options.bounce_terms);
    const int L = plan.layers();

    // Short and same-bin links, and the largest lag, in one pass over the links.
    std::vector<std::uint64_t> short_row(n + 1, 0), same_row(n + 1, 0);
    std::vector<ShortLink> short_links;
    std::vector<SameBinLink> same_links;
    int max_lag = 0;
    for (std::size_t i = 0; i < n; ++i) {
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) {
            const Taps t = link_taps(links.distance[k], inv_bin_f, options.delay, links.ff[k]);
            max_lag = std::max(max_lag, t.lag);
            if (t.lag >= bt) continue;
            if (t.lag == 0) {
                same_links.push_back({links.source[k], t.w0});
                short_links.push_back({links.source[k], 0, 0.0f, t.w1});
            } else {
                short_links.push_back({links.source[k], t.lag, t.w0, t.w1});
            }
        }
        short_row[i + 1] = short_links.size();
        same_row[i + 1] = same_links.size();
    }

    // Ring: the window [t - lag - 1, t] of every read must fit, plus one block; mirrored so that any
    // window of bt + 1 bins is contiguous.
    const int ring = next_pow2(max_lag + bt + 2);
    const int mirror = bt + 1;
    const std::size_t stride = std::size_t(ring + mirror) * std::size_t(C);
    const std::size_t layers = std::size_t(L);
    std::vector<std::vector<float>> rings(layers, std::vector<float>(n * stride, 0.0f));
    const std::size_t block_values = n * std::size_t(bt) * std::size_t(C);
    std::vector<std::vector<float>> acc(layers, std::vector<float>(block_values));
    std::vector<std::vector<float>> emit(layers, std::vector<float>(block_values));
    std::vector<float> base(std::size_t(L) * n * std::size_t(C)), iterate(std::size_t(L) * n * std::size_t(C));
    std::vector<float> out_total(n * std::size_t(bt) * 3);
    std::vector<float> out_terms(std::size_t(plan.terms) * n * std::size_t(bt) * 3);

    // Pulses by bin (exact containment: a delta at path p lies in the bin that holds p).
    auto pulse_bin = [&](const Pulse& p) { return std::int64_t(std::floor((p.path - start_m) * inv_bin)); };
    std::int64_t first_pulse_bin = 0;
    for (const Pulse& p : emission.pulses) first_pulse_bin = std::min(first_pulse_bin, pulse_bin(p));
    const std::int64_t T = time.bins;
    // Light sent before the window opens still travels: march from the earliest pulse, block-aligned.
    std::int64_t b_begin = first_pulse_bin;
    b_begin = (b_begin >= 0) ? 0 : -((-b_begin + bt - 1) / bt) * bt;
    const std::int64_t blocks = (T - b_begin + bt - 1) / bt;

    SolveStats stats;
    stats.block_bins = bt;
    stats.ring_bins = ring;
    stats.channels = C;
    std::size_t working = 0;
    for (const auto& r : rings) working += r.size() * sizeof(float);
    working += 2 * std::size_t(L) * block_values * sizeof(float) + 2 * base.size() * sizeof(float) +
               (out_total.size() + out_terms.size()) * sizeof(float) + short_links.size() * sizeof(ShortLink) +
               same_links.size() * sizeof(SameBinLink) + 2 * (n + 1) * sizeof(std::uint64_t);
    stats.working_bytes = working;
    int fed_layers = 0;
    for (int l = 0; l < L; ++l) fed_layers += plan.source[std::size_t(l)] >= 0;
    const bool has_same_bin = !same_links.empty();
    const int rmask = ring - 1;
    auto ring_at = [&](int layer, std::size_t patch, std::int64_t bin) {
        return rings[std::size_t(layer)].data() + patch * stride + std::size_t(int(bin & rmask)) * std::size_t(C);
    };
    auto store = [&](int layer, std::size_t patch, std::int64_t bin, const float* v) {
        const int pos = int(bin & rmask);
        float* r = rings[std::size_t(layer)].data() + patch * stride;
        for (int c = 0; c < C; ++c) r[std::size_t(pos * C + c)] = v[c];
        if (pos < mirror)
            for (int c = 0; c < C; ++c) r[std::size_t((pos + ring) * C + c)] = v[c];
    };
    // Layer that an emission pulse of order `order` enters, besides the total (-1: none).
    auto exact_layer = [&](int order) { return order < plan.exact ? order : -1; };

    const std::size_t receiver_tiles = (n + kReceiverTile - 1) / kReceiverTile;
    const GatherKernel kernel = pick_kernel(C, bt);
    float jacobi_change = 0.0f, jacobi_largest = 0.0f;  // shared by the threads' max-reductions
    std::atomic<int> worst_iterations{0};

    using clock = std::chrono::steady_clock;
    auto lap = [](clock::time_point& since) {
        const auto now = clock::now();
        const double s = std::chrono::duration<double>(now - since).count();
        since = now;
        return s;
    };
    for (std::int64_t blk = 0; blk < blocks; ++blk) {
        const std::int64_t b0 = b_begin + blk * bt;
        clock::time_point since = clock::now();
        double long_seconds = 0.0;
        // One parallel region per block, so that the sink below runs outside it and can use every
        // thread itself (inside, a nested region would get one thread). Phase times from thread 0:
        // every phase ends at a barrier, so they are the phases' wall times.
#pragma omp parallel num_threads(threads)
        {
            const bool timer = omp_get_thread_num() == 0;

            // 1. Per receiver: the block's emission, and every long link (lag >= bt) as one contiguous
            //    multiply-add over the block, reading history that is already final. Receivers go in
            //    tiles and their links (sorted by source) in source tiles, so that the histories one
            //    source tile reads stay in cache for all the tile's receivers.
#pragma omp for schedule(dynamic, 1)
            for (std::size_t tile = 0; tile < receiver_tiles; ++tile) {
                const std::size_t i0 = tile * kReceiverTile, i1 = std::min(n, i0 + kReceiverTile);
                std::uint64_t cursor[kReceiverTile];
                for (std::size_t i = i0; i < i1; ++i) {
                    for (int l = 0; l < L; ++l) {
                        std::fill_n(acc[std::size_t(l)].data() + i * std::size_t(bt * C), bt * C, 0.0f);
                        std::fill_n(emit[std::size_t(l)].data() + i * std::size_t(bt * C), bt * C, 0.0f);
                    }
                    for (std::uint64_t k = emission.row[i]; k < emission.row[i + 1]; ++k) {
                        const Pulse& p = emission.pulses[k];
                        const std::int64_t b = pulse_bin(p);
                        if (!p.propagates || b < b0 || b >= b0 + bt) continue;
                        const std::size_t at = i * std::size_t(bt * C) + std::size_t((b - b0) * C);
                        const int targets[2] = {plan.total, exact_layer(p.order)};
                        for (int l : targets)
                            if (l >= 0)
                                for (int c = 0; c < C; ++c) emit[std::size_t(l)][at + std::size_t(c)] += float(p.energy[c]);
                    }
                }
                for (int l = 0; l < L; ++l) {
                    const int src = plan.source[std::size_t(l)];
                    if (src < 0) continue;
                    const float* ring_src = rings[std::size_t(src)].data();
                    for (std::size_t i = i0; i < i1; ++i) cursor[i - i0] = links.row[i];
                    for (std::size_t s0 = 0; s0 < n; s0 += kSourceTile) {
                        const std::uint32_t s1 = std::uint32_t(std::min(n, s0 + kSourceTile));
                        for (std::size_t i = i0; i < i1; ++i) {
                            float* a = acc[std::size_t(l)].data() + i * std::size_t(bt * C);
                            if (kernel)
                                kernel(links, cursor[i - i0], links.row[i + 1], s1, inv_bin_f, options.delay, ring_src,
                                       stride, rmask, b0, a);
                            else
                                gather_long_any(links, cursor[i - i0], links.row[i + 1], s1, inv_bin_f, options.delay,
                                                ring_src, stride, rmask, b0, C, bt, a);
                        }
                    }
                }
            }

            if (timer) long_seconds = lap(since);

            // 2. Bin by bin: short links, then the same-bin system by Jacobi iteration.
            for (int o = 0; o < bt; ++o) {
                const std::int64_t bin = b0 + o;
#pragma omp for schedule(static)
                for (std::size_t i = 0; i < n; ++i) {
                    for (int l = 0; l < L; ++l) {
                        const int src = plan.source[std::size_t(l)];
                        float g[3] = {0, 0, 0};
                        const std::size_t at = i * std::size_t(bt * C) + std::size_t(o * C);
                        if (src >= 0) {
                            for (int c = 0; c < C; ++c) g[c] = acc[std::size_t(l)][at + std::size_t(c)];
                            for (std::uint64_t k = short_row[i]; k < short_row[i + 1]; ++k) {
                                const ShortLink& s = short_links[k];
                                const float* h1 = ring_at(src, s.source, bin - s.lag - 1);
                                if (s.lag > 0) {
                                    const float* h0 = ring_at(src, s.source, bin - s.lag);
                                    for (int c = 0; c < C; ++c) g[c] += s.w0 * h0[c] + s.w1 * h1[c];
                                } else {
                                    for (int c = 0; c < C; ++c) g[c] += s.w1 * h1[c];
                                }
                            }
                        }
                        float b[3];
                        for (int c = 0; c < C; ++c)
                            b[c] = emit[std::size_t(l)][at + std::size_t(c)] + float(patches.albedo[i][c]) * g[c];
                        float* keep = base.data() + (std::size_t(l) * n + i) * std::size_t(C);
                        for (int c = 0; c < C; ++c) keep[c] = b[c];
                        store(l, i, bin, b);
                    }
                }
                if (has_same_bin) {
                    for (int iteration = 1; iteration <= 200; ++iteration) {
#pragma omp single
                        {
                            jacobi_change = 0.0f;
                            jacobi_largest = 0.0f;
                        }
#pragma omp for schedule(static) reduction(max : jacobi_change, jacobi_largest)
                        for (std::size_t i = 0; i < n; ++i) {
                            for (int l = 0; l < L; ++l) {
                                const int src = plan.source[std::size_t(l)];
                                const float* keep = base.data() + (std::size_t(l) * n + i) * std::size_t(C);
                                float* next = iterate.data() + (std::size_t(l) * n + i) * std::size_t(C);
                                float g[3] = {0, 0, 0};
                                if (src >= 0)
                                    for (std::uint64_t k = same_row[i]; k < same_row[i + 1]; ++k) {
                                        const float* h = ring_at(src, same_links[k].source, bin);
                                        for (int c = 0; c < C; ++c) g[c] += same_links[k].w * h[c];
                                    }
                                const float* now = ring_at(l, i, bin);
                                for (int c = 0; c < C; ++c) {
                                    next[c] = keep[c] + float(patches.albedo[i][c]) * g[c];
                                    jacobi_change = std::max(jacobi_change, std::abs(next[c] - now[c]));
                                    jacobi_largest = std::max(jacobi_largest, std::abs(next[c]));
                                }
                            }
                        }
                        // Read the shared result before the barrier that ends the next loop, so that the
                        // next iteration's reset cannot overtake a slow thread.
                        const bool converged = jacobi_change <= 1e-7f * jacobi_largest;
#pragma omp for schedule(static)
                        for (std::size_t i = 0; i < n; ++i)
                            for (int l = 0; l < L; ++l)
                                store(l, i, bin, iterate.data() + (std::size_t(l) * n + i) * std::size_t(C));
                        // Float resolution: further sweeps cannot change the stored values meaningfully.
                        if (converged) {
#pragma omp single
                            {
                                if (iteration > worst_iterations.load()) worst_iterations.store(iteration);
                            }
                            break;
                        }
                    }
                }
            }

        }  // omp parallel
        stats.seconds_long += long_seconds;
        stats.seconds_short += lap(since);

        // 3. Hand the block's bins inside the window to the sink.
        const std::int64_t lo = std::max<std::int64_t>(b0, 0), hi = std::min<std::int64_t>(b0 + bt, T);
        if (lo < hi) {
            const int count = int(hi - lo);
            auto put = [&](float* out, std::size_t i, int o, int c, float v) {
                out[(i * std::size_t(count) + std::size_t(o)) * 3 + std::size_t(c)] = v;
            };
#pragma omp parallel for schedule(static) num_threads(threads)
            for (std::size_t i = 0; i < n; ++i) {
                for (int o = 0; o < count; ++o) {
                    const std::int64_t bin = lo + o;
                    float total[3] = {0, 0, 0};
                    if (plan.total >= 0) {
                        const float* v = ring_at(plan.total, i, bin);
                        for (int c = 0; c < C; ++c) total[c] = v[c];
                    } else {
                        for (int l = 0; l < L; ++l) {
                            const float* v = ring_at(l, i, bin);
                            for (int c = 0; c < C; ++c) total[c] += v[c];
                        }
                    }
                    for (int c = 0; c < 3; ++c) put(out_total.data(), i, o, c, total[C == 1 ? 0 : c]);
                    for (int k = 0; k < plan.terms; ++k) {
                        float* term = out_terms.data() + std::size_t(k) * n * std::size_t(count) * 3;
                        float v[3] = {0, 0, 0};
                        if (k < plan.exact) {
                            const float* r = ring_at(k, i, bin);
                            for (int c = 0; c < C; ++c) v[c] = r[c];
                        } else {  // the tail: every order from k on
                            for (int c = 0; c < C; ++c) v[c] = total[c];
                            for (int l = 0; l < plan.exact; ++l) {
                                const float* r = ring_at(l, i, bin);
                                for (int c = 0; c < C; ++c) v[c] -= r[c];
                            }
                        }
                        for (int c = 0; c < 3; ++c) put(term, i, o, c, v[C == 1 ? 0 : c]);
                    }
                }
                // Pulses seen but not propagated (the laser spot) join the output only.
                for (std::uint64_t k = emission.row[i]; k < emission.row[i + 1]; ++k) {
                    const Pulse& p = emission.pulses[k];
                    const std::int64_t b = pulse_bin(p);
                    if (p.propagates || b < lo || b >= hi) continue;
                    if (plan.total < 0 && p.order >= plan.exact) continue;  // beyond max_bounces
                    const int o = int(b - lo);
                    for (int c = 0; c < 3; ++c) {
                        out_total[(i * std::size_t(count) + std::size_t(o)) * 3 + std::size_t(c)] += float(p.energy[c]);
                        if (plan.terms > 0) {
                            const int term = std::min<int>(p.order, plan.terms - 1);
                            out_terms[((std::size_t(term) * n + i) * std::size_t(count) + std::size_t(o)) * 3 + std::size_t(c)] +=
                                float(p.energy[c]);
                        }
                    }
                }
            }
            SolveBlock block;
            block.first_bin = int(lo);
            block.bins = count;
            block.patches = n;
            block.radiosity = out_total.data();
            block.terms = plan.terms;
            block.per_order = plan.terms > 0 ? out_terms.data() : nullptr;
            if (sink) sink(block);
        }
        if (options.progress) options.progress("solve", double(blk + 1) / double(blocks));
        stats.seconds_sink += lap(since);
    }

    stats.link_bin_updates = std::uint64_t(links.size()) * std::uint64_t(fed_layers) * std::uint64_t(blocks) * std::uint64_t(bt);
    stats.max_jacobi_iterations = worst_iterations.load();
    stats.short_links = short_links.size();
    return stats;
}

}  // namespace tprf
