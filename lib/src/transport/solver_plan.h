#pragma once
// The transient solver's plan (solver.cpp marches it): every size, list and ring geometry fixed before
// a march starts, the link kinds it sorts links into, and the long-link kernels' signatures. Internal
// to lib/src/transport: solver_plan.cpp builds a plan, solver_kernels.cpp holds the kernels.

#include "tprf/core/time_axis.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"
#include "tprf/core/default_init.h"
#include "tprf/transport/links.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <type_traits>
#include <vector>

namespace tprf {

struct PatchSet;
struct LinkSet;
struct ClusterTree;

namespace solver_detail {

// Most values marched per patch and bin: the three colours of kMaxBatch illuminations.
constexpr int kMaxLanes = 3 * kMaxBatch;

// A grey link with its taps (delay_taps_f), made once when the plan is, for the lists the march visits at
// every bin or block: the bin-by-bin pass's links shorter than a block (lag < block length; lag 0 keeps
// only its w1 tap there, w0 is in the same-bin list), and the shortest window's (SolvePlan::near: lags
// of one to two blocks), whose taps' arithmetic would otherwise sit between each link and its loads.
struct TapLink {
    std::uint32_t source;  // the source's node slot (SolvePlan::node_slot: a patch's position)
    int lag;
    float w0;
    float w1;
};

struct SameBinLink {
    std::uint32_t source;  // the source patch's position (SolvePlan::order)
    float w;
};

// A link through tinted mirrors or glass (Links::tint), between patches: its taps in each colour, ff x
// tints[t][c] split as delay_taps_f splits a grey link's. The long-pass kernels and the lists above keep
// to grey links, whose one weight serves every lane; the few tinted ones have lists of their own.
struct TintedLink {
    std::uint32_t source;  // long list: the source patch; bin-by-bin list: its position
    int lag;               // as TapLink's (lag 0: the w1 taps only, w0 is in the same-bin list)
    float w0[3];
    float w1[3];
};

struct TintedSameLink {
    std::uint32_t source;  // the source patch's position
    float w[3];
};

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

// Where node m's ring of recent radiosity lives in a layer's ring array: `length` bins (a power of
// two, as long as the node's longest outgoing link needs), then a mirror of the first bins, so that
// any window of a block plus one bin is contiguous.
struct RingSlot {
    std::uint64_t offset;  // floats
    std::int32_t mask;     // length - 1
    std::int32_t length;
    std::int32_t mirror;   // bins mirrored after the ring: the longest window a long link reads, plus one
};

// A long link of a dense row as the plan packs it for the tiled kernel (gather_packed): its source
// node and lag in one word (source << lag_bits | lag: one compare finds a source tile's end) and its
// taps, made once instead of once per block.
struct PackedLink {
    std::uint32_t key;
    float w0;
    float w1;
};

// One call of a long-link kernel (GatherKernel, LaneKernel, gather_long_any): one receiver's links of one
// window, from `cursor` on while their sources lie in the source tile, applied to the block.
struct LongCall {
    const Links* links;        // the grey links, by receiver (SolvePlan::links)
    std::uint64_t* cursor;     // in: the receiver's next link of the window; out: past the tile's last
    std::uint64_t end;         // the end of the receiver's links of the window
    std::uint32_t source_end;  // the source tile's end
    float inv_bin;             // SolvePlan::inv_bin_f, for delay_taps_f
    DelayMode mode;            // SolvePlan::delay
    const float* ring;         // the rings of the layer gathered from
    const RingSlot* slots;     // every node's ring in them (SolvePlan::slots)
    std::int64_t b0;           // the block's first bin
    int lanes;                 // C (LaneKernel and gather_long_any; a GatherKernel is compiled for its own)
    int bins;                  // the window's bins (gather_long_any; the others are compiled for theirs)
    float* acc;                // the sums: bin b's lanes at acc + b * stride
    std::size_t stride;        // floats from one bin's sums to the next's
};

// One call of a packed kernel (PackedKernel): one receiver's packed links of one window in one source tile.
struct PackedCall {
    const PackedLink* links;   // SolvePlan::packed
    std::uint64_t* cursor;     // in: the receiver's next link of the window; out: past the tile's last
    std::uint64_t end;         // the end of the receiver's links of the window
    std::uint64_t key_end;     // the source tile's end as a key (source << lag_bits)
    int lag_bits;              // SolvePlan::lag_bits
    const float* ring;         // the rings of the layer gathered from, `ring_floats` each
    std::size_t ring_floats;   // SolvePlan::packed_ring
    int mask;                  // bins of a ring less one (before its mirror)
    std::int64_t b0;           // the block's first bin
    float* acc;                // the sums: bin b's lanes at acc + b * stride
    std::size_t stride;        // floats from one bin's sums to the next's
};

using PackedKernel = void (*)(const PackedCall&);
using GatherKernel = void (*)(const LongCall&);
// Where the shortest window's links read their sources' history: the recent bins, bin-major by node slot
// (SolvePlan::recent_at), `slice` floats a bin, `mask` = recent_bins - 1.
struct RecentView {
    const float* data;
    std::size_t slice;
    int mask;
};
// The shortest window's links, copied out of the rows into one contiguous list (a window's links are
// short runs between the other windows' in a row): per receiver node.
struct NearLinks {
    std::vector<std::uint64_t> row;  // m + 1
    std::vector<TapLink> links;
    std::size_t bytes() const { return row.size() * sizeof(std::uint64_t) + links.size() * sizeof(TapLink); }
};
// One call of the shortest window's kernel (RecentKernel): one receiver's near links.
struct RecentCall {
    const NearLinks* near;     // SolvePlan::near
    std::uint64_t first;       // the receiver's links: near->links[first, last)
    std::uint64_t last;
    RecentView recent;         // the recent bins of the layer gathered from
    std::int64_t b0;           // the block's first bin
    int lanes;                 // C (a kernel compiled for a lane count ignores it)
    float* acc;                // the sums: bin b's lanes at acc + b * stride
    std::size_t stride;        // floats from one bin's sums to the next's
};
using RecentKernel = void (*)(const RecentCall&);
using LaneKernel = void (*)(const LongCall&);

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
// The most bytes of a thread's receiver-tile sums (SolvePlan::tile_sum_floats): in a core's L2 with the
// source tile's rings. Three lanes in windows of 32 bins take 96 KiB; a batch of 48 lanes would take
// 1.5 MiB, where they measured no faster than adding into the accumulators (bench/RESULTS.md).
constexpr std::size_t kTileSumBytes = std::size_t(512) << 10;
// Floats of a thread's receiver-tile sums: a tile's receivers x the longest window x lanes, where the
// sources are tiled (fewer a tile than the nodes) and that fits in kTileSumBytes; else none.
inline std::size_t receiver_tile_floats(std::size_t source_tile, std::size_t nodes, int window_bins, int lanes) {
    const std::size_t floats = std::min(nodes, kReceiverTile) * std::size_t(window_bins) * std::size_t(lanes);
    return source_tile < nodes && floats * sizeof(float) <= kTileSumBytes ? floats : 0;
}
// Most same-bin sweeps in one bin.
constexpr int kMaxSweeps = 200;
// The long pass's longest window, bins: links at least this long are applied this many bins at a
// time; shorter ones (down to the block) in the longest power-of-two window their delay allows.
constexpr int kLongestWindow = 32;
static_assert(1 << (kDelayOctaves - 2) == kLongestWindow, "a hierarchical row's last octave is the longest window");
static_assert(HierarchyOptions::kLongestMinLag <= kLongestWindow, "blocks no longer than the longest window");
// Dense rows with packed links (flat sets) take windows twice as long: each link's window is read from
// its source's ring half as often, and its taps and address are worked out once for twice the bins.
constexpr int kDenseLongestWindow = 64;
// Floats after a layer's last ring: a packed kernel's last vector of a window reads up to 15 floats past
// the window's end (into the next ring, or here), into sums that are never used.
constexpr std::size_t kRingSlackFloats = 16;
constexpr int kMaxWindows = 16;
// A patch's own work in the bin-by-bin pass (its sums, emission, state), counted in short links.
constexpr std::size_t kShortPatchLinks = 4;

// Everything about the march that is fixed before it starts: sizes, link lists, ring geometry and
// the range of blocks. Computed once; the march only executes it.
struct SolvePlan {
    /// Patches: the tree's leaves, which emit, reflect and are output.
    std::size_t patches = 0;
    /// Nodes: the patches, then the clusters (each keeps a ring and gathers).
    std::size_t nodes = 0;
    const ClusterTree* tree = nullptr;
    const LinkSet* set = nullptr;      ///< what the plan marches (its rows' albedos: LinkSet::albedo)
    const PatchSet* patches_of = nullptr;  ///< the patches it marches
    /// Rows [out_begin, patches) are glossy out-cells (glossy_rows.h): each takes its lobe over its
    /// patch's in-cells of the bin before, of the same bounce order; the in-cells of a patch lie at
    /// consecutive positions.
    std::size_t out_begin = 0;
    /// The first glossy in-cell row (out_begin when there are none): rows [in_begin(), out_begin) are
    /// read by their patches' out-cells alone, and the output leaves them zero (SolveBlock::unread).
    std::size_t in_begin() const { return set && !set->glossy.empty() ? set->glossy.patches : out_begin; }
    bool unread(std::size_t row) const { return row >= in_begin() && row < out_begin; }
    bool clusters = false;          // push and pull run (a link set with clusters)
    // With clusters: the subtrees that threads take whole (their patches and clusters) and the
    // clusters above them, in preorder.
    std::vector<std::uint32_t> top, subtrees;
    // Sources per tile of the long pass: kSourceTile for dense rows; one tile for sparse ones
    // (hierarchical links), whose rows would otherwise be walked once per empty tile.
    std::size_t source_tile = kSourceTile;
    int threads = 1;
    /// The march's block, bins (a power of two).
    int block_bins = 0;
    int emit_blocks = 1;            // blocks per SolveBlock handed to the sink (a power of two)
    int emit_bins() const { return block_bins * emit_blocks; }
    // Windows of the long pass: window s is block_bins << s bins long and is applied at the blocks
    // that start at its multiples, to the links of delay >= its length (and below the next window's;
    // the last takes every longer one).
    int windows = 1;
    /// The accumulators' bins, the next ones the long pass adds into: the last window's length,
    /// block_bins << (windows - 1).
    int accumulator_bins = 0;
    // Per receiver: where its links of each window start, then where its row ends (windows + 1
    // offsets); with one window, the whole row (the kernel skips links shorter than the block).
    std::vector<std::uint64_t> segments;
    const Links* links = nullptr;   // the set's links, or `sorted` (plan_windows): the grey ones, by window
    Links sorted;
    // Lanes: every value the march keeps per node and bin (rings, accumulators, recent bins, emission,
    // sweep state) is `lanes` floats, illumination k's colour c in lane k * channels + c.
    /// Illuminations marched together.
    int illuminations = 1;
    int channels = 3;               // per illumination: 1 for a grey scene (every albedo and pulse), else 3
    /// Values per node and bin: illuminations x channels.
    int lanes = 3;
    // The lane that holds illumination k's colour c (a grey lane serves all three).
    int lane(int k, int c) const { return k * channels + (channels == 1 ? 0 : c); }
    DelayMode delay = DelayMode::Linear;
    bool wide = false;              // a long-link kernel for AVX-512 runs (SolverOptions::wide_vectors)
    BinMap bin_map;                 // the time axis's bins in metres (pulse_bin)
    float inv_bin_f = 0.0f;         // its reciprocal bin width in float, as the kernels take it (delay_taps_f)
    LayerPlan layers;
    /// Rings per node: layers.layers().
    int layer_count = 0;
    // Links shorter than a block, applied bin by bin, and the same-bin ones (CSR by receiver).
    std::vector<std::uint64_t> short_row, same_row;  // by receiver position
    std::vector<TapLink> short_links;
    // The bin-by-bin pass's positions by thread: thread t takes [short_split[t], short_split[t + 1]),
    // about as many short links (tinted ones too) and patches each (kShortPatchLinks a patch). Short
    // links gather where surfaces meet, so an even split of the positions was not even: 61% of the flat
    // 4k Cornell box's in the first half.
    std::vector<std::size_t> short_split;
    std::vector<SameBinLink> same_links;
    // Tinted links: those of lag >= block_bins by receiver patch, applied a block at a time (March::gather_tinted);
    // shorter ones and the same-bin pieces by receiver position, as the lists above. All empty, their
    // rows too, when no link is tinted.
    std::vector<std::uint64_t> tinted_long_row, tinted_short_row, tinted_same_row;
    std::vector<TintedLink> tinted_long, tinted_short;
    std::vector<TintedSameLink> tinted_same;
    bool same_bin() const { return !same_links.empty() || !tinted_same.empty(); }
    // The same-bin system's rows: the patches that receive or send a same-bin link, by position (most
    // of a scene's patches have none: their values are final before the sweeps). Once the plan is
    // made, same_row and tinted_same_row are by row and the same-bin links name their source's row, so
    // that the sweeps read and write compact iterates (layer_count x rows x lanes).
    std::vector<std::uint32_t> sweep_rows;   // row -> position
    std::vector<std::int32_t> sweep_row_of;  // position -> row, or -1 outside the system
    std::size_t sweep_at(int layer, std::size_t row) const {
        return (std::size_t(layer) * sweep_rows.size() + row) * std::size_t(lanes);
    }
    // Iterates the sweeps rotate through: the current and the next, and with Chebyshev the one before.
    int sweep_buffers() const { return same_radius > 0.0 ? 3 : 2; }
    // The bin-by-bin passes visit patches in the cluster tree's leaf order (near patches together)
    // and keep their state by position in it: short and same-bin links name their source's position.
    std::vector<std::uint32_t> order;     // position -> patch
    std::vector<std::uint32_t> position;  // patch -> position
    std::vector<float> albedo;            // by position, `lanes` per patch: each lane's colour
    // Where node i's values are kept in arrays over nodes that the bin-by-bin passes read: patches
    // by position, clusters by id.
    std::size_t node_slot(std::size_t i) const { return i < patches ? position[i] : i; }
    // Chebyshev acceleration of the same-bin sweeps: an upper bound of the spectral radius of the
    // same-bin operator (albedo x weights), or 0 to sweep plain Jacobi.
    double same_radius = 0.0;
    /// The Chebyshev weights of sweeps 1..kMaxSweeps.
    std::vector<float> chebyshev_weights;
    int max_lag = 0;
    // Rings: the window [t - lag - 1, t] of every read from a node must fit, plus one block; mirrored
    // so that any window of block_bins + 1 bins is contiguous. Each node's as long as its longest outgoing
    // link needs: most patches of a hierarchical set send only to near ones (or not at all).
    std::vector<int> send_lag;      // per node: its longest outgoing link's lag, bins
    std::vector<int> send_window;   // per node: its longest outgoing long link's window, bins (0: none)
    std::vector<RingSlot> slots;    // per node
    std::size_t ring_floats = 0;    // per layer
    /// The longest ring, bins.
    int longest_ring = 0;
    /// The time axis's bins.
    std::int64_t bins = 0;
    /// The march's first bin: the window's first, or before it the batch's earliest pulse's, aligned to
    /// the longest window (plan_blocks).
    std::int64_t start_bin = 0;
    std::int64_t blocks = 0;        // blocks marched from start_bin
    std::int64_t first_emitted = 0;  // first bin handed to the sink (SolverOptions::first_bin)
    int fed_layers = 0;             // layers that gather from links
    GatherKernel kernel[kMaxWindows] = {};  // per window: its kernel for (lanes, length), or null (generic)
    LaneKernel lane_kernel[kMaxWindows] = {};  // per window without one: the generic kernel, or null (any)
    // Dense rows of a flat set whose lanes have packed kernels (SolvePlan::lag_bits > 0): their grey
    // links of at least a block packed, by row and window (`segments` index them, not `links`), and per
    // window the kernel that reads them.
    std::vector<PackedLink, DefaultInitAllocator<PackedLink>> packed;
    std::uint64_t packed_count = 0;  // their number (also in a plan made for sizing only, which has none)
    int lag_bits = 0;               // a packed key's bits for the lag (the source's above them)
    bool packs() const { return lag_bits > 0; }
    /// With packed links every ring is longest_ring bins and one mirror: the floats of a node's.
    std::size_t packed_ring_floats = 0;
    PackedKernel packed_kernel[kMaxWindows] = {};
    // The shortest window's links (lags block_bins to 2 block_bins - 1) read the sources' last
    // 2 block_bins bins, which the recent bins hold then, instead of their rings: near links have near
    // sources, whose values share cache lines there, where each source's ring is a line of its own
    // (bench/RESULTS.md).
    // Null with one window (blocks of the longest window).
    RecentKernel recent_kernel = nullptr;
    NearLinks near;  // the links it applies (taken out of `segments`: the first window is empty)

    std::size_t acc_values() const { return nodes * std::size_t(accumulator_bins) * std::size_t(lanes); }
    // Where node i's long-link sums for `bin` are: the accumulators are bin-major (a bin's values of
    // every node together), so that the bin-by-bin passes read them contiguously.
    std::size_t acc_at(std::size_t i, std::int64_t bin) const { return acc_at_slot(node_slot(i), bin); }
    std::size_t acc_at_slot(std::size_t slot, std::int64_t bin) const {
        return (std::size_t(bin & std::int64_t(accumulator_bins - 1)) * nodes + slot) * std::size_t(lanes);
    }
    std::size_t acc_stride() const { return nodes * std::size_t(lanes); }
    // Floats of a thread's receiver-tile sums in the long pass: a tile's receivers x the longest window
    // x lanes, where the sources are tiled (dense rows) and that fits in kTileSumBytes; none otherwise
    // (the kernels then add into the accumulators directly).
    std::size_t tile_sum_floats() const { return receiver_tile_floats(source_tile, nodes, accumulator_bins, lanes); }
    // Every node's radiosity of the last `recent_bins` bins, bin-major like the accumulators, by
    // node_slot (patches by position, then clusters): what the bin-by-bin passes, the pull and the
    // shortest window read (a few bins of near nodes together), besides the rings.
    int recent_bins = 0;
    std::size_t recent_at(std::size_t slot, std::int64_t bin) const {
        return (std::size_t(bin & std::int64_t(recent_bins - 1)) * nodes + slot) * std::size_t(lanes);
    }
    int window_bins(int s) const { return block_bins << s; }
    // The window of a link `lag` bins long: -1 below the block.
    int window_of(int lag) const {
        if (lag < block_bins) return -1;  // block_bins is a power of two: a shift, not a division (once per link in the plan)
        return std::min(int(std::bit_width(unsigned(lag) >> std::countr_zero(unsigned(block_bins)))) - 1, windows - 1);
    }
    // Bin of a pulse (exact containment: a delta at path p lies in the bin that holds p).
    std::int64_t pulse_bin(const Pulse& p) const { return bin_map.bin(p.path); }
};

/// What a plan is made for: a march of `illuminations` illuminations of `channels` channels each;
/// `sizing_only`: a plan for working_bytes alone, whose packed links are counted, not made.
struct PlanFor {
    int illuminations = 1;
    int channels = 3;
    bool sizing_only = false;
};

/// The plan of a march, from the window's first block (plan_blocks moves the start to the batch's
/// earliest pulse).
SolvePlan make_plan(const PatchSet& patches, const LinkSet& set, const TimeAxis& time, const SolverOptions& options,
                    const PlanFor& what);
/// Moves the march's start to the batch's earliest pulse, aligned to the longest window.
void plan_blocks(SolvePlan& plan, std::span<const Illumination* const> batch);
/// Bytes of the ring buffers, block buffers and short-link lists of a march on this plan.
std::size_t working_bytes(const SolvePlan& p);
/// Whether every pulse of the batch is grey (with keeps_grey: the march runs on one channel).
bool pulses_grey(std::span<const Illumination* const> batch);

/// Whether this build has the kernels compiled for AVX-512 (512-bit vectors) and this CPU runs them.
bool cpu_has_wide_kernels();
/// The long-link kernel for C lanes and windows of `bins` bins, or null (solver_kernels.cpp); `wide`:
/// the AVX-512 one where cpu_has_wide_kernels() (the results are bit-identical).
GatherKernel pick_kernel(int C, int bins, bool wide);
/// The generic kernel for windows of `bins` bins, up to kLongestWindow; null beyond (gather_long_any).
LaneKernel lane_kernel_for(int bins, bool wide);
/// The kernel of the shortest window's links (SolvePlan::near) for C lanes and blocks of `bins` bins, reading
/// the recent bins (specialised for the lane counts gather_long has, any other count at run time), or
/// null for blocks of more than 16 bins.
RecentKernel recent_kernel_for(int C, int bins, bool wide);
/// The packed kernel (dense rows) for C lanes and windows of `bins` bins, or null; which (C, bins) have
/// one does not depend on `wide`, and the wide one gives the same bits.
PackedKernel packed_kernel_for(int C, int bins, bool wide);
/// Any lane count and window length, summed straight into the accumulators.
void gather_long_any(const LongCall& call);

}  // namespace solver_detail
}  // namespace tprf
