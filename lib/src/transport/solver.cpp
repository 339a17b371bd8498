// The transient march (solver.h): ring buffers of every node's recent radiosity advanced a block at a
// time over the plan that solver_plan.cpp makes.

#include "tprf/transport/solver.h"

#include "solver_plan.h"

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
namespace solver_detail {
namespace {

// The march: ring buffers of every layer's recent radiosity, the block's accumulators, and the
// steps that advance them one block at a time. Steps marked "in a region" are called by every thread
// of one OpenMP parallel region and share their loops among them.
// Per lane, the largest change of a Jacobi sweep and the largest new value so far (arrays of lanes).
struct SweepMaxima {
    float* change;
    float* largest;
};

class March {
public:
    March(std::span<const Illumination* const> batch, const SolvePlan& plan)
        : m_links(*plan.links), m_batch(batch), m_plan(plan),
          m_rings(std::size_t(plan.layer_count), std::vector<float>(plan.ring_floats + kRingSlackFloats, 0.0f)),
          m_acc(std::size_t(plan.layer_count), std::vector<float>(plan.acc_values(), 0.0f)),
          m_recent(std::size_t(plan.layer_count),
                   std::vector<float>(std::size_t(plan.recent_bins) * plan.nodes * std::size_t(plan.lanes), 0.0f)),
          m_emit(std::size_t(plan.layer_count),
                 std::vector<float>(plan.patches * std::size_t(plan.block_bins) * std::size_t(plan.lanes))),
          m_base(std::size_t(plan.layer_count) * plan.patches * std::size_t(plan.lanes)),
          m_same(plan.same_bin() ? std::size_t(plan.layer_count) * plan.sweep_rows.size() * std::size_t(plan.lanes) : 0,
                 0.0f),
          m_same_before(m_same.size(), 0.0f),
          m_kept(plan.emit_blocks > 1 ? (1 + std::size_t(plan.layers.terms)) * plan.patches *
                                            std::size_t(plan.emit_bins()) * std::size_t(plan.illuminations) * 3
                                      : 0),
          m_out_total(plan.patches * std::size_t(plan.emit_bins()) * std::size_t(plan.illuminations) * 3),
          m_out_terms(std::size_t(plan.layers.terms) * plan.patches * std::size_t(plan.emit_bins()) *
                      std::size_t(plan.illuminations) * 3),
          m_tile_sums(std::size_t(plan.threads), std::vector<float>(plan.tile_sum_floats())),
          m_lobe_out(std::size_t(plan.layer_count),
                     std::vector<float>(plan.set->glossy.rows() / 2 * std::size_t(plan.lanes), 0.0f)) {
        if (plan.same_bin())
            for (int k = 0; k < plan.sweep_buffers(); ++k)
                m_sweep[k].assign(std::size_t(plan.layer_count) * plan.sweep_rows.size() * std::size_t(plan.lanes), 0.0f);
    }

    // Step 1 (in a region): per receiver, the block's emission and, for every window that starts at
    // this block, each of its links as one contiguous multiply-add over the window, reading history
    // that is already final.
    void long_pass(std::int64_t b0);
    // Step 1b (in a region, clusters only): every cluster's long-link sums added into its children's.
    void push_block(std::int64_t b0);
    // Step 2 (in a region): bin by bin, short links, then the same-bin system by Jacobi iteration.
    void short_pass(std::int64_t b0) {
        with_lanes(m_plan.lanes, [&](auto lanes) { short_pass_lanes<decltype(lanes)::value>(b0); });
    }
    // Step 2b (in a region, clusters only): every cluster's radiosity over the block from its children's.
    void pull_block(std::int64_t b0);
    // Step 3: the block's bins inside the window, kept for the sink, which takes them when
    // SolvePlan::emit_blocks blocks are kept or at the last block.
    void emit_block(std::int64_t b0, const BlockSink& sink);
    int worst_jacobi_iterations() const { return m_worst_iterations.load(); }
    std::uint64_t jacobi_sweeps() const { return m_sweeps; }

private:
    const float* recent(int layer, std::size_t q, std::int64_t bin) const {
        return m_recent[std::size_t(layer)].data() + m_plan.recent_at(q, bin);
    }
    // The bin-by-bin state of the patch at position q (m_base).
    std::size_t state_at(int layer, std::size_t q) const {
        return (std::size_t(layer) * m_plan.patches + q) * std::size_t(m_plan.lanes);
    }
    float* ring_at(int layer, std::size_t patch, std::int64_t bin) {
        const RingSlot& slot = m_plan.slots[patch];
        return m_rings[std::size_t(layer)].data() + slot.offset +
               std::size_t(int(bin & slot.mask)) * std::size_t(m_plan.lanes);
    }
    // Node `node`'s value at `bin` into its ring; CT lanes (0: m_plan.lanes, counted at run time), as the
    // bin-by-bin steps below: a copy of a run-time count of floats is a library call (memmove), made
    // for every node and bin.
    template <int CT>
    void store(int layer, std::size_t node, std::int64_t bin, const float* v);
    // The value at `bin` of the node at slot q (its lanes) into the recent bins.
    template <int CT>
    void store_recent(int layer, std::size_t q, std::int64_t bin, const float* v) {
        const int C = CT > 0 ? CT : m_plan.lanes;
        float* r = m_recent[std::size_t(layer)].data() + m_plan.recent_at(q, bin);
        for (int c = 0; c < C; ++c) r[c] = v[c];
    }
    // Layer that a pulse of order `order` enters besides the total (-1: none).
    int exact_layer(int order) const { return order < m_plan.layers.exact ? order : -1; }
    void load_emission(std::size_t i, std::int64_t b0);
    void gather_tile(std::size_t i0, std::size_t i1, std::int64_t b0);
    void gather_tinted(std::size_t i, const float* ring, std::int64_t b0, float* acc) const;
    // The bin-by-bin steps for CT lanes (0: m_plan.lanes lanes, counted at run time): with the lane count
    // known at compile time the sums stay in registers.
    template <int CT>
    void short_pass_lanes(std::int64_t b0);
    template <int CT>
    void short_links_of(std::size_t q, std::int64_t b0, int o, float* fixed);
    void lobe_products(std::size_t g, std::int64_t bin);
    // g += the short links (or the same-bin links), grey and tinted, of the patch at position q at `bin`,
    // from layer src.
    template <int CT>
    void add_short_links(int src, std::size_t q, std::int64_t bin, float* g) const;
    // g += the same-bin links of the system's row r from layer src of the iterate `x` (SolvePlan::sweep_at).
    template <int CT>
    void add_same_links(const float* x, int src, std::size_t r, float* g) const;
    template <int CT>
    void push_node(std::uint32_t i, std::int64_t b0);
    template <int CT>
    void pull_node(std::uint32_t c, std::int64_t b0);
    template <class NodeFn>
    void over_tree(bool down, NodeFn visit);
    template <int CT>
    bool jacobi_sweep(int iteration);
    template <int CT>
    void sweep_row(std::size_t r, const float* x, float* next, const float* before, float omega, SweepMaxima maxima);
    bool sweeps_converged(int parity) const;
    template <int CT>
    void block_totals(std::size_t q, std::int64_t lo, int count, int offset);
    void block_spots(std::size_t i, std::int64_t lo, std::int64_t hi);

    const Links& m_links;
    std::span<const Illumination* const> m_batch;
    const SolvePlan& m_plan;
    std::vector<std::vector<float>> m_rings;    // per layer: M x (ring + mirror) x C, and kRingSlackFloats
    std::vector<std::vector<float>> m_acc;      // per layer: accumulator_bins x nodes x lanes, long links' sums (a ring)
    std::vector<std::vector<float>> m_recent;   // per layer: recent_bins x M x C (SolvePlan::recent_at)
    std::vector<std::vector<float>> m_emit;     // per layer: N x bt x C by position, the block's emission
    // L x N x C by position (state_at): the bin's value before the same-bin sweeps, the last bin's
    // same-bin share.
    std::vector<float> m_base;
    // L x rows x C (SolvePlan::sweep_at): the same-bin share (converged value less m_base) of the
    // last bin and of the one before it, from which the next bin's sweeps start.
    std::vector<float> m_same, m_same_before;
    // The same-bin system's iterates, L x rows x C (SolvePlan::sweep_at): sweep k reads buffer
    // (k - 1) % B, writes k % B and with Chebyshev reads the one before from (k + 1) % B, B being
    // SolvePlan::sweep_buffers. Sweep 1 starts from buffer 0, filled as each bin's values are made.
    std::vector<float> m_sweep[3];
    // The bins kept for the sink, [m_out_lo, m_out_lo + m_out_bins): with SolvePlan::emit_blocks > 1 in
    // m_kept, the total and then each term, N x emit_bins x K x 3 by position (the order in which the
    // recent bins are read, so that both sides of the copy are streams), handed over by patch as
    // N x m_out_bins x K x 3 (SolveBlock); with one block, written there directly.
    std::vector<float> m_kept;
    std::vector<float> m_out_total, m_out_terms;
    // Per thread: a receiver tile's sums over its source tiles (SolvePlan::tile_sum_floats).
    std::vector<std::vector<float>> m_tile_sums;
    /// Per layer, every glossy patch's out-cells' lobe products of the bin (lane-major within a patch:
    /// [(g * lanes + lane) * M + cell]), made before the bin's rows (lobe_products).
    std::vector<std::vector<float>> m_lobe_out;
    std::int64_t m_out_lo = 0;
    int m_out_bins = 0;
    // The Jacobi sweep's max-reductions per lane, by the sweep's parity (a thread still reading one
    // sweep's result while another resets the next's): the largest change and the largest value;
    // and the bin's largest value outside the system (final before the sweeps).
    float m_change[2][kMaxLanes] = {}, m_largest[2][kMaxLanes] = {}, m_fixed[kMaxLanes] = {};
    std::atomic<int> m_worst_iterations{0};
    std::uint64_t m_sweeps = 0;                 // written by one thread (omp single)
    bool m_stop = false;                        // a cancelled run, as read by one thread (omp single)
};

template <int CT>
void March::store(int layer, std::size_t node, std::int64_t bin, const float* v) {
    const int C = CT > 0 ? CT : m_plan.lanes;
    const RingSlot& slot = m_plan.slots[node];
    const int pos = int(bin & slot.mask);
    float* r = m_rings[std::size_t(layer)].data() + slot.offset;
    for (int c = 0; c < C; ++c) r[std::size_t(pos * C + c)] = v[c];
    if (pos < slot.mirror)
        for (int c = 0; c < C; ++c) r[std::size_t((pos + slot.length) * C + c)] = v[c];
}

// Patch i's pulses of every illumination within the block, each into its illumination's lanes.
void March::load_emission(std::size_t i, std::int64_t b0) {
    const int bt = m_plan.block_bins, C = m_plan.lanes, channels = m_plan.channels;
    if (i >= m_plan.patches) return;  // clusters emit nothing of their own
    const std::size_t q = m_plan.position[i];
    for (int l = 0; l < m_plan.layer_count; ++l)
        std::fill_n(m_emit[std::size_t(l)].data() + q * std::size_t(bt * C), bt * C, 0.0f);
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
    // The due windows' bins: the longest one's (windows are due from the shortest up; the block's own,
    // window 0, always is).
    const int span = p.window_bins(due[count - 1]);
    const bool tiled = p.tile_sum_floats() > 0;
    const std::size_t row = std::size_t(span) * std::size_t(p.lanes);
    float* sums = tiled ? m_tile_sums[std::size_t(omp_get_thread_num())].data() : nullptr;
    for (int l = 0; l < p.layer_count; ++l) {
        const int src = p.layers.source[std::size_t(l)];
        if (src < 0) continue;
        if (tiled) std::fill_n(sums, (i1 - i0) * row, 0.0f);
        const float* ring_src = m_rings[std::size_t(src)].data();
        const RecentView recent_src{m_recent[std::size_t(src)].data(), p.nodes * std::size_t(p.lanes), p.recent_bins - 1};
        for (std::size_t i = i0; i < i1; ++i)
            for (int d = 0; d < count; ++d) cursor[i - i0][d] = p.segments[i * (S + 1) + std::size_t(due[d])];
        for (std::size_t s0 = 0; s0 < p.nodes; s0 += p.source_tile) {
            const std::uint32_t s1 = std::uint32_t(std::min(p.nodes, s0 + p.source_tile));
            const std::uint64_t key_end = std::uint64_t(s1) << p.lag_bits;  // packed links: the tile's end
            for (std::size_t i = i0; i < i1; ++i) {
                // Tiled sources add into the tile's own sums (receiver-major, so a kernel's sums add
                // as one contiguous stream), which go to the accumulators once, after the last tile.
                float* a = tiled ? sums + (i - i0) * row : m_acc[std::size_t(l)].data() + p.acc_at(i, b0);
                const std::size_t stride = tiled ? std::size_t(p.lanes) : p.acc_stride();
                // The shortest window's links, from their own list, with the first source tile.
                if (p.recent_kernel && s0 == 0)
                    p.recent_kernel({&p.near, p.near.row[i], p.near.row[i + 1], recent_src, b0, p.lanes, a, stride});
                for (int d = 0; d < count; ++d) {
                    const int s = due[d];
                    const std::uint64_t end = p.segments[i * (S + 1) + std::size_t(s) + 1];
                    // The next receivers' rows, each a line of its own far from this one: asked for
                    // while this one is summed (the check below would otherwise wait on memory).
                    if (p.packs() && i + 2 < i1) __builtin_prefetch(p.packed.data() + cursor[i + 2 - i0][d]);
                    if (cursor[i - i0][d] >= end) continue;
                    if (p.packed_kernel[s]) {
                        // Many pairs of a receiver and a source tile have no link (a wall and itself).
                        if (p.packed[cursor[i - i0][d]].key >= key_end) continue;
                        p.packed_kernel[s]({p.packed.data(), &cursor[i - i0][d], end, key_end, p.lag_bits, ring_src,
                                            p.packed_ring_floats, p.longest_ring - 1, b0, a, stride});
                        continue;
                    }
                    const LongCall call{&m_links, &cursor[i - i0][d], end, s1, p.inv_bin_f, p.delay, ring_src,
                                        p.slots.data(), b0, p.lanes, p.window_bins(s), a, stride};
                    if (p.kernel[s])
                        p.kernel[s](call);
                    else if (p.lane_kernel[s])
                        p.lane_kernel[s](call);
                    else
                        gather_long_any(call);
                }
            }
        }
        // Bin by bin: a bin's accumulators of the tile's receivers are together (bin-major).
        if (tiled)
            for (int b = 0; b < span; ++b)
                for (std::size_t i = i0; i < i1; ++i) {
                    const float* from = sums + (i - i0) * row + std::size_t(b * p.lanes);
                    float* to = m_acc[std::size_t(l)].data() + p.acc_at(i, b0 + b);
                    for (int c = 0; c < p.lanes; ++c) to[c] += from[c];
                }
        if (!p.tinted_long.empty())
            for (std::size_t i = i0; i < std::min(i1, p.patches); ++i)
                gather_tinted(i, ring_src, b0, m_acc[std::size_t(l)].data() + p.acc_at(i, b0));
    }
}

// Patch i's tinted links of lag >= bt over the block, into its accumulators `acc`: each one multiply-add
// per tap and colour over the block, reading final history from the ring of its source (`ring`).
void March::gather_tinted(std::size_t i, const float* ring, std::int64_t b0, float* acc) const {
    const SolvePlan& p = m_plan;
    const std::size_t C = std::size_t(p.lanes), stride = p.acc_stride();
    for (std::uint64_t k = p.tinted_long_row[i]; k < p.tinted_long_row[i + 1]; ++k) {
        const TintedLink& t = p.tinted_long[k];
        const RingSlot& slot = p.slots[t.source];
        const float* h = ring + slot.offset + std::size_t(int((b0 - t.lag - 1) & slot.mask)) * C;
        for (std::size_t b = 0; b < std::size_t(p.block_bins); ++b) {  // two accumulations, as in gather_long
            add_tinted(acc + b * stride, t.w0, h + (b + 1) * C, p.lanes, p.channels);
            add_tinted(acc + b * stride, t.w1, h + b * C, p.lanes, p.channels);
        }
    }
}

void March::long_pass(std::int64_t b0) {
    const std::size_t tiles = (m_plan.nodes + kReceiverTile - 1) / kReceiverTile;
#pragma omp for schedule(dynamic, 1)
    for (std::size_t tile = 0; tile < tiles; ++tile) {
        // A cancelled run skips the rest of the pass (a long block of a large flat set takes seconds);
        // solve_transient throws after the region.
        if (cancel_requested()) continue;
        const std::size_t i0 = tile * kReceiverTile, i1 = std::min(m_plan.nodes, i0 + kReceiverTile);
        for (std::size_t i = i0; i < i1; ++i) load_emission(i, b0);
        gather_tile(i0, i1, b0);
    }
}

// The patch at position q at bin b0 + o: the long links' sum (with every cluster's above it) plus its
// short links, the emission, stored in the recent bins (the rings take it after the same-bin sweeps).
template <int CT>
void March::add_short_links(int src, std::size_t q, std::int64_t bin, float* g) const {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes;
    float sum[CT > 0 ? CT : kMaxLanes];
    std::fill_n(sum, C, 0.0f);
    for (std::uint64_t k = p.short_row[q]; k < p.short_row[q + 1]; ++k) {
        const TapLink& s = p.short_links[k];
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

// Glossy patch g's out-cells at `bin`: its lobe over its in-cells of the bin before, every layer and
// lane, into m_lobe_out. A sum over in-cells of a column of the lobe times one in-cell's value (the
// lobe is stored in-cell by in-cell), so that the inner loop runs over the out-cells in one vector.
void March::lobe_products(std::size_t g, std::int64_t bin) {
    const SolvePlan& p = m_plan;
    const GlossyRows& rows = p.set->glossy;
    const std::size_t m = std::size_t(rows.cells()), C = std::size_t(p.lanes);
    const float* lobe = rows.lobe_of_patch(*p.patches_of, g);
    for (int l = 0; l < p.layer_count; ++l) {
        const float* h = recent(l, p.position[rows.in_row(g, 0)], bin - 1);  // the in-cells, one after the other
        float* out = m_lobe_out[std::size_t(l)].data() + g * C * m;
        std::fill_n(out, C * m, 0.0f);
        for (std::size_t in = 0; in < m; ++in) {
            const float* column = lobe + in * m;
            for (std::size_t ch = 0; ch < C; ++ch) {
                const float v = h[in * C + ch];
                float* o = out + ch * m;
                for (std::size_t c = 0; c < m; ++c) o[c] += column[c] * v;
            }
        }
    }
}

template <int CT>
void March::add_same_links(const float* x, int src, std::size_t r, float* g) const {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes;
    float sum[CT > 0 ? CT : kMaxLanes];
    std::fill_n(sum, C, 0.0f);
    for (std::uint64_t k = p.same_row[r]; k < p.same_row[r + 1]; ++k) {
        const float* h = x + p.sweep_at(src, p.same_links[k].source);
        for (int c = 0; c < C; ++c) sum[c] += p.same_links[k].w * h[c];
    }
    if (!p.tinted_same.empty())
        for (std::uint64_t k = p.tinted_same_row[r]; k < p.tinted_same_row[r + 1]; ++k)
            add_tinted(sum, p.tinted_same[k].w, x + p.sweep_at(src, p.tinted_same[k].source), C, p.channels);
    for (int c = 0; c < C; ++c) g[c] += sum[c];
}

template <int CT>
void March::short_links_of(std::size_t q, std::int64_t b0, int o, float* fixed) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes;
    const std::int64_t bin = b0 + o;
    const float* albedo = p.albedo.data() + std::size_t(C) * q;
    for (int l = 0; l < p.layer_count; ++l) {
        const int src = p.layers.source[std::size_t(l)];
        float g[CT > 0 ? CT : kMaxLanes];
        const std::size_t at = q * std::size_t(p.block_bins * C) + std::size_t(o * C);
        // The long links' sums for this bin, taken (the accumulator ring's slot is free again).
        float* acc = m_acc[std::size_t(l)].data() + p.acc_at_slot(q, bin);
        for (int c = 0; c < C; ++c) {
            g[c] = acc[c];
            acc[c] = 0.0f;
        }
        if (src >= 0) add_short_links<CT>(src, q, bin, g);
        // A glossy out-cell: its lobe over its in-cells' light of the same order, one bin before.
        if (const std::size_t i = p.order[q]; i >= p.out_begin) {
            const std::size_t m = std::size_t(p.set->glossy.cells()), j = i - p.out_begin;
            const float* lobe = m_lobe_out[std::size_t(l)].data() + (j / m) * std::size_t(C) * m + j % m;
            for (int c = 0; c < C; ++c) g[c] += lobe[std::size_t(c) * m];
        }
        float b[CT > 0 ? CT : kMaxLanes];
        for (int c = 0; c < C; ++c) b[c] = m_emit[std::size_t(l)][at + std::size_t(c)] + albedo[c] * g[c];
        float* keep = m_base.data() + state_at(l, q);
        for (int c = 0; c < C; ++c) keep[c] = b[c];
        const bool same = !m_same.empty();
        const std::int32_t r = same ? p.sweep_row_of[q] : -1;
        if (r >= 0) {
            // The system's rows: the sweeps start from the same-bin share extrapolated from the last
            // two bins (profiles are smooth where the sweeps take longest, so they start nearer their
            // fixed point), and store the converged value.
            const std::size_t s = p.sweep_at(l, std::size_t(r));
            float* start = m_sweep[0].data() + s;
            for (int c = 0; c < C; ++c) start[c] = b[c] + (2.0f * m_same[s + std::size_t(c)] - m_same_before[s + std::size_t(c)]);
            continue;
        }
        // Outside the system the value is final.
        if (same)
            for (int c = 0; c < C; ++c) fixed[c] = std::max(fixed[c], std::abs(b[c]));
        store_recent<CT>(l, q, bin, b);
    }
}

// Node i's long-link sums over the block plus its parent's (after the parent's own push).
template <int CT>
void March::push_node(std::uint32_t i, std::int64_t b0) {
    const int C = CT > 0 ? CT : m_plan.lanes;
    const std::uint32_t up = m_plan.tree->parent[i];
    if (up == kNoNode) return;
    for (int l = 0; l < m_plan.layer_count; ++l)
        for (std::int64_t bin = b0; bin < b0 + m_plan.block_bins; ++bin) {
            float* own = m_acc[std::size_t(l)].data() + m_plan.acc_at(i, bin);
            const float* from = m_acc[std::size_t(l)].data() + m_plan.acc_at(up, bin);
            for (int c = 0; c < C; ++c) own[c] += from[c];
        }
}

// Cluster c's radiosity over the block's bins: the area-weighted mean of its children's. Its long-link
// sums for the block, pushed to its children by now, are cleared.
template <int CT>
void March::pull_node(std::uint32_t c, std::int64_t b0) {
    const int C = CT > 0 ? CT : m_plan.lanes;
    const ClusterTree& t = *m_plan.tree;
    const auto [a, b] = t.children[c - t.leaves];
    const float wa = float(t.area[a] / t.area[c]), wb = float(t.area[b] / t.area[c]);
    for (int l = 0; l < m_plan.layer_count; ++l)
        for (std::int64_t bin = b0; bin < b0 + m_plan.block_bins; ++bin)
            std::fill_n(m_acc[std::size_t(l)].data() + m_plan.acc_at(c, bin), C, 0.0f);
    // The children's bins from the recent bins (by node slot: a cluster's children are near there).
    auto value = [&](int l, std::uint32_t node, std::int64_t bin) { return recent(l, m_plan.node_slot(node), bin); };
    for (int l = 0; l < m_plan.layer_count; ++l)
        for (std::int64_t bin = b0; bin < b0 + m_plan.block_bins; ++bin) {
            const float* va = value(l, a, bin);
            const float* vb = value(l, b, bin);
            float v[kMaxLanes];
            for (int ch = 0; ch < C; ++ch) v[ch] = wa * va[ch] + wb * vb[ch];
            store<CT>(l, c, bin, v);
            store_recent<CT>(l, c, bin, v);
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
    with_lanes(m_plan.lanes, [&](auto lanes) {
        over_tree(true, [&](std::uint32_t i) { push_node<decltype(lanes)::value>(i, b0); });
    });
}

void March::pull_block(std::int64_t b0) {
    with_lanes(m_plan.lanes, [&](auto lanes) {
        over_tree(false, [&](std::uint32_t c) { pull_node<decltype(lanes)::value>(c, b0); });
    });
}

// One Jacobi sweep of the same-bin system (in a region), sweep `iteration` (from 1) of this bin; true
// when it has converged to float resolution, where further sweeps cannot change the stored values
// meaningfully. With SolvePlan::same_radius, Chebyshev's semi-iteration (Golub and Varga 1961):
// x_{k+1} = omega_{k+1} (J(x_k) - x_{k-1}) + x_{k-1}, which has the same fixed point and, for a
// spectrum in [-rho, rho], converges at rho / (1 + sqrt(1 - rho^2)) per sweep instead of rho.
template <int CT>
bool March::jacobi_sweep(int iteration) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes;
    const bool extrapolate = p.same_radius > 0.0 && iteration > 1;
    const float omega = extrapolate ? p.chebyshev_weights[std::size_t(std::min(iteration, kMaxSweeps) - 1)] : 1.0f;
    const int B = p.sweep_buffers(), parity = iteration & 1;
    const float* x = m_sweep[(iteration - 1) % B].data();
    float* next = m_sweep[iteration % B].data();
    const float* before = extrapolate ? m_sweep[(iteration + 1) % B].data() : nullptr;
#pragma omp single
    {
        std::fill_n(m_change[parity], C, 0.0f);
        std::fill_n(m_largest[parity], C, 0.0f);
    }
    float change[CT > 0 ? CT : kMaxLanes], largest[CT > 0 ? CT : kMaxLanes];
    std::fill_n(change, C, 0.0f);
    std::fill_n(largest, C, 0.0f);
#pragma omp for schedule(static) nowait
    for (std::size_t r = 0; r < p.sweep_rows.size(); ++r) sweep_row<CT>(r, x, next, before, omega, {change, largest});
#pragma omp critical(tprf_jacobi_reduction)
    for (int c = 0; c < C; ++c) {
        m_change[parity][c] = std::max(m_change[parity][c], change[c]);
        m_largest[parity][c] = std::max(m_largest[parity][c], largest[c]);
    }
#pragma omp barrier
    return sweeps_converged(parity);
}

// The sweep's new values of the system's row r (into `next`) from the iterate `x` (and with Chebyshev
// the one before it, `before`), and per lane the largest change from x and the largest new value so far.
template <int CT>
void March::sweep_row(std::size_t r, const float* x, float* next, const float* before, float omega,
                      SweepMaxima maxima) {
    float* change = maxima.change;
    float* largest = maxima.largest;
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes;
    const std::size_t q = p.sweep_rows[r];
    const float* albedo = p.albedo.data() + std::size_t(C) * q;
    for (int l = 0; l < p.layer_count; ++l) {
        const int src = p.layers.source[std::size_t(l)];
        const float* keep = m_base.data() + state_at(l, q);
        const std::size_t at = p.sweep_at(l, r);
        float g[CT > 0 ? CT : kMaxLanes];
        std::fill_n(g, C, 0.0f);
        if (src >= 0) add_same_links<CT>(x, src, r, g);
        for (int c = 0; c < C; ++c) {
            float v = keep[c] + albedo[c] * g[c];
            if (before) v = before[at + std::size_t(c)] + omega * (v - before[at + std::size_t(c)]);
            next[at + std::size_t(c)] = v;
            change[c] = std::max(change[c], std::abs(v - x[at + std::size_t(c)]));
            largest[c] = std::max(largest[c], std::abs(v));
        }
    }
}

// Whether every illumination's same-bin values have converged to float resolution: its largest change
// at most 1e-7 of its largest value. Each illumination is judged on its own lanes, so that a faint one
// sweeps as long as it would alone, however bright the others.
bool March::sweeps_converged(int parity) const {
    const int channels = m_plan.channels;
    for (int k = 0; k < m_plan.illuminations; ++k) {
        float change = 0.0f, largest = 0.0f;
        for (int c = k * channels; c < (k + 1) * channels; ++c) {
            change = std::max(change, m_change[parity][c]);
            largest = std::max({largest, m_largest[parity][c], m_fixed[c]});
        }
        if (!(change <= 1e-7f * largest)) return false;
    }
    return true;
}

template <int CT>
void March::short_pass_lanes(std::int64_t b0) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes;
    const bool same = p.same_bin();
    for (int o = 0; o < p.block_bins; ++o) {
        // A cancelled run leaves the block here (solve_transient throws after the region): every
        // thread reads the one answer after the single's barrier, so all leave at the same bin.
#pragma omp single
        {
            m_stop = cancel_requested();
            std::fill_n(m_fixed, p.lanes, 0.0f);
        }
        if (m_stop) break;
        // The glossy patches' lobes (their in-cells of the bin before are final).
        if (!p.set->glossy.empty()) {
#pragma omp for schedule(static)
            for (std::size_t g = 0; g < p.set->glossy.glossy.size(); ++g) lobe_products(g, b0 + o);
        }
        float fixed[kMaxLanes];
        std::fill_n(fixed, p.lanes, 0.0f);
        // Each thread its share of the positions, balanced by their links (SolvePlan::short_split).
        const std::size_t threads = std::size_t(omp_get_num_threads()), t = std::size_t(omp_get_thread_num());
        const bool split = threads + 1 == p.short_split.size();
        const std::size_t q0 = split ? p.short_split[t] : p.patches * t / threads;
        const std::size_t q1 = split ? p.short_split[t + 1] : p.patches * (t + 1) / threads;
        for (std::size_t q = q0; q < q1; ++q) short_links_of<CT>(q, b0, o, fixed);
        if (same) {
#pragma omp critical(tprf_jacobi_reduction)
            for (int c = 0; c < p.lanes; ++c) m_fixed[c] = std::max(m_fixed[c], fixed[c]);
        }
#pragma omp barrier
        int last = 0;  // the sweep whose iterate is the bin's value
        for (int iteration = 1; iteration <= kMaxSweeps && same; ++iteration) {
            last = iteration;
            if (!jacobi_sweep<CT>(iteration)) continue;
#pragma omp single
            {
                if (iteration > m_worst_iterations.load()) m_worst_iterations.store(iteration);
                m_sweeps += std::uint64_t(iteration);
            }
            break;
        }
        // The system's rows take the converged values into the recent bins, and the next bin's
        // sweeps the same-bin share.
        if (!same) continue;
        const float* converged = m_sweep[last % p.sweep_buffers()].data();
#pragma omp for schedule(static)
        for (std::size_t r = 0; r < p.sweep_rows.size(); ++r)
            for (int l = 0; l < p.layer_count; ++l) {
                const std::size_t q = p.sweep_rows[r], s = p.sweep_at(l, r);
                const float* v = converged + s;
                store_recent<CT>(l, q, b0 + o, v);
                const float* base = m_base.data() + state_at(l, q);
                for (int c = 0; c < C; ++c) {
                    m_same_before[s + std::size_t(c)] = m_same[s + std::size_t(c)];
                    m_same[s + std::size_t(c)] = v[c] - base[c];
                }
            }
    }
    // The block's bins into every patch's ring at once: a patch's bins are together there (a cache
    // line or two), its bins of one time far apart. Nothing reads a patch's ring at the block's bins
    // before the next block's long pass: the bin-by-bin passes and the pull read the recent bins.
#pragma omp for schedule(static)
    for (std::size_t q = 0; q < p.patches; ++q)
        for (int l = 0; l < p.layer_count; ++l)
            for (std::int64_t bin = b0; bin < b0 + p.block_bins; ++bin) store<CT>(l, p.order[q], bin, recent(l, q, bin));
}

// The total and per-order terms of the patch at position q for the bins [lo, lo + count), into its
// rows from bin `offset` on, every illumination's (a grey lane fills all three colours); CT lanes (0: C,
// at run time).
template <int CT>
void March::block_totals(std::size_t q, std::int64_t lo, int count, int offset) {
    const SolvePlan& p = m_plan;
    const int C = CT > 0 ? CT : p.lanes, L = p.layer_count, K = p.illuminations;
    const LayerPlan& plan = p.layers;
    // Kept rows (by position) are emit_bins long; rows written for the sink directly (one block per
    // hand-over, offset 0) `count`.
    const bool kept = !m_kept.empty();
    const std::size_t row = std::size_t(kept ? p.emit_bins() : count) * std::size_t(K) * 3, part = p.patches * row;
    // Short blocks from the recent bins (which hold the whole block; compact, and in cache), long ones
    // from the ring, where a patch's bins are contiguous.
    const std::size_t i = p.order[q];
    if (p.unread(i)) return;  // a glossy in-cell: left zero (SolveBlock::unread)
    auto value = [&](int layer, std::int64_t bin) -> const float* {
        return count <= 4 ? recent(layer, q, bin) : ring_at(layer, i, bin);
    };
    float* const total_out = kept ? m_kept.data() : m_out_total.data();
    float* const terms_out = kept ? m_kept.data() + part : m_out_terms.data();
    auto put = [&](float* out, int o, const float* lanes) {
        float* at = out + (kept ? q : i) * row + std::size_t(offset + o) * std::size_t(K) * 3;
        for (int k = 0; k < K; ++k)
            for (int c = 0; c < 3; ++c) at[k * 3 + c] = lanes[p.lane(k, c)];
    };
    for (int o = 0; o < count; ++o) {
        const std::int64_t bin = lo + o;
        float total[kMaxLanes];  // put() reads lanes by illumination and colour: sized for any
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
        put(total_out, o, total);
        for (int k = 0; k < plan.terms; ++k) {
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
            put(terms_out + std::size_t(k) * part, o, v);
        }
    }
}

// Pulses seen but not propagated (the laser spot) join the output only, each its illumination's: those
// of the bins [lo, hi) handed over.
void March::block_spots(std::size_t i, std::int64_t lo, std::int64_t hi) {
    const SolvePlan& p = m_plan;
    const LayerPlan& plan = p.layers;
    const std::size_t count = std::size_t(hi - lo), K = std::size_t(p.illuminations);
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
                    m_out_terms[term * p.patches * count * K * 3 + at + std::size_t(c)] += float(pulse.energy[c]);
                }
            }
        }
    }
}

void March::emit_block(std::int64_t b0, const BlockSink& sink) {
    const SolvePlan& p = m_plan;
    const int stride = p.emit_bins();
    const std::int64_t lo = std::max<std::int64_t>(b0, p.first_emitted);
    const std::int64_t hi = std::min<std::int64_t>(b0 + p.block_bins, p.bins);
    if (lo < hi) {
        if (m_out_bins == 0) m_out_lo = lo;
        TPRF_CHECK_EQ(lo, m_out_lo + m_out_bins);
        const int offset = m_out_bins, count = int(hi - lo);
        // By position, the order of the recent bins, the rings and the kept rows.
        with_lanes(p.lanes, [&](auto lanes) {
            parallel_for(p.patches, {p.threads, 1, false},
                         [&](std::size_t q) { block_totals<decltype(lanes)::value>(q, lo, count, offset); });
        });
        m_out_bins += count;
    }
    // The kept bins go when the next block's would not fit, and at the last block: each patch's rows
    // (total, then terms) where SolveBlock has them, with the spots.
    if (m_out_bins == 0 || (m_out_bins + p.block_bins <= stride && b0 + p.block_bins < p.bins)) return;
    const int count = m_out_bins;
    const std::size_t lanes = std::size_t(p.illuminations) * 3, kept_row = std::size_t(stride) * lanes;
    const std::size_t row = std::size_t(count) * lanes;
    parallel_for(p.patches, {p.threads, 1, false}, [&](std::size_t i) {
        if (p.unread(i)) return;  // a glossy in-cell: left zero
        if (!m_kept.empty()) {
            const std::size_t q = p.position[i];
            std::copy_n(m_kept.data() + q * kept_row, row, m_out_total.data() + i * row);
            for (int k = 0; k < p.layers.terms; ++k)
                std::copy_n(m_kept.data() + (std::size_t(1 + k) * p.patches + q) * kept_row, row,
                            m_out_terms.data() + (std::size_t(k) * p.patches + i) * row);
        }
        block_spots(i, m_out_lo, m_out_lo + count);
    });
    SolveBlock block;
    block.first_bin = int(m_out_lo);
    block.bins = count;
    block.patches = p.patches;
    block.illuminations = p.illuminations;
    block.radiosity = m_out_total.data();
    block.terms = p.layers.terms;
    block.per_order = p.layers.terms > 0 ? m_out_terms.data() : nullptr;
    block.unread_first = p.in_begin();
    block.unread_last = p.out_begin;
    if (sink) sink(block);
    m_out_bins = 0;
}

double lap(std::chrono::steady_clock::time_point& since) {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - since).count();
    since = now;
    return s;
}

}  // namespace
}  // namespace solver_detail

using namespace solver_detail;

SolveStats solve_transient(const PatchSet& patches, const LinkSet& set, const Illumination& illumination,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink) {
    const Illumination* const one[1] = {&illumination};
    return solve_transient(patches, set, std::span<const Illumination* const>(one), time, options, sink);
}

std::size_t solve_working_bytes(const PatchSet& patches, const LinkSet& set, const TimeAxis& time,
                                const SolverOptions& options, int illuminations, int channels) {
    return solve_sizing(patches, set, time, options, illuminations, channels).working_bytes;
}

int batch_that_fits(double one_bytes, double full_bytes, double memory_bytes) {
    const double per_lane = std::max(0.0, (full_bytes - one_bytes) / (kMaxBatch - 1));
    if (!(per_lane > 0.0)) return memory_bytes >= one_bytes ? kMaxBatch : 1;
    return int(std::clamp(1.0 + std::floor((memory_bytes - one_bytes) / per_lane), 1.0, double(kMaxBatch)));
}

int capture_batch(const std::function<double(int)>& working_bytes, double budget_bytes) {
    int batch = batch_that_fits(working_bytes(1), working_bytes(kMaxBatch), budget_bytes);
    while (batch > 1 && working_bytes(batch) > budget_bytes) --batch;
    return batch;
}

SolveStats solve_transient(const PatchSet& patches, const LinkSet& set, std::span<const Illumination* const> batch,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink) {
    const Links& links = set.links;
    TPRF_CHECK_EQ(links.receivers(), set.nodes());
    TPRF_CHECK_LE(std::size_t(1), batch.size());
    TPRF_CHECK_LE(batch.size(), std::size_t(kMaxBatch));
    for (const Illumination* illumination : batch) {
        TPRF_CHECK(illumination != nullptr);
        TPRF_CHECK_EQ(illumination->row.size(), set.patches() + 1);  // the patches and the glossy rows
    }
    check_tints(links);
    SolvePlan plan =
        make_plan(patches, set, time, options,
                  {int(batch.size()), march_channels(keeps_grey(patches, links) && keeps_grey(set.glossy) && pulses_grey(batch))});
    TPRF_CHECK_LE(options.first_bin, 0);
    plan.first_emitted = options.first_bin;
    plan_blocks(plan, batch);
    March march(batch, plan);
    SolveStats stats;
    stats.block_bins = plan.block_bins;
    stats.wide_kernels = plan.wide;
    stats.packed_links = plan.packed_count;
    stats.ring_bins = plan.longest_ring;
    stats.channels = plan.channels;
    stats.illuminations = plan.illuminations;
    stats.lanes = plan.lanes;
    stats.working_bytes = working_bytes(plan);
    for (std::int64_t blk = 0; blk < plan.blocks; ++blk) {
        const std::int64_t b0 = plan.start_bin + blk * plan.block_bins;
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
                             std::uint64_t(plan.blocks) * std::uint64_t(plan.block_bins);
    stats.max_jacobi_iterations = march.worst_jacobi_iterations();
    stats.jacobi_sweeps = march.jacobi_sweeps();
    stats.short_links = plan.short_links.size() + plan.tinted_short.size();
    return stats;
}

}  // namespace tprf
