#include "tprf/transport/solver.h"

#include "tprf/transport/illumination.h"
#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/transport/link_set.h"
#include "tprf/geometry/patches.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <bit>
#include <atomic>
#include <chrono>
#include <cmath>
#include <type_traits>

namespace tprf {
namespace {

// Most values marched per patch and bin: the three colours of kMaxBatch illuminations.
constexpr int kMaxLanes = 3 * kMaxBatch;

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
    std::uint32_t source;  // the source patch's position (SolvePlan::order)
    int lag;     // < block length; lag 0 keeps only its w1 tap here (w0 is in the same-bin list)
    float w0;
    float w1;
};

struct SameBinLink {
    std::uint32_t source;  // the source patch's position (SolvePlan::order)
    float w;
};

// A link through tinted mirrors or glass (Links::tint), between patches: its taps in each colour, ff x
// tints[t][c] split as link_taps splits a grey link's. The long-pass kernels and the lists above keep
// to grey links, whose one weight serves every lane; the few tinted ones have lists of their own.
struct TintedLink {
    std::uint32_t source;  // long list: the source patch; bin-by-bin list: its position
    int lag;               // as ShortLink's (lag 0: the w1 taps only, w0 is in the same-bin list)
    float w0[3];
    float w1[3];
};

struct TintedSameLink {
    std::uint32_t source;  // the source patch's position
    float w[3];
};

// Whether link k carries a tint other than {1, 1, 1} (which leaves it a grey link).
bool tinted_link(const Links& links, std::uint64_t k) {
    if (links.tint.empty() || links.tint[k] == 0) return false;
    const std::array<float, 3>& f = links.tints[links.tint[k]];
    return !(f[0] == 1.0f && f[1] == 1.0f && f[2] == 1.0f);
}

bool any_tinted(const Links& links) {
    for (std::uint64_t k = 0; k < links.tint.size(); ++k)
        if (tinted_link(links, k)) return true;
    return false;
}

// Link k's taps in each colour, from `source` (a patch or its position).
TintedLink tinted_taps(const Links& links, std::uint64_t k, std::uint32_t source, float inv_bin, DelayMode mode) {
    TintedLink out{source, 0, {}, {}};
    const std::array<float, 3>& f = links.tints[links.tint[k]];
    for (int c = 0; c < 3; ++c) {
        const Taps t = link_taps(links.distance[k], inv_bin, mode, links.ff[k] * f[std::size_t(c)]);
        out.lag = t.lag;
        out.w0[c] = t.w0;
        out.w1[c] = t.w1;
    }
    return out;
}

// sum[e] += w[c] h[e] over C lanes, c being lane e's colour: lanes come in threes, one per colour, or
// are grey (`channels` 1), when every tint is grey too and w[0] serves them all.
inline void add_tinted(float* __restrict sum, const float* w, const float* __restrict h, int C, int channels) {
    if (channels == 1) {
        for (int e = 0; e < C; ++e) sum[e] += w[0] * h[e];
        return;
    }
    for (int e = 0; e + 3 <= C; e += 3)  // C is 3 K
        for (int c = 0; c < 3; ++c) sum[e + c] += w[c] * h[e + c];
}

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

bool scene_is_grey(const PatchSet& patches, const Links& links, std::span<const Illumination* const> batch) {
    auto grey = [](const Rgb& c) { return c[0] == c[1] && c[1] == c[2]; };
    for (const Rgb& a : patches.albedo)
        if (!grey(a)) return false;
    for (std::uint16_t t : links.tint)
        if (!(links.tints[t][0] == links.tints[t][1] && links.tints[t][1] == links.tints[t][2])) return false;
    for (const Illumination* illumination : batch)
        for (const Pulse& p : illumination->pulses)
            if (!grey(p.energy)) return false;
    return true;
}

// Where node m's ring of recent radiosity lives in a layer's ring array: `length` bins (a power of
// two, as long as the node's longest outgoing link needs), then a mirror of the first bins, so that
// any window of a block plus one bin is contiguous.
struct RingSlot {
    std::uint64_t offset;  // floats
    std::int32_t mask;     // length - 1
    std::int32_t length;
    std::int32_t mirror;   // bins mirrored after the ring: the longest window a long link reads, plus one
};

// Links ahead whose source history the long-link kernel prefetches.
constexpr std::uint64_t kAhead = 8;

// The long-link kernel for one receiver and one source tile: the block's sums stay in registers
// (C * BT floats) across all the receiver's links, and go to memory once at the end.
template <int C, int BT>
void gather_long(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end, float inv_bin,
                 DelayMode mode, const float* ring, const RingSlot* slots, std::int64_t b0, float* acc,
                 std::size_t stride) {
    // Locals, not the reference and the vectors: a store through `cursor` would make the compiler
    // reload every array pointer once per link.
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    float local[C * BT] = {};
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        // Sparse rows (hierarchical sets) read a scattered ring per link: ask for the one kAhead links
        // on, and for the slot of the one after that, while this link is summed.
        if (k + 2 * kAhead < end) {
            __builtin_prefetch(&slots[source[k + 2 * kAhead]]);
            const RingSlot& next = slots[source[k + kAhead]];
            const int lag = int(distance[k + kAhead] * inv_bin);
            const float* at = ring + next.offset + std::size_t(int((b0 - lag - 1) & next.mask)) * C;
            for (int line = 0; line < (C * (BT + 1) * 4 + 63) / 64 && line < 4; ++line)
                __builtin_prefetch(at + 16 * line);
        }
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < BT) continue;
        const RingSlot& slot = slots[source[k]];
        const float* __restrict h = ring + slot.offset + std::size_t(int((b0 - t.lag - 1) & slot.mask)) * C;
        // Two separate accumulations: written as one sum, the compiler (no -ffast-math) must round
        // w0 h + w1 h first, which costs a multiply, an FMA and an add instead of two FMAs.
        for (int e = 0; e < C * BT; ++e) {
            local[e] += t.w0 * h[e + C];
            local[e] += t.w1 * h[e];
        }
    }
    if (k == cursor) return;  // no link of this window in this source tile: nothing to add
    cursor = k;
    for (int b = 0; b < BT; ++b)
        for (int c = 0; c < C; ++c) acc[std::size_t(b) * stride + std::size_t(c)] += local[b * C + c];
}

// The same for any lane count C and windows of BT bins: the sums (C * BT floats) in a local array,
// each link one contiguous multiply-add over it, which vectorises over bins and lanes alike.
template <int BT>
void gather_lanes(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end,
                  float inv_bin, DelayMode mode, const float* ring, const RingSlot* slots, std::int64_t b0, int C,
                  float* acc, std::size_t stride) {
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    const int len = C * BT;
    float local[kMaxLanes * BT];
    std::fill_n(local, len, 0.0f);
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        if (k + 2 * kAhead < end) {  // as in gather_long
            __builtin_prefetch(&slots[source[k + 2 * kAhead]]);
            const RingSlot& next = slots[source[k + kAhead]];
            const int lag = int(distance[k + kAhead] * inv_bin);
            const float* at = ring + next.offset + std::size_t(int((b0 - lag - 1) & next.mask)) * std::size_t(C);
            for (int line = 0; line < 4; ++line) __builtin_prefetch(at + 16 * line);
        }
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < BT) continue;
        const RingSlot& slot = slots[source[k]];
        const float* __restrict h = ring + slot.offset + std::size_t(int((b0 - t.lag - 1) & slot.mask)) * std::size_t(C);
        for (int e = 0; e < len; ++e) {  // two accumulations, as in gather_long
            local[e] += t.w0 * h[e + C];
            local[e] += t.w1 * h[e];
        }
    }
    if (k == cursor) return;
    cursor = k;
    for (int b = 0; b < BT; ++b)
        for (int c = 0; c < C; ++c) acc[std::size_t(b) * stride + std::size_t(c)] += local[b * C + c];
}

// The same for windows longer than kLongestWindow without a specialisation (long blocks): summed
// straight into the accumulators, a bin's lanes at a time.
void gather_long_any(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end,
                     float inv_bin, DelayMode mode, const float* ring, const RingSlot* slots, std::int64_t b0,
                     int C, int bt, float* __restrict acc, std::size_t stride) {
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
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
    cursor = k;
}

using GatherKernel = void (*)(const Links&, std::uint64_t&, std::uint64_t, std::uint32_t, float, DelayMode,
                              const float*, const RingSlot*, std::int64_t, float*, std::size_t);
using LaneKernel = void (*)(const Links&, std::uint64_t&, std::uint64_t, std::uint32_t, float, DelayMode,
                            const float*, const RingSlot*, std::int64_t, int, float*, std::size_t);

// The long-link kernel for C channels and windows of `bins` bins (the block's and the longer
// windows up to kLongestWindow), or null for the generic one.
template <int C>
GatherKernel kernel_for(int bins) {
    switch (bins) {
        case 1: return gather_long<C, 1>;
        case 2: return gather_long<C, 2>;
        case 4: return gather_long<C, 4>;
        case 8: return gather_long<C, 8>;
        case 16: return gather_long<C, 16>;
        case 32: return gather_long<C, 32>;
        case 64:  // grey scenes only: 3 x 64 sums do not fit in registers
            if constexpr (C == 1) return gather_long<C, 64>;
            return nullptr;
        default: return nullptr;
    }
}

// Lane counts with kernels of their own: one or three channels of one illumination, a grey batch of 8
// or 16. Any other count takes the generic kernels (gather_lanes, a run-time lane loop).
GatherKernel pick_kernel(int C, int bins) {
    switch (C) {
        case 1: return kernel_for<1>(bins);
        case 3: return kernel_for<3>(bins);
        case 8: return kernel_for<8>(bins);
        case 16: return kernel_for<16>(bins);
        default: return nullptr;
    }
}

// The generic kernel for windows of `bins` bins, up to kLongestWindow; null beyond (gather_long_any).
LaneKernel lane_kernel_for(int bins) {
    switch (bins) {
        case 1: return gather_lanes<1>;
        case 2: return gather_lanes<2>;
        case 4: return gather_lanes<4>;
        case 8: return gather_lanes<8>;
        case 16: return gather_lanes<16>;
        case 32: return gather_lanes<32>;
        default: return nullptr;
    }
}

// Calls fn with the lane count C as a std::integral_constant where the bin-by-bin passes are
// specialised for it (as pick_kernel), else with 0: lanes counted at run time.
template <class Fn>
void with_lanes(int C, Fn&& fn) {
    switch (C) {
        case 1: return fn(std::integral_constant<int, 1>{});
        case 3: return fn(std::integral_constant<int, 3>{});
        case 8: return fn(std::integral_constant<int, 8>{});
        case 16: return fn(std::integral_constant<int, 16>{});
        default: return fn(std::integral_constant<int, 0>{});
    }
}

// Tiles of the long-link pass (March::long_pass): a tile of 256 receivers walks its links in tiles of
// 64 sources, so that those sources' rings (64 x ring x 3 floats, under 0.5 MB for rings of 512) stay
// in a core's L2 while every receiver of the tile reads them (sizes measured, bench/RESULTS.md). A
// batch's lanes make them larger; tiles of fewer sources for more lanes (8 for 24 lanes, 12 for 16)
// measured no faster on the Cornell box (bench/solver_bench.cpp, BM_TransientSolveBatch).
constexpr std::size_t kReceiverTile = 256;
constexpr std::size_t kSourceTile = 64;
// Links per receiver below which the sources are not tiled.
constexpr std::size_t kDenseRow = 256;
// Most same-bin sweeps in one bin.
constexpr int kMaxSweeps = 200;
// The long pass's longest window, bins: links at least this long are applied this many bins at a
// time; shorter ones (down to the block) in the longest power-of-two window their delay allows.
constexpr int kLongestWindow = 32;
constexpr int kMaxWindows = 16;

// Everything about the march that is fixed before it starts: sizes, link lists, ring geometry and
// the range of blocks. Computed once; the march only executes it.
struct SolvePlan {
    std::size_t n = 0;              // patches (the leaves: they emit, reflect and are output)
    std::size_t m = 0;              // nodes: patches, then clusters (rings, gathers)
    const ClusterTree* tree = nullptr;
    bool clusters = false;          // push and pull run (a link set with clusters)
    // With clusters: the subtrees that threads take whole (their patches and clusters) and the
    // clusters above them, in preorder.
    std::vector<std::uint32_t> top, subtrees;
    // Sources per tile of the long pass: kSourceTile for dense rows; one tile for sparse ones
    // (hierarchical links), whose rows would otherwise be walked once per empty tile.
    std::size_t source_tile = kSourceTile;
    int threads = 1;
    int bt = 0;                     // block length, bins (a power of two)
    // Windows of the long pass: window s is bt << s bins long and is applied at the blocks that
    // start at its multiples, to the links of delay >= its length (and below the next window's;
    // the last takes every longer one). The accumulators hold the next `acc_bins` bins.
    int windows = 1;
    int acc_bins = 0;               // the last window's length: bt << (windows - 1)
    // Per receiver: where its links of each window start, then where its row ends (windows + 1
    // offsets); with one window, the whole row (the kernel skips links shorter than the block).
    std::vector<std::uint64_t> segments;
    const Links* links = nullptr;   // the set's links, or `sorted` (plan_windows): the grey ones, by window
    Links sorted;
    // Lanes: every value the march keeps per node and bin (rings, accumulators, recent bins, emission,
    // sweep state) is C floats, illumination k's colour c in lane k * channels + c.
    int K = 1;                      // illuminations marched together
    int channels = 3;               // per illumination: 1 for a grey scene (every albedo and pulse), else 3
    int C = 3;                      // lanes, K x channels
    // The lane that holds illumination k's colour c (a grey lane serves all three).
    int lane(int k, int c) const { return k * channels + (channels == 1 ? 0 : c); }
    DelayMode delay = DelayMode::Linear;
    double start_m = 0.0, inv_bin = 0.0;
    float inv_bin_f = 0.0f;
    LayerPlan layers;
    int L = 0;                      // layers
    // Links shorter than a block, applied bin by bin, and the same-bin ones (CSR by receiver).
    std::vector<std::uint64_t> short_row, same_row;  // by receiver position
    std::vector<ShortLink> short_links;
    std::vector<SameBinLink> same_links;
    // Tinted links: those of lag >= bt by receiver patch, applied a block at a time (March::gather_tinted);
    // shorter ones and the same-bin pieces by receiver position, as the lists above. All empty, their
    // rows too, when no link is tinted.
    std::vector<std::uint64_t> tinted_long_row, tinted_short_row, tinted_same_row;
    std::vector<TintedLink> tinted_long, tinted_short;
    std::vector<TintedSameLink> tinted_same;
    bool same_bin() const { return !same_links.empty() || !tinted_same.empty(); }
    // The bin-by-bin passes visit patches in the cluster tree's leaf order (near patches together)
    // and keep their state by position in it: short and same-bin links name their source's position.
    std::vector<std::uint32_t> order;     // position -> patch
    std::vector<std::uint32_t> position;  // patch -> position
    std::vector<float> albedo;            // by position, C per patch: each lane's colour
    // Where node i's values are kept in arrays over nodes that the bin-by-bin passes read: patches
    // by position, clusters by id.
    std::size_t node_slot(std::size_t i) const { return i < n ? position[i] : i; }
    // Chebyshev acceleration of the same-bin sweeps: an upper bound of the spectral radius of the
    // same-bin operator (albedo x weights), or 0 to sweep plain Jacobi.
    double same_radius = 0.0;
    std::vector<float> omega;  // Chebyshev weights of sweeps 1..kMaxSweeps
    int max_lag = 0;
    // Rings: the window [t - lag - 1, t] of every read from a node must fit, plus one block; mirrored
    // so that any window of bt + 1 bins is contiguous. Each node's as long as its longest outgoing
    // link needs: most patches of a hierarchical set send only to near ones (or not at all).
    std::vector<int> send_lag;      // per node: its longest outgoing link's lag, bins
    std::vector<int> send_window;   // per node: its longest outgoing long link's window, bins (0: none)
    std::vector<RingSlot> slots;    // per node
    std::size_t ring_floats = 0;    // per layer
    int ring = 0;                   // longest ring
    std::int64_t T = 0, b_begin = 0, blocks = 0;
    std::int64_t first_emitted = 0;  // first bin handed to the sink (SolverOptions::first_bin)
    int fed_layers = 0;             // layers that gather from links
    GatherKernel kernel[kMaxWindows] = {};  // per window: its kernel for (C, length), or null (generic)
    LaneKernel lane_kernel[kMaxWindows] = {};  // per window without one: the generic kernel, or null (any)

    std::size_t acc_values() const { return m * std::size_t(acc_bins) * std::size_t(C); }
    // Where node i's long-link sums for `bin` are: the accumulators are bin-major (a bin's values of
    // every node together), so that the bin-by-bin passes read them contiguously.
    std::size_t acc_at(std::size_t i, std::int64_t bin) const { return acc_at_slot(node_slot(i), bin); }
    std::size_t acc_at_slot(std::size_t slot, std::int64_t bin) const {
        return (std::size_t(bin & std::int64_t(acc_bins - 1)) * m + slot) * std::size_t(C);
    }
    std::size_t acc_stride() const { return m * std::size_t(C); }
    // The patches' radiosity of the last `recent_bins` bins, bin-major like the accumulators and by
    // position: what the bin-by-bin passes read (a few bins of every patch, contiguous), besides the rings.
    int recent_bins = 0;
    std::size_t recent_at(std::size_t q, std::int64_t bin) const {
        return (std::size_t(bin & std::int64_t(recent_bins - 1)) * n + q) * std::size_t(C);
    }
    int window_bins(int s) const { return bt << s; }
    // The window of a link `lag` bins long: -1 below the block.
    int window_of(int lag) const {
        if (lag < bt) return -1;
        return std::min(int(std::bit_width(unsigned(lag / bt))) - 1, windows - 1);
    }
    // Bin of a pulse (exact containment: a delta at path p lies in the bin that holds p).
    std::int64_t pulse_bin(const Pulse& p) const { return std::int64_t(std::floor((p.path - start_m) * inv_bin)); }
};

// The links that have to be applied bin by bin (lag < bt), as lists by receiver patch; the tinted
// ones (sized only when some link is tinted), long ones included.
struct BinLinks {
    std::vector<std::vector<ShortLink>> shorts;
    std::vector<std::vector<SameBinLink>> same;
    std::vector<std::vector<TintedLink>> tinted_long, tinted_shorts;
    std::vector<std::vector<TintedSameLink>> tinted_same;
};

// Adds a link of lag < bt between patches (the same-bin system takes a lag-0 link's w0 tap).
void add_bin_link(BinLinks& out, std::size_t receiver, std::uint32_t source, const Taps& t, float scale) {
    if (t.lag == 0) {
        out.same[receiver].push_back({source, t.w0 * scale});
        out.shorts[receiver].push_back({source, 0, 0.0f, t.w1 * scale});
    } else {
        out.shorts[receiver].push_back({source, t.lag, t.w0 * scale, t.w1 * scale});
    }
}

// Adds tinted link k from patch s to patch i: as add_bin_link adds a grey one when it is shorter than a
// block, else to the tinted long list, which reads a block and one bin of the source's ring.
void add_tinted_link(BinLinks& out, SolvePlan& plan, const Links& links, std::uint64_t k, std::size_t i,
                     std::uint32_t s) {
    TPRF_CHECK(i < plan.n && s < plan.n);  // only links between patches are tinted (Links::tint)
    TintedLink t = tinted_taps(links, k, s, plan.inv_bin_f, plan.delay);
    if (t.lag >= plan.bt) {
        plan.send_window[s] = std::max(plan.send_window[s], plan.bt);
        out.tinted_long[i].push_back(t);
        return;
    }
    if (t.lag == 0) {
        out.tinted_same[i].push_back({s, {t.w0[0], t.w0[1], t.w0[2]}});
        std::fill_n(t.w0, 3, 0.0f);
    }
    out.tinted_shorts[i].push_back(t);
}

// The tinted lists as CSR: long ones by receiver patch, the others by position, naming their source's.
void flatten_tinted(BinLinks& bins, SolvePlan& plan) {
    plan.tinted_long_row.assign(plan.n + 1, 0);
    plan.tinted_short_row.assign(plan.n + 1, 0);
    plan.tinted_same_row.assign(plan.n + 1, 0);
    for (std::size_t i = 0; i < plan.n; ++i) {
        plan.tinted_long.insert(plan.tinted_long.end(), bins.tinted_long[i].begin(), bins.tinted_long[i].end());
        plan.tinted_long_row[i + 1] = plan.tinted_long.size();
    }
    for (std::size_t q = 0; q < plan.n; ++q) {
        const std::size_t i = plan.order[q];
        for (TintedLink l : bins.tinted_shorts[i]) {
            l.source = plan.position[l.source];
            plan.tinted_short.push_back(l);
        }
        for (TintedSameLink l : bins.tinted_same[i]) {
            l.source = plan.position[l.source];
            plan.tinted_same.push_back(l);
        }
        plan.tinted_short_row[q + 1] = plan.tinted_short.size();
        plan.tinted_same_row[q + 1] = plan.tinted_same.size();
    }
}

// Sorts every link into the long pass (lag >= bt), the bin-by-bin pass (0 < lag < bt) or both the
// bin-by-bin and the same-bin system (lag 0: its w0 tap is within the bin). The bin-by-bin passes
// touch patches only: a link shorter than a block with a cluster at either end (which the
// hierarchical build avoids when it knows the bin) is applied as the links between their patches,
// the receiver's each taking the whole link (push), the source's each its share of the area (pull).
void split_links(const PatchSet& patches, const Links& links, SolvePlan& plan) {
    const ClusterTree& tree = *plan.tree;
    BinLinks bins;
    bins.shorts.resize(plan.n);
    bins.same.resize(plan.n);
    const bool tinted = any_tinted(links);
    if (tinted) {
        bins.tinted_long.resize(plan.n);
        bins.tinted_shorts.resize(plan.n);
        bins.tinted_same.resize(plan.n);
    }
    plan.send_lag.assign(plan.m, 0);
    plan.send_window.assign(plan.m, 0);
    for (std::size_t i = 0; i < plan.m; ++i) {
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) {
            const Taps t = link_taps(links.distance[k], plan.inv_bin_f, plan.delay, links.ff[k]);
            plan.max_lag = std::max(plan.max_lag, t.lag);
            const std::uint32_t s = links.source[k];
            plan.send_lag[s] = std::max(plan.send_lag[s], t.lag);
            if (tinted && tinted_link(links, k)) {
                add_tinted_link(bins, plan, links, k, i, s);
                continue;
            }
            if (t.lag >= plan.bt) {
                plan.send_window[s] = std::max(plan.send_window[s], plan.window_bins(plan.window_of(t.lag)));
                continue;
            }
            if (i < plan.n && s < plan.n) {
                add_bin_link(bins, i, s, t, 1.0f);
                continue;
            }
            for (std::uint32_t r = tree.first[i]; r < tree.last[i]; ++r)
                for (std::uint32_t q = tree.first[s]; q < tree.last[s]; ++q) {
                    const std::uint32_t leaf = tree.leaf_order[q];
                    add_bin_link(bins, tree.leaf_order[r], leaf, t, float(tree.area[leaf] / tree.area[s]));
                }
        }
    }
    plan.order.assign(tree.leaf_order.begin(), tree.leaf_order.end());
    plan.position.assign(plan.n, 0);
    for (std::size_t q = 0; q < plan.n; ++q) plan.position[plan.order[q]] = std::uint32_t(q);
    for (std::size_t i = 0; i < plan.n; ++i) {
        for (ShortLink& l : bins.shorts[i]) l.source = plan.position[l.source];
        for (SameBinLink& l : bins.same[i]) l.source = plan.position[l.source];
    }
    plan.short_row.assign(plan.n + 1, 0);
    plan.same_row.assign(plan.n + 1, 0);
    plan.albedo.resize(plan.n * std::size_t(plan.C));
    for (std::size_t q = 0; q < plan.n; ++q) {
        const std::size_t i = plan.order[q];
        plan.short_links.insert(plan.short_links.end(), bins.shorts[i].begin(), bins.shorts[i].end());
        plan.same_links.insert(plan.same_links.end(), bins.same[i].begin(), bins.same[i].end());
        std::vector<ShortLink>().swap(bins.shorts[i]);
        std::vector<SameBinLink>().swap(bins.same[i]);
        plan.short_row[q + 1] = plan.short_links.size();
        plan.same_row[q + 1] = plan.same_links.size();
        for (int c = 0; c < plan.C; ++c)
            plan.albedo[q * std::size_t(plan.C) + std::size_t(c)] = float(patches.albedo[i][c % plan.channels]);
    }
    if (tinted) flatten_tinted(bins, plan);
}

// plan.sorted: the grey links of every row (tinted ones have lists of their own), each row stably
// sorted by window when `by_window`, so that sources stay non-decreasing within a window.
template <class WindowFn>
void copy_grey_links(const Links& links, SolvePlan& plan, bool by_window, WindowFn window) {
    Links& out = plan.sorted;
    out.row.assign(links.row.size(), 0);
    out.source.reserve(links.size());
    out.ff.reserve(links.size());
    out.distance.reserve(links.size());
    std::vector<std::uint64_t> order;
    for (std::size_t i = 0; i < plan.m; ++i) {
        order.clear();
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k)
            if (!tinted_link(links, k)) order.push_back(k);
        if (by_window)
            std::stable_sort(order.begin(), order.end(),
                             [&](std::uint64_t a, std::uint64_t b) { return window(links, a) < window(links, b); });
        for (std::uint64_t k : order) {
            out.source.push_back(links.source[k]);
            out.ff.push_back(links.ff[k]);
            out.distance.push_back(links.distance[k]);
        }
        out.row[i + 1] = out.source.size();
    }
}

// The long pass's windows and every row's range of links per window (SolvePlan::segments). Rows of a
// hierarchical set come sorted by delay octave, which for the linear delay orders them by window;
// other rows are sorted here, into a copy, when more than one window is used. The kernels read grey
// links only: a set with tinted links is copied without them.
void plan_windows(const Links& links, SolvePlan& plan) {
    plan.acc_bins = std::max(plan.bt, kLongestWindow);
    plan.windows = 1 + std::countr_zero(unsigned(plan.acc_bins / plan.bt));
    TPRF_CHECK_LE(plan.windows, kMaxWindows);
    plan.links = &links;
    const std::size_t S = std::size_t(plan.windows);
    plan.segments.assign(plan.m * (S + 1), 0);
    auto window = [&](const Links& l, std::uint64_t k) {
        return plan.window_of(link_taps(l.distance[k], plan.inv_bin_f, plan.delay, 1.0f).lag);
    };
    const bool tinted = any_tinted(links);
    bool ordered = true;
    for (std::size_t i = 0; i < plan.m && ordered && S > 1; ++i)
        for (std::uint64_t k = links.row[i] + 1; k < links.row[i + 1] && ordered; ++k)
            ordered = window(links, k - 1) <= window(links, k);
    if (tinted || !ordered) {
        copy_grey_links(links, plan, S > 1, window);
        plan.links = &plan.sorted;
    }
    const Links& l = *plan.links;
    if (S == 1) {
        for (std::size_t i = 0; i < plan.m; ++i) {
            plan.segments[2 * i] = l.row[i];
            plan.segments[2 * i + 1] = l.row[i + 1];
        }
        return;
    }
    for (std::size_t i = 0; i < plan.m; ++i) {
        std::uint64_t k = l.row[i];
        for (std::size_t s = 0; s < S; ++s) {
            while (k < l.row[i + 1] && window(l, k) < int(s)) ++k;
            plan.segments[i * (S + 1) + s] = k;
        }
        plan.segments[i * (S + 1) + S] = l.row[i + 1];
    }
}

// An upper bound of the spectral radius of the same-bin operator M (M_ij = albedo_i w_ij, the largest
// albedo and the largest tinted weight over channels, so that it bounds every channel's operator): by
// Collatz and Wielandt, rho(M) <= max_i (Mv)_i / v_i for any positive v, and power iterations from v = 1
// bring that bound down to rho. M is similar to a symmetric matrix (the weights are reciprocal:
// A_i w_ij = A_j w_ji, a tinted link's reverse passing the same mirrors), so its spectrum lies in
// [-rho, rho], the interval that the Chebyshev weights assume.
double same_bin_radius(const PatchSet& patches, const SolvePlan& plan) {
    const std::size_t n = plan.n;
    std::vector<double> v(n, 1.0), y(n);
    double bound = 0.0;
    for (int iteration = 0; iteration < 24; ++iteration) {
        bound = 0.0;
        double top = 0.0;
        for (std::size_t q = 0; q < n; ++q) {  // by position, as the links
            double sum = 0.0;
            for (std::uint64_t k = plan.same_row[q]; k < plan.same_row[q + 1]; ++k)
                sum += double(plan.same_links[k].w) * v[plan.same_links[k].source];
            if (!plan.tinted_same.empty())
                for (std::uint64_t k = plan.tinted_same_row[q]; k < plan.tinted_same_row[q + 1]; ++k) {
                    const TintedSameLink& l = plan.tinted_same[k];
                    sum += double(std::max({l.w[0], l.w[1], l.w[2]})) * v[l.source];
                }
            y[q] = patches.albedo[plan.order[q]].maxCoeff() * sum;
            bound = std::max(bound, y[q] / v[q]);
            top = std::max(top, y[q]);
        }
        if (!(top > 0.0)) return 0.0;
        for (std::size_t i = 0; i < n; ++i) v[i] = y[i] / top + 1e-3;  // kept positive
    }
    return bound;
}

// The subtrees that threads take whole during push and pull: the highest nodes with at most
// `cut` patches below, so that there are several per thread; the clusters above them, in preorder.
void cut_subtrees(const ClusterTree& t, SolvePlan& plan) {
    const std::size_t cut = std::max<std::size_t>(32, t.leaves / (16 * std::size_t(std::max(plan.threads, 1))));
    std::vector<std::uint32_t> stack{t.root()};
    while (!stack.empty()) {
        const std::uint32_t c = stack.back();
        stack.pop_back();
        if (t.last[c] - t.first[c] <= cut || t.is_leaf(c)) {
            plan.subtrees.push_back(c);
            continue;
        }
        plan.top.push_back(c);
        const auto [a, b] = t.children[c - t.leaves];
        stack.push_back(b);
        stack.push_back(a);
    }
    std::sort(plan.top.begin(), plan.top.end());  // preorder ids: parents first
}

// Chebyshev needs one system that gathers from itself; per-order layers chain (and converge in as many
// sweeps as there are orders), so they sweep plain Jacobi.
void plan_sweeps(const PatchSet& patches, SolvePlan& plan) {
    if (plan.L != 1 || plan.layers.source[0] != 0 || !plan.same_bin()) return;
    const double rho = same_bin_radius(patches, plan);
    if (rho > 0.05 && rho < 0.95) plan.same_radius = rho;
    double w = 1.0;
    for (int k = 1; k <= kMaxSweeps; ++k) {
        w = k == 1 ? 1.0 : k == 2 ? 1.0 / (1.0 - 0.5 * rho * rho) : 1.0 / (1.0 - 0.25 * rho * rho * w);
        plan.omega.push_back(float(w));
    }
}

// Every node's ring of C lanes per bin: patches' rings in leaf order (the bin-by-bin passes store them
// in that order), then clusters'.
void plan_rings(SolvePlan& plan) {
    plan.slots.resize(plan.m);
    for (std::size_t at = 0; at < plan.m; ++at) {
        const std::size_t k = at < plan.n ? plan.order[at] : at;
        const int length = int(std::bit_ceil(unsigned(plan.send_lag[k] + plan.bt + 2)));
        const int mirror = plan.send_window[k] > 0 ? plan.send_window[k] + 1 : 0;
        plan.slots[k] = {plan.ring_floats, length - 1, length, mirror};
        plan.ring_floats += std::size_t(length + mirror) * std::size_t(plan.C);
        plan.ring = std::max(plan.ring, length);
    }
    std::vector<int>().swap(plan.send_lag);
    std::vector<int>().swap(plan.send_window);
}

// The plan of a march of `illuminations` illuminations of `channels` channels each, from the window's
// first block (plan_blocks moves the start to the batch's earliest pulse).
SolvePlan make_plan(const PatchSet& patches, const LinkSet& set, const TimeAxis& time, const SolverOptions& options,
                    int illuminations, int channels) {
    const Links& links = set.links;
    SolvePlan plan;
    plan.n = patches.size();
    plan.m = set.nodes();
    plan.tree = &set.tree;
    plan.clusters = set.tree.clusters() > 0;
    plan.threads = thread_count(options.threads);
    if (plan.clusters) cut_subtrees(set.tree, plan);
    if (links.size() < kDenseRow * plan.m) plan.source_tile = std::max<std::size_t>(plan.m, 1);
    plan.bt = int(std::bit_ceil(unsigned(std::clamp(options.block_bins, 1, 4096))));
    // Blocks no longer than the shortest cluster link, so that no cluster link has to be expanded.
    if (plan.clusters && set.block_bins > 0)
        while (plan.bt > 1 && plan.bt > set.block_bins) plan.bt /= 2;
    plan.K = illuminations;
    plan.channels = channels;
    plan.C = illuminations * channels;
    plan.delay = options.delay;
    plan.start_m = time.start_m();
    plan.inv_bin = 1.0 / time.bin_width_m();
    plan.inv_bin_f = float(plan.inv_bin);
    plan.layers = plan_layers(options.max_bounces, options.bounce_terms);
    plan.L = plan.layers.layers();
    plan_windows(links, plan);
    plan.recent_bins = int(std::bit_ceil(unsigned(plan.bt + 1)));
    split_links(patches, links, plan);
    plan_sweeps(patches, plan);
    plan_rings(plan);
    plan.T = time.bins;
    plan.blocks = (plan.T + plan.bt - 1) / plan.bt;
    for (int l = 0; l < plan.L; ++l) plan.fed_layers += plan.layers.source[std::size_t(l)] >= 0;
    for (int s = 0; s < plan.windows; ++s) {
        plan.kernel[s] = pick_kernel(plan.C, plan.window_bins(s));
        if (!plan.kernel[s]) plan.lane_kernel[s] = lane_kernel_for(plan.window_bins(s));
    }
    return plan;
}

// Light sent before the window opens still travels: the march starts at the batch's earliest pulse,
// aligned to the longest window, so that every window starts at the first block.
void plan_blocks(SolvePlan& plan, std::span<const Illumination* const> batch) {
    std::int64_t first_pulse_bin = std::min<std::int64_t>(0, plan.first_emitted);
    for (const Illumination* illumination : batch)
        for (const Pulse& p : illumination->pulses) first_pulse_bin = std::min(first_pulse_bin, plan.pulse_bin(p));
    const std::int64_t align = plan.acc_bins;
    plan.b_begin = (first_pulse_bin >= 0) ? 0 : -((-first_pulse_bin + align - 1) / align) * align;
    plan.blocks = (plan.T - plan.b_begin + plan.bt - 1) / plan.bt;
}

// Bytes of the ring buffers, block buffers and short-link lists of a march on this plan.
std::size_t working_bytes(const SolvePlan& p) {
    const std::size_t L = std::size_t(p.L), C = std::size_t(p.C), bt = std::size_t(p.bt);
    const std::size_t state = L * p.n * C;  // per patch and lane: m_base, m_iterate, m_previous, m_same
    const std::size_t states = 2 + (p.same_radius > 0.0 ? 1 : 0) + (p.same_bin() ? 1 : 0);
    const std::size_t floats = L * p.ring_floats + L * p.n * bt * C + L * p.acc_values() +
                               L * std::size_t(p.recent_bins) * p.n * C + states * state +
                               (1 + std::size_t(p.layers.terms)) * p.n * bt * std::size_t(p.K) * 3;
    return floats * sizeof(float) + p.short_links.size() * sizeof(ShortLink) +
           p.same_links.size() * sizeof(SameBinLink) + 2 * (p.n + 1) * sizeof(std::uint64_t) +
           p.slots.size() * sizeof(RingSlot) + p.segments.size() * sizeof(std::uint64_t) + p.sorted.bytes() +
           p.albedo.size() * sizeof(float) + (p.tinted_long.size() + p.tinted_short.size()) * sizeof(TintedLink) +
           p.tinted_same.size() * sizeof(TintedSameLink) +
           (p.tinted_long_row.size() + p.tinted_short_row.size() + p.tinted_same_row.size()) * sizeof(std::uint64_t);
}

// The march: ring buffers of every layer's recent radiosity, the block's accumulators, and the
// steps that advance them one block at a time. Steps marked "in a region" are called by every thread
// of one OpenMP parallel region and share their loops among them.
class March {
public:
    March(std::span<const Illumination* const> batch, const SolvePlan& plan)
        : m_links(*plan.links), m_batch(batch), m_plan(plan),
          m_rings(std::size_t(plan.L), std::vector<float>(plan.ring_floats, 0.0f)),
          m_acc(std::size_t(plan.L), std::vector<float>(plan.acc_values(), 0.0f)),
          m_recent(std::size_t(plan.L),
                   std::vector<float>(std::size_t(plan.recent_bins) * plan.n * std::size_t(plan.C), 0.0f)),
          m_emit(std::size_t(plan.L), std::vector<float>(plan.n * std::size_t(plan.bt) * std::size_t(plan.C))),
          m_base(std::size_t(plan.L) * plan.n * std::size_t(plan.C)),
          m_iterate(std::size_t(plan.L) * plan.n * std::size_t(plan.C)),
          m_previous(plan.same_radius > 0.0 ? std::size_t(plan.L) * plan.n * std::size_t(plan.C) : 0),
          m_same(plan.same_bin() ? std::size_t(plan.L) * plan.n * std::size_t(plan.C) : 0, 0.0f),
          m_out_total(plan.n * std::size_t(plan.bt) * std::size_t(plan.K) * 3),
          m_out_terms(std::size_t(plan.layers.terms) * plan.n * std::size_t(plan.bt) * std::size_t(plan.K) * 3) {}

    // Step 1 (in a region): per receiver, the block's emission and, for every window that starts at
    // this block, each of its links as one contiguous multiply-add over the window, reading history
    // that is already final.
    void long_pass(std::int64_t b0);
    // Step 1b (in a region, clusters only): every cluster's long-link sums added into its children's.
    void push_block(std::int64_t b0);
    // Step 2 (in a region): bin by bin, short links, then the same-bin system by Jacobi iteration.
    void short_pass(std::int64_t b0) {
        with_lanes(m_plan.C, [&](auto lanes) { short_pass_lanes<decltype(lanes)::value>(b0); });
    }
    // Step 2b (in a region, clusters only): every cluster's radiosity over the block from its children's.
    void pull_block(std::int64_t b0);
    // Step 3: the block's bins inside the window, handed to the sink.
    void emit_block(std::int64_t b0, const BlockSink& sink);
    int worst_jacobi_iterations() const { return m_worst_iterations.load(); }
    std::uint64_t jacobi_sweeps() const { return m_sweeps; }

private:
    const float* recent(int layer, std::size_t q, std::int64_t bin) const {
        return m_recent[std::size_t(layer)].data() + m_plan.recent_at(q, bin);
    }
    // The bin-by-bin state of the patch at position q (m_base, m_iterate, m_previous, m_same).
    std::size_t state_at(int layer, std::size_t q) const {
        return (std::size_t(layer) * m_plan.n + q) * std::size_t(m_plan.C);
    }
    float* ring_at(int layer, std::size_t patch, std::int64_t bin) {
        const RingSlot& slot = m_plan.slots[patch];
        return m_rings[std::size_t(layer)].data() + slot.offset + std::size_t(int(bin & slot.mask)) * std::size_t(m_plan.C);
    }
    // Node `node`'s value at `bin` into its ring.
    void store(int layer, std::size_t node, std::int64_t bin, const float* v);
    // The value at `bin` of the patch at position q (its C lanes) into the recent bins.
    void store_recent(int layer, std::size_t q, std::int64_t bin, const float* v, int C) {
        float* r = m_recent[std::size_t(layer)].data() + m_plan.recent_at(q, bin);
        for (int c = 0; c < C; ++c) r[c] = v[c];
    }
    // Layer that a pulse of order `order` enters besides the total (-1: none).
    int exact_layer(int order) const { return order < m_plan.layers.exact ? order : -1; }
    void load_emission(std::size_t i, std::int64_t b0);
    void gather_tile(std::size_t i0, std::size_t i1, std::int64_t b0);
    void gather_tinted(std::size_t i, const float* ring, std::int64_t b0, float* acc) const;
    // The bin-by-bin steps for CT lanes (0: m_plan.C lanes, counted at run time): with the lane count
    // known at compile time the sums stay in registers.
    template <int CT>
    void short_pass_lanes(std::int64_t b0);
    template <int CT>
    void short_links_of(std::size_t q, std::int64_t b0, int o);
    // g += the short links (or the same-bin links), grey and tinted, of the patch at position q at `bin`,
    // from layer src.
    template <int CT>
    void add_short_links(int src, std::size_t q, std::int64_t bin, float* g) const;
    template <int CT>
    void add_same_links(int src, std::size_t q, std::int64_t bin, float* g) const;
    void push_node(std::uint32_t i, std::int64_t b0);
    void pull_node(std::uint32_t c, std::int64_t b0);
    template <class NodeFn>
    void over_tree(bool down, NodeFn visit);
    template <int CT>
    bool jacobi_sweep(std::int64_t bin, int iteration);
    template <int CT>
    void sweep_patch(std::size_t q, std::int64_t bin, bool extrapolate, float omega, float* change, float* largest);
    bool sweeps_converged() const;
    void block_totals(std::size_t i, std::int64_t lo, int count);
    void block_spots(std::size_t i, std::int64_t lo, std::int64_t hi);

    const Links& m_links;
    std::span<const Illumination* const> m_batch;
    const SolvePlan& m_plan;
    std::vector<std::vector<float>> m_rings;    // per layer: M x (ring + mirror) x C
    std::vector<std::vector<float>> m_acc;      // per layer: acc_bins x M x C, long links' sums (a ring)
    std::vector<std::vector<float>> m_recent;   // per layer: recent_bins x N x C (SolvePlan::recent_at)
    std::vector<std::vector<float>> m_emit;     // per layer: N x bt x C by position, the block's emission
    // L x N x C by position (state_at): the bin's value before the same-bin sweeps, the sweep's new
    // values, the iterate before the current one (Chebyshev), the last bin's same-bin share.
    std::vector<float> m_base, m_iterate, m_previous, m_same;
    std::vector<float> m_out_total, m_out_terms;
    // The Jacobi sweep's max-reductions per lane: the largest change and the largest value.
    float m_change[kMaxLanes] = {}, m_largest[kMaxLanes] = {};
    std::atomic<int> m_worst_iterations{0};
    std::uint64_t m_sweeps = 0;                 // written by one thread (omp single)
    bool m_stop = false;                        // a cancelled run, as read by one thread (omp single)
};

void March::store(int layer, std::size_t node, std::int64_t bin, const float* v) {
    const int C = m_plan.C;
    const RingSlot& slot = m_plan.slots[node];
    const int pos = int(bin & slot.mask);
    float* r = m_rings[std::size_t(layer)].data() + slot.offset;
    for (int c = 0; c < C; ++c) r[std::size_t(pos * C + c)] = v[c];
    if (pos < slot.mirror)
        for (int c = 0; c < C; ++c) r[std::size_t((pos + slot.length) * C + c)] = v[c];
}

// Patch i's pulses of every illumination within the block, each into its illumination's lanes.
void March::load_emission(std::size_t i, std::int64_t b0) {
    const int bt = m_plan.bt, C = m_plan.C, channels = m_plan.channels;
    if (i >= m_plan.n) return;  // clusters emit nothing of their own
    const std::size_t q = m_plan.position[i];
    for (int l = 0; l < m_plan.L; ++l) std::fill_n(m_emit[std::size_t(l)].data() + q * std::size_t(bt * C), bt * C, 0.0f);
    for (std::size_t e = 0; e < m_batch.size(); ++e) {
        const Illumination& illumination = *m_batch[e];
        for (std::uint64_t k = illumination.row[i]; k < illumination.row[i + 1]; ++k) {
            const Pulse& p = illumination.pulses[k];
            const std::int64_t b = m_plan.pulse_bin(p);
            if (!p.propagates || b < b0 || b >= b0 + bt) continue;
            const std::size_t at = q * std::size_t(bt * C) + std::size_t((b - b0) * C) + std::size_t(m_plan.lane(int(e), 0));
            const int targets[2] = {m_plan.layers.total, exact_layer(p.order)};
            for (int l : targets)
                if (l >= 0)
                    for (int c = 0; c < channels; ++c) m_emit[std::size_t(l)][at + std::size_t(c)] += float(p.energy[c]);
        }
    }
}

// Receivers [i0, i1) of one tile: the links of every window that starts at b0 (sorted by source
// within a window) in source tiles, so that the histories one source tile reads stay in cache for all
// the tile's receivers.
void March::gather_tile(std::size_t i0, std::size_t i1, std::int64_t b0) {
    const SolvePlan& p = m_plan;
    const std::size_t S = std::size_t(p.windows);
    int due[kMaxWindows];
    int count = 0;
    for (int s = 0; s < p.windows; ++s)
        if ((b0 & std::int64_t(p.window_bins(s) - 1)) == 0) due[count++] = s;
    std::uint64_t cursor[kReceiverTile][kMaxWindows];
    for (int l = 0; l < p.L; ++l) {
        const int src = p.layers.source[std::size_t(l)];
        if (src < 0) continue;
        const float* ring_src = m_rings[std::size_t(src)].data();
        for (std::size_t i = i0; i < i1; ++i)
            for (int d = 0; d < count; ++d) cursor[i - i0][d] = p.segments[i * (S + 1) + std::size_t(due[d])];
        for (std::size_t s0 = 0; s0 < p.m; s0 += p.source_tile) {
            const std::uint32_t s1 = std::uint32_t(std::min(p.m, s0 + p.source_tile));
            for (std::size_t i = i0; i < i1; ++i) {
                float* a = m_acc[std::size_t(l)].data() + p.acc_at(i, b0);
                for (int d = 0; d < count; ++d) {
                    const int s = due[d];
                    const std::uint64_t end = p.segments[i * (S + 1) + std::size_t(s) + 1];
                    if (cursor[i - i0][d] >= end) continue;
                    if (p.kernel[s])
                        p.kernel[s](m_links, cursor[i - i0][d], end, s1, p.inv_bin_f, p.delay, ring_src,
                                    p.slots.data(), b0, a, p.acc_stride());
                    else if (p.lane_kernel[s])
                        p.lane_kernel[s](m_links, cursor[i - i0][d], end, s1, p.inv_bin_f, p.delay, ring_src,
                                         p.slots.data(), b0, p.C, a, p.acc_stride());
                    else
                        gather_long_any(m_links, cursor[i - i0][d], end, s1, p.inv_bin_f, p.delay, ring_src,
                                        p.slots.data(), b0, p.C, p.window_bins(s), a, p.acc_stride());
                }
            }
        }
        if (!p.tinted_long.empty())
            for (std::size_t i = i0; i < std::min(i1, p.n); ++i)
                gather_tinted(i, ring_src, b0, m_acc[std::size_t(l)].data() + p.acc_at(i, b0));
    }
}

// Patch i's tinted links of lag >= bt over the block, into its accumulators `acc`: each one multiply-add
// per tap and colour over the block, reading final history from the ring of its source (`ring`).
void March::gather_tinted(std::size_t i, const float* ring, std::int64_t b0, float* acc) const {
    const SolvePlan& p = m_plan;
    const std::size_t C = std::size_t(p.C), stride = p.acc_stride();
    for (std::uint64_t k = p.tinted_long_row[i]; k < p.tinted_long_row[i + 1]; ++k) {
        const TintedLink& t = p.tinted_long[k];
        const RingSlot& slot = p.slots[t.source];
        const float* h = ring + slot.offset + std::size_t(int((b0 - t.lag - 1) & slot.mask)) * C;
        for (std::size_t b = 0; b < std::size_t(p.bt); ++b) {  // two accumulations, as in gather_long
            add_tinted(acc + b * stride, t.w0, h + (b + 1) * C, p.C, p.channels);
            add_tinted(acc + b * stride, t.w1, h + b * C, p.C, p.channels);
        }
    }
}

void March::long_pass(std::int64_t b0) {
    const std::size_t tiles = (m_plan.m + kReceiverTile - 1) / kReceiverTile;
#pragma omp for schedule(dynamic, 1)
    for (std::size_t tile = 0; tile < tiles; ++tile) {
        // A cancelled run skips the rest of the pass (a long block of a large flat set takes seconds);
        // solve_transient throws after the region.
        if (cancel_requested()) continue;
        const std::size_t i0 = tile * kReceiverTile, i1 = std::min(m_plan.m, i0 + kReceiverTile);
        for (std::size_t i = i0; i < i1; ++i) load_emission(i, b0);
        gather_tile(i0, i1, b0);
    }
}

// The patch at position q at bin b0 + o: the long links' sum (with every cluster's above it) plus its
// short links, the emission, stored in the recent bins (the rings take it after the same-bin sweeps).
template <int CT>
void March::add_short_links(int src, std::size_t q, std::int64_t bin, float* g) const {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.C;
    float sum[CT > 0 ? CT : kMaxLanes];
    std::fill_n(sum, C, 0.0f);
    for (std::uint64_t k = p.short_row[q]; k < p.short_row[q + 1]; ++k) {
        const ShortLink& s = p.short_links[k];
        const float* h1 = recent(src, s.source, bin - s.lag - 1);
        if (s.lag > 0) {
            const float* h0 = recent(src, s.source, bin - s.lag);
            for (int c = 0; c < C; ++c) sum[c] += s.w0 * h0[c] + s.w1 * h1[c];
        } else {
            for (int c = 0; c < C; ++c) sum[c] += s.w1 * h1[c];
        }
    }
    if (!p.tinted_short.empty())
        for (std::uint64_t k = p.tinted_short_row[q]; k < p.tinted_short_row[q + 1]; ++k) {
            const TintedLink& s = p.tinted_short[k];
            if (s.lag > 0) add_tinted(sum, s.w0, recent(src, s.source, bin - s.lag), C, p.channels);
            add_tinted(sum, s.w1, recent(src, s.source, bin - s.lag - 1), C, p.channels);
        }
    for (int c = 0; c < C; ++c) g[c] += sum[c];
}

template <int CT>
void March::add_same_links(int src, std::size_t q, std::int64_t bin, float* g) const {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.C;
    float sum[CT > 0 ? CT : kMaxLanes];
    std::fill_n(sum, C, 0.0f);
    for (std::uint64_t k = p.same_row[q]; k < p.same_row[q + 1]; ++k) {
        const float* h = recent(src, p.same_links[k].source, bin);
        for (int c = 0; c < C; ++c) sum[c] += p.same_links[k].w * h[c];
    }
    if (!p.tinted_same.empty())
        for (std::uint64_t k = p.tinted_same_row[q]; k < p.tinted_same_row[q + 1]; ++k)
            add_tinted(sum, p.tinted_same[k].w, recent(src, p.tinted_same[k].source, bin), C, p.channels);
    for (int c = 0; c < C; ++c) g[c] += sum[c];
}

template <int CT>
void March::short_links_of(std::size_t q, std::int64_t b0, int o) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.C;
    const std::int64_t bin = b0 + o;
    const float* albedo = p.albedo.data() + std::size_t(C) * q;
    for (int l = 0; l < p.L; ++l) {
        const int src = p.layers.source[std::size_t(l)];
        float g[CT > 0 ? CT : kMaxLanes];
        const std::size_t at = q * std::size_t(p.bt * C) + std::size_t(o * C);
        // The long links' sums for this bin, taken (the accumulator ring's slot is free again).
        float* acc = m_acc[std::size_t(l)].data() + p.acc_at_slot(q, bin);
        for (int c = 0; c < C; ++c) {
            g[c] = acc[c];
            acc[c] = 0.0f;
        }
        if (src >= 0) add_short_links<CT>(src, q, bin, g);
        float b[CT > 0 ? CT : kMaxLanes];
        for (int c = 0; c < C; ++c) b[c] = m_emit[std::size_t(l)][at + std::size_t(c)] + albedo[c] * g[c];
        float* keep = m_base.data() + state_at(l, q);
        for (int c = 0; c < C; ++c) keep[c] = b[c];
        if (!m_same.empty()) {
            // The same-bin sweeps start from the last bin's same-bin share: profiles are smooth where
            // the sweeps take longest, so they start nearer their fixed point.
            const float* last = m_same.data() + state_at(l, q);
            for (int c = 0; c < C; ++c) b[c] += last[c];
        }
        store_recent(l, q, bin, b, C);
    }
}

// Node i's long-link sums over the block plus its parent's (after the parent's own push).
void March::push_node(std::uint32_t i, std::int64_t b0) {
    const std::uint32_t up = m_plan.tree->parent[i];
    if (up == kNoNode) return;
    for (int l = 0; l < m_plan.L; ++l)
        for (std::int64_t bin = b0; bin < b0 + m_plan.bt; ++bin) {
            float* own = m_acc[std::size_t(l)].data() + m_plan.acc_at(i, bin);
            const float* from = m_acc[std::size_t(l)].data() + m_plan.acc_at(up, bin);
            for (int c = 0; c < m_plan.C; ++c) own[c] += from[c];
        }
}

// Cluster c's radiosity over the block's bins: the area-weighted mean of its children's. Its long-link
// sums for the block, pushed to its children by now, are cleared.
void March::pull_node(std::uint32_t c, std::int64_t b0) {
    const ClusterTree& t = *m_plan.tree;
    const auto [a, b] = t.children[c - t.leaves];
    const float wa = float(t.area[a] / t.area[c]), wb = float(t.area[b] / t.area[c]);
    for (int l = 0; l < m_plan.L; ++l)
        for (std::int64_t bin = b0; bin < b0 + m_plan.bt; ++bin)
            std::fill_n(m_acc[std::size_t(l)].data() + m_plan.acc_at(c, bin), m_plan.C, 0.0f);
    for (int l = 0; l < m_plan.L; ++l)
        for (std::int64_t bin = b0; bin < b0 + m_plan.bt; ++bin) {
            const float* va = ring_at(l, a, bin);
            const float* vb = ring_at(l, b, bin);
            float v[kMaxLanes];
            for (int ch = 0; ch < m_plan.C; ++ch) v[ch] = wa * va[ch] + wb * vb[ch];
            store(l, c, bin, v);
        }
}

// (In a region.) Visits every node of the tree, parents before children (`down`), or every cluster,
// children before parents: the clusters above the subtrees on one thread, each subtree (whose
// clusters are numbered in preorder) on any thread, its patches after its clusters going down.
template <class NodeFn>
void March::over_tree(bool down, NodeFn visit) {
    const SolvePlan& p = m_plan;
    const ClusterTree& t = *p.tree;
    if (down) {
#pragma omp single
        for (std::uint32_t c : p.top) visit(c);
    }
#pragma omp for schedule(dynamic, 1)
    for (std::size_t s = 0; s < p.subtrees.size(); ++s) {
        const std::uint32_t r = p.subtrees[s];
        const std::uint32_t clusters = t.is_leaf(r) ? 0u : (t.last[r] - t.first[r]) - 1;
        if (down) {
            for (std::uint32_t c = r; c < r + clusters; ++c) visit(c);
            for (std::uint32_t k = t.first[r]; k < t.last[r]; ++k) visit(t.leaf_order[k]);
        } else {
            for (std::uint32_t c = r + clusters; c-- > r;) visit(c);
        }
    }
    if (!down) {
#pragma omp single
        for (std::size_t k = p.top.size(); k-- > 0;) visit(p.top[k]);
    }
}

void March::push_block(std::int64_t b0) {
    over_tree(true, [&](std::uint32_t i) { push_node(i, b0); });
}

void March::pull_block(std::int64_t b0) {
    over_tree(false, [&](std::uint32_t c) { pull_node(c, b0); });
}

// One Jacobi sweep of the same-bin system (in a region), sweep `iteration` (from 1) of this bin; true
// when it has converged to float resolution, where further sweeps cannot change the stored values
// meaningfully. With SolvePlan::same_radius, Chebyshev's semi-iteration (Golub and Varga 1961):
// x_{k+1} = omega_{k+1} (J(x_k) - x_{k-1}) + x_{k-1}, which has the same fixed point and, for a
// spectrum in [-rho, rho], converges at rho / (1 + sqrt(1 - rho^2)) per sweep instead of rho.
template <int CT>
bool March::jacobi_sweep(std::int64_t bin, int iteration) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.C;
    const bool extrapolate = p.same_radius > 0.0 && iteration > 1;
    const float omega = extrapolate ? p.omega[std::size_t(std::min(iteration, kMaxSweeps) - 1)] : 1.0f;
#pragma omp single
    {
        std::fill_n(m_change, C, 0.0f);
        std::fill_n(m_largest, C, 0.0f);
    }
    float change[CT > 0 ? CT : kMaxLanes], largest[CT > 0 ? CT : kMaxLanes];
    std::fill_n(change, C, 0.0f);
    std::fill_n(largest, C, 0.0f);
#pragma omp for schedule(static) nowait
    for (std::size_t q = 0; q < p.n; ++q) sweep_patch<CT>(q, bin, extrapolate, omega, change, largest);
#pragma omp critical(tprf_jacobi_reduction)
    for (int c = 0; c < C; ++c) {
        m_change[c] = std::max(m_change[c], change[c]);
        m_largest[c] = std::max(m_largest[c], largest[c]);
    }
#pragma omp barrier
    // Read the shared result before the barrier that ends the next loop, so that the next sweep's
    // reset cannot overtake a slow thread.
    const bool converged = sweeps_converged();
#pragma omp for schedule(static)
    for (std::size_t q = 0; q < p.n; ++q)
        for (int l = 0; l < p.L; ++l) {
            if (p.same_radius > 0.0) std::copy_n(recent(l, q, bin), C, m_previous.data() + state_at(l, q));
            store_recent(l, q, bin, m_iterate.data() + state_at(l, q), C);
        }
    return converged;
}

// The sweep's new values of the patch at position q (m_iterate), and per lane the largest change from
// the current ones and the largest new value so far.
template <int CT>
void March::sweep_patch(std::size_t q, std::int64_t bin, bool extrapolate, float omega, float* change,
                        float* largest) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.C;
    const float* albedo = p.albedo.data() + std::size_t(C) * q;
    for (int l = 0; l < p.L; ++l) {
        const int src = p.layers.source[std::size_t(l)];
        const float* keep = m_base.data() + state_at(l, q);
        float* next = m_iterate.data() + state_at(l, q);
        float g[CT > 0 ? CT : kMaxLanes];
        std::fill_n(g, C, 0.0f);
        if (src >= 0) add_same_links<CT>(src, q, bin, g);
        const float* now = recent(l, q, bin);
        const float* before = extrapolate ? m_previous.data() + state_at(l, q) : nullptr;
        for (int c = 0; c < C; ++c) {
            next[c] = keep[c] + albedo[c] * g[c];
            if (extrapolate) next[c] = before[c] + omega * (next[c] - before[c]);
            change[c] = std::max(change[c], std::abs(next[c] - now[c]));
            largest[c] = std::max(largest[c], std::abs(next[c]));
        }
    }
}

// Whether every illumination's same-bin values have converged to float resolution: its largest change
// at most 1e-7 of its largest value. Each illumination is judged on its own lanes, so that a faint one
// sweeps as long as it would alone, however bright the others.
bool March::sweeps_converged() const {
    const int channels = m_plan.channels;
    for (int k = 0; k < m_plan.K; ++k) {
        float change = 0.0f, largest = 0.0f;
        for (int c = k * channels; c < (k + 1) * channels; ++c) {
            change = std::max(change, m_change[c]);
            largest = std::max(largest, m_largest[c]);
        }
        if (!(change <= 1e-7f * largest)) return false;
    }
    return true;
}

template <int CT>
void March::short_pass_lanes(std::int64_t b0) {
    for (int o = 0; o < m_plan.bt; ++o) {
        // A cancelled run leaves the block here (solve_transient throws after the region): every
        // thread reads the one answer after the single's barrier, so all leave at the same bin.
#pragma omp single
        m_stop = cancel_requested();
        if (m_stop) break;
#pragma omp for schedule(static)
        for (std::size_t q = 0; q < m_plan.n; ++q) short_links_of<CT>(q, b0, o);
        for (int iteration = 1; iteration <= kMaxSweeps && m_plan.same_bin(); ++iteration) {
            if (!jacobi_sweep<CT>(b0 + o, iteration)) continue;
#pragma omp single
            {
                if (iteration > m_worst_iterations.load()) m_worst_iterations.store(iteration);
                m_sweeps += std::uint64_t(iteration);
            }
            break;
        }
        // The sweeps updated the recent bins only: the rings take the converged values, and the
        // next bin's sweeps the same-bin share.
#pragma omp for schedule(static)
        for (std::size_t q = 0; q < m_plan.n; ++q)
            for (int l = 0; l < m_plan.L; ++l) {
                const float* v = recent(l, q, b0 + o);
                store(l, m_plan.order[q], b0 + o, v);
                if (m_same.empty()) continue;
                const std::size_t at = state_at(l, q);
                for (int c = 0; c < m_plan.C; ++c) m_same[at + std::size_t(c)] = v[c] - m_base[at + std::size_t(c)];
            }
    }
}

// Patch i's total and per-order terms for the bins [lo, lo + count) of the output block, every
// illumination's (N x count x K x 3; a grey lane fills all three colours).
void March::block_totals(std::size_t i, std::int64_t lo, int count) {
    const SolvePlan& p = m_plan;
    const int C = p.C, L = p.L, K = p.K;
    const LayerPlan& plan = p.layers;
    // Short blocks from the recent bins (which hold the whole block; compact, and in cache), long ones
    // from the ring, where a patch's bins are contiguous.
    const std::size_t q = p.position[i];
    auto value = [&](int layer, std::int64_t bin) -> const float* {
        return count <= 4 ? recent(layer, q, bin) : ring_at(layer, i, bin);
    };
    auto put = [&](float* out, int o, const float* lanes) {
        float* at = out + (i * std::size_t(count) + std::size_t(o)) * std::size_t(K) * 3;
        for (int k = 0; k < K; ++k)
            for (int c = 0; c < 3; ++c) at[k * 3 + c] = lanes[p.lane(k, c)];
    };
    for (int o = 0; o < count; ++o) {
        const std::int64_t bin = lo + o;
        float total[kMaxLanes];
        std::fill_n(total, C, 0.0f);
        if (plan.total >= 0) {
            const float* v = value(plan.total, bin);
            for (int c = 0; c < C; ++c) total[c] = v[c];
        } else {
            for (int l = 0; l < L; ++l) {
                const float* v = value(l, bin);
                for (int c = 0; c < C; ++c) total[c] += v[c];
            }
        }
        put(m_out_total.data(), o, total);
        for (int k = 0; k < plan.terms; ++k) {
            float* term = m_out_terms.data() + std::size_t(k) * p.n * std::size_t(count) * std::size_t(K) * 3;
            float v[kMaxLanes];
            if (k < plan.exact) {
                const float* r = value(k, bin);
                for (int c = 0; c < C; ++c) v[c] = r[c];
            } else {  // the tail: every order from k on
                for (int c = 0; c < C; ++c) v[c] = total[c];
                for (int l = 0; l < plan.exact; ++l) {
                    const float* r = value(l, bin);
                    for (int c = 0; c < C; ++c) v[c] -= r[c];
                }
            }
            put(term, o, v);
        }
    }
}

// Pulses seen but not propagated (the laser spot) join the output only, each its illumination's.
void March::block_spots(std::size_t i, std::int64_t lo, std::int64_t hi) {
    const SolvePlan& p = m_plan;
    const LayerPlan& plan = p.layers;
    const std::size_t count = std::size_t(hi - lo), K = std::size_t(p.K);
    for (std::size_t e = 0; e < m_batch.size(); ++e) {
        const Illumination& illumination = *m_batch[e];
        for (std::uint64_t k = illumination.row[i]; k < illumination.row[i + 1]; ++k) {
            const Pulse& pulse = illumination.pulses[k];
            const std::int64_t b = p.pulse_bin(pulse);
            if (pulse.propagates || b < lo || b >= hi) continue;
            if (plan.total < 0 && pulse.order >= plan.exact) continue;  // beyond max_bounces
            const std::size_t at = ((i * count + std::size_t(b - lo)) * K + e) * 3;
            for (int c = 0; c < 3; ++c) {
                m_out_total[at + std::size_t(c)] += float(pulse.energy[c]);
                if (plan.terms > 0) {
                    const std::size_t term = std::size_t(std::min<int>(pulse.order, plan.terms - 1));
                    m_out_terms[term * p.n * count * K * 3 + at + std::size_t(c)] += float(pulse.energy[c]);
                }
            }
        }
    }
}

void March::emit_block(std::int64_t b0, const BlockSink& sink) {
    const std::int64_t lo = std::max<std::int64_t>(b0, m_plan.first_emitted);
    const std::int64_t hi = std::min<std::int64_t>(b0 + m_plan.bt, m_plan.T);
    if (lo >= hi) return;
    const int count = int(hi - lo);
    parallel_for(m_plan.n, {m_plan.threads, 1, false}, [&](std::size_t i) {
        block_totals(i, lo, count);
        block_spots(i, lo, hi);
    });
    SolveBlock block;
    block.first_bin = int(lo);
    block.bins = count;
    block.patches = m_plan.n;
    block.illuminations = m_plan.K;
    block.radiosity = m_out_total.data();
    block.terms = m_plan.layers.terms;
    block.per_order = m_plan.layers.terms > 0 ? m_out_terms.data() : nullptr;
    if (sink) sink(block);
}

double lap(std::chrono::steady_clock::time_point& since) {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - since).count();
    since = now;
    return s;
}

}  // namespace

SolveStats solve_transient(const PatchSet& patches, const LinkSet& set, const Illumination& illumination,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink) {
    const Illumination* const one[1] = {&illumination};
    return solve_transient(patches, set, std::span<const Illumination* const>(one), time, options, sink);
}

std::size_t solve_working_bytes(const PatchSet& patches, const LinkSet& set, const TimeAxis& time,
                                const SolverOptions& options, int illuminations, int channels) {
    TPRF_CHECK_LE(1, illuminations);
    TPRF_CHECK_LE(illuminations, kMaxBatch);
    TPRF_CHECK(channels == 1 || channels == 3);
    TPRF_CHECK_EQ(set.patches(), patches.size());
    check_tints(set.links);
    return working_bytes(make_plan(patches, set, time, options, illuminations, channels));
}

SolveStats solve_transient(const PatchSet& patches, const LinkSet& set, std::span<const Illumination* const> batch,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink) {
    const Links& links = set.links;
    TPRF_CHECK_EQ(set.patches(), patches.size());
    TPRF_CHECK_EQ(links.receivers(), set.nodes());
    TPRF_CHECK_LE(std::size_t(1), batch.size());
    TPRF_CHECK_LE(batch.size(), std::size_t(kMaxBatch));
    for (const Illumination* illumination : batch) {
        TPRF_CHECK(illumination != nullptr);
        TPRF_CHECK_EQ(illumination->row.size(), patches.size() + 1);
    }
    check_tints(links);
    SolvePlan plan =
        make_plan(patches, set, time, options, int(batch.size()), scene_is_grey(patches, links, batch) ? 1 : 3);
    TPRF_CHECK_LE(options.first_bin, 0);
    plan.first_emitted = options.first_bin;
    plan_blocks(plan, batch);
    March march(batch, plan);
    SolveStats stats;
    stats.block_bins = plan.bt;
    stats.ring_bins = plan.ring;
    stats.channels = plan.channels;
    stats.illuminations = plan.K;
    stats.lanes = plan.C;
    stats.working_bytes = working_bytes(plan);
    for (std::int64_t blk = 0; blk < plan.blocks; ++blk) {
        const std::int64_t b0 = plan.b_begin + blk * plan.bt;
        auto since = std::chrono::steady_clock::now();
        double long_seconds = 0.0;
        // One parallel region per block, so that the sink below runs outside it and can use every
        // thread itself (inside, a nested region would get one thread). Phase times from thread 0:
        // every phase ends at a barrier, so they are the phases' wall times. The steps throw nothing.
#pragma omp parallel num_threads(plan.threads)
        {
            march.long_pass(b0);
            if (plan.clusters) march.push_block(b0);
            if (omp_get_thread_num() == 0) long_seconds = lap(since);
            march.short_pass(b0);
            if (plan.clusters) march.pull_block(b0);
        }
        check_cancelled();
        stats.seconds_long += long_seconds;
        stats.seconds_short += lap(since);
        march.emit_block(b0, sink);
        if (options.progress) options.progress("solve", double(blk + 1) / double(plan.blocks));
        stats.seconds_sink += lap(since);
    }
    stats.link_bin_updates = std::uint64_t(links.size()) * std::uint64_t(plan.fed_layers) *
                             std::uint64_t(plan.blocks) * std::uint64_t(plan.bt);
    stats.max_jacobi_iterations = march.worst_jacobi_iterations();
    stats.jacobi_sweeps = march.jacobi_sweeps();
    stats.short_links = plan.short_links.size() + plan.tinted_short.size();
    return stats;
}

}  // namespace tprf
