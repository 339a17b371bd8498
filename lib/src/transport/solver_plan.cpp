// The transient solver's plan: sorting the links into the long pass, the bin-by-bin lists and the
// tinted lists, the windows, the same-bin sweeps' bound, the rings and the blocks (solver_plan.h).

#include "solver_plan.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>

namespace tprf::solver_detail {
namespace {

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
        const DelayTaps t = delay_taps_f(links.distance[k], inv_bin, mode, links.ff[k] * f[std::size_t(c)]);
        out.lag = t.lag;
        out.w0[c] = t.w0;
        out.w1[c] = t.w1;
    }
    return out;
}

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

// Layers that gather from links: all but those of the pulses alone.
int fed_layers(const LayerPlan& plan) {
    int fed = 0;
    for (int l = 0; l < plan.layers(); ++l) fed += plan.source[std::size_t(l)] >= 0;
    return fed;
}

// The links that have to be applied bin by bin (lag < bt), as lists by receiver patch; the tinted
// ones (sized only when some link is tinted), long ones included.
struct BinLinks {
    std::vector<std::vector<TapLink>> shorts;
    std::vector<std::vector<SameBinLink>> same;
    std::vector<std::vector<TintedLink>> tinted_long, tinted_shorts;
    std::vector<std::vector<TintedSameLink>> tinted_same;
};

// Adds a link of lag < bt between patches (the same-bin system takes a lag-0 link's w0 tap).
void add_bin_link(BinLinks& out, std::size_t receiver, std::uint32_t source, const DelayTaps& t, float scale) {
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
    TPRF_CHECK(i < plan.patches && s < plan.patches);  // only links between patches are tinted (Links::tint)
    TintedLink t = tinted_taps(links, k, s, plan.inv_bin_f, plan.delay);
    if (t.lag >= plan.block_bins) {
        plan.send_window[s] = std::max(plan.send_window[s], plan.block_bins);
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
    plan.tinted_long_row.assign(plan.patches + 1, 0);
    plan.tinted_short_row.assign(plan.patches + 1, 0);
    plan.tinted_same_row.assign(plan.patches + 1, 0);
    for (std::size_t i = 0; i < plan.patches; ++i) {
        plan.tinted_long.insert(plan.tinted_long.end(), bins.tinted_long[i].begin(), bins.tinted_long[i].end());
        plan.tinted_long_row[i + 1] = plan.tinted_long.size();
    }
    for (std::size_t q = 0; q < plan.patches; ++q) {
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
    bins.shorts.resize(plan.patches);
    bins.same.resize(plan.patches);
    const bool tinted = any_tinted(links);
    if (tinted) {
        bins.tinted_long.resize(plan.patches);
        bins.tinted_shorts.resize(plan.patches);
        bins.tinted_same.resize(plan.patches);
    }
    plan.send_lag.assign(plan.nodes, 0);
    plan.send_window.assign(plan.nodes, 0);
    for (std::size_t i = 0; i < plan.nodes; ++i) {
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) {
            const DelayTaps t = delay_taps_f(links.distance[k], plan.inv_bin_f, plan.delay, links.ff[k]);
            plan.max_lag = std::max(plan.max_lag, t.lag);
            const std::uint32_t s = links.source[k];
            plan.send_lag[s] = std::max(plan.send_lag[s], t.lag);
            if (tinted && tinted_link(links, k)) {
                add_tinted_link(bins, plan, links, k, i, s);
                continue;
            }
            if (t.lag >= plan.block_bins) {
                plan.send_window[s] = std::max(plan.send_window[s], plan.window_bins(plan.window_of(t.lag)));
                continue;
            }
            if (i < plan.patches && s < plan.patches) {
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
    plan.position.assign(plan.patches, 0);
    for (std::size_t q = 0; q < plan.patches; ++q) plan.position[plan.order[q]] = std::uint32_t(q);
    for (std::size_t i = 0; i < plan.patches; ++i) {
        for (TapLink& l : bins.shorts[i]) l.source = plan.position[l.source];
        for (SameBinLink& l : bins.same[i]) l.source = plan.position[l.source];
    }
    plan.short_row.assign(plan.patches + 1, 0);
    plan.same_row.assign(plan.patches + 1, 0);
    plan.albedo.resize(plan.patches * std::size_t(plan.lanes));
    for (std::size_t q = 0; q < plan.patches; ++q) {
        const std::size_t i = plan.order[q];
        plan.short_links.insert(plan.short_links.end(), bins.shorts[i].begin(), bins.shorts[i].end());
        plan.same_links.insert(plan.same_links.end(), bins.same[i].begin(), bins.same[i].end());
        std::vector<TapLink>().swap(bins.shorts[i]);
        std::vector<SameBinLink>().swap(bins.same[i]);
        plan.short_row[q + 1] = plan.short_links.size();
        plan.same_row[q + 1] = plan.same_links.size();
        for (int c = 0; c < plan.lanes; ++c)
            plan.albedo[q * std::size_t(plan.lanes) + std::size_t(c)] = float(plan.set->albedo(patches, i)[c % plan.channels]);
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
    for (std::size_t i = 0; i < plan.nodes; ++i) {
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

// Dense rows (sources in tiles) whose lane count has packed kernels: the bits of a packed key's lag
// (MarchShape::lag_bits), or 0 where a source and a lag do not fit one word or a window of
// bt..kDenseLongestWindow bins has no packed kernel.
int packed_lag_bits(const MarchInputs& in, const MarchShape& s, bool wide) {
    // Flat sets only: a dense hierarchical set would lose its per-node rings (every packed ring is as
    // long as the longest).
    if (in.clusters || s.source_tile >= s.nodes || s.block_bins > kDenseLongestWindow) return 0;
    for (int bins = s.block_bins; bins <= kDenseLongestWindow; bins *= 2)
        if (!packed_kernel_for(s.lanes, bins, wide)) return 0;
    // A link's lag grows with its length: the longest link's is the largest.
    const int bits = std::max(1, int(std::bit_width(unsigned(in.longest_lag))));
    return bits < 32 && (std::uint64_t(s.nodes) << bits) <= (std::uint64_t(1) << 32) ? bits : 0;
}

// plan.packed: the grey links of every row at least a block long (tinted ones have lists of their own,
// shorter ones the bin-by-bin pass's) with their taps, each row stably sorted by window (sources stay
// non-decreasing within one); and the segments. Rows in parallel, twice: their counts, then the links
// (not where the plan is only sized: SolvePlan::packed_count is all that solve_working_bytes needs).
void pack_links(const Links& links, SolvePlan& plan, bool fill) {
    const std::size_t S = std::size_t(plan.windows);
    const bool tinted = any_tinted(links);
    auto packs = [&](std::uint64_t k) {
        return !(tinted && tinted_link(links, k)) &&
               delay_taps_f(links.distance[k], plan.inv_bin_f, plan.delay, 1.0f).lag >= plan.block_bins;
    };
    std::vector<std::uint64_t> start(plan.nodes + 1, 0);
    parallel_for(plan.nodes, LoopSchedule{plan.threads, 64, true}, [&](std::size_t i) {
        std::uint64_t count = 0;
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) count += packs(k) ? 1 : 0;
        start[i + 1] = count;
    });
    for (std::size_t i = 0; i < plan.nodes; ++i) start[i + 1] += start[i];
    plan.packed_count = start[plan.nodes];
    if (!fill) return;
    plan.packed.resize(start[plan.nodes]);
    std::vector<std::vector<std::pair<int, PackedLink>>> rows(std::size_t(plan.threads));
    parallel_for(plan.nodes, LoopSchedule{plan.threads, 64, true}, [&](std::size_t i) {
        std::vector<std::pair<int, PackedLink>>& row = rows[std::size_t(omp_get_thread_num())];
        row.clear();
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) {
            if (tinted && tinted_link(links, k)) continue;
            const DelayTaps t = delay_taps_f(links.distance[k], plan.inv_bin_f, plan.delay, links.ff[k]);
            if (t.lag < plan.block_bins) continue;  // as packs(k): a lag does not depend on the form factor
            row.push_back({plan.window_of(t.lag), {(links.source[k] << plan.lag_bits) | std::uint32_t(t.lag), t.w0, t.w1}});
        }
        // Windows 0 to S - 1, one pass each: stable, and S is small.
        std::uint64_t at = start[i];
        for (int s = 0; s < int(S); ++s) {
            plan.segments[i * (S + 1) + std::size_t(s)] = at;
            for (const auto& [window, link] : row)
                if (window == s) plan.packed[at++] = link;
        }
        plan.segments[i * (S + 1) + S] = at;
    });
}

// Every row's range of links per window of the long pass (SolvePlan::segments). Rows of a
// hierarchical set come sorted by delay octave, which for the linear delay orders them by window;
// other rows are sorted here, into a copy, when more than one window is used. The kernels read grey
// links only: a set with tinted links is copied without them. Dense rows of a flat set are packed
// instead (pack_links), where packed kernels serve their lanes; `fill`: with their links, not only counted.
void plan_windows(const Links& links, SolvePlan& plan, bool wide, bool fill) {
    plan.links = &links;
    const std::size_t S = std::size_t(plan.windows);
    plan.segments.assign(plan.nodes * (S + 1), 0);
    auto window = [&](const Links& l, std::uint64_t k) {
        return plan.window_of(delay_taps_f(l.distance[k], plan.inv_bin_f, plan.delay, 1.0f).lag);
    };
    if (plan.packs()) {
        pack_links(links, plan, fill);
        for (int s = 0; s < plan.windows; ++s)
            plan.packed_kernel[s] = packed_kernel_for(plan.lanes, plan.window_bins(s), wide);
        return;
    }
    const bool tinted = any_tinted(links);
    bool ordered = true;
    for (std::size_t i = 0; i < plan.nodes && ordered && S > 1; ++i)
        for (std::uint64_t k = links.row[i] + 1; k < links.row[i + 1] && ordered; ++k)
            ordered = window(links, k - 1) <= window(links, k);
    if (tinted || !ordered) {
        copy_grey_links(links, plan, S > 1, window);
        plan.links = &plan.sorted;
    }
    const Links& l = *plan.links;
    if (S == 1) {
        for (std::size_t i = 0; i < plan.nodes; ++i) {
            plan.segments[2 * i] = l.row[i];
            plan.segments[2 * i + 1] = l.row[i + 1];
        }
        return;
    }
    for (std::size_t i = 0; i < plan.nodes; ++i) {
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
    const std::size_t n = plan.patches;
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
            y[q] = plan.set->albedo(patches, plan.order[q]).maxCoeff() * sum;
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
    if (plan.layer_count != 1 || plan.layers.source[0] != 0 || !plan.same_bin()) return;
    const double rho = same_bin_radius(patches, plan);
    if (rho > 0.05 && rho < 0.95) plan.same_radius = rho;
    double w = 1.0;
    for (int k = 1; k <= kMaxSweeps; ++k) {
        w = k == 1 ? 1.0 : k == 2 ? 1.0 / (1.0 - 0.5 * rho * rho) : 1.0 / (1.0 - 0.25 * rho * rho * w);
        plan.chebyshev_weights.push_back(float(w));
    }
}

// SolvePlan::short_split: the positions cut into plan.threads ranges of about equal work.
void split_positions(SolvePlan& plan) {
    auto work = [&](std::size_t q) {
        std::uint64_t w = kShortPatchLinks + (plan.short_row[q + 1] - plan.short_row[q]);
        if (!plan.tinted_short_row.empty()) w += plan.tinted_short_row[q + 1] - plan.tinted_short_row[q];
        return w;
    };
    std::uint64_t total = 0;
    for (std::size_t q = 0; q < plan.patches; ++q) total += work(q);
    const std::size_t T = std::size_t(plan.threads);
    plan.short_split.assign(T + 1, plan.patches);
    plan.short_split[0] = 0;
    std::uint64_t done = 0;
    std::size_t t = 1;
    for (std::size_t q = 0; q < plan.patches && t < T; ++q) {
        done += work(q);
        while (t < T && done * T >= total * t) plan.short_split[t++] = q + 1;
    }
}

// The same-bin system restricted to its rows (SolvePlan::sweep_rows): the patches that receive or send a
// same-bin link, in position order, their link lists re-indexed by row.
void compact_same_bin(SolvePlan& plan) {
    plan.sweep_row_of.assign(plan.patches, -1);
    if (!plan.same_bin()) return;
    std::vector<char> in(plan.patches, 0);
    for (std::size_t q = 0; q < plan.patches; ++q) {
        const bool receives = plan.same_row[q + 1] > plan.same_row[q] ||
                              (!plan.tinted_same.empty() && plan.tinted_same_row[q + 1] > plan.tinted_same_row[q]);
        in[q] = char(in[q] | receives);
        for (std::uint64_t k = plan.same_row[q]; k < plan.same_row[q + 1]; ++k) in[plan.same_links[k].source] = 1;
        if (!plan.tinted_same.empty())
            for (std::uint64_t k = plan.tinted_same_row[q]; k < plan.tinted_same_row[q + 1]; ++k)
                in[plan.tinted_same[k].source] = 1;
    }
    for (std::size_t q = 0; q < plan.patches; ++q)
        if (in[q]) {
            plan.sweep_row_of[q] = std::int32_t(plan.sweep_rows.size());
            plan.sweep_rows.push_back(std::uint32_t(q));
        }
    auto by_row = [&](std::vector<std::uint64_t>& row, auto& list) {
        if (row.empty()) return;  // no tinted links
        std::vector<std::uint64_t> compact(plan.sweep_rows.size() + 1, 0);
        for (std::size_t r = 0; r < plan.sweep_rows.size(); ++r) {
            const std::size_t q = plan.sweep_rows[r];
            compact[r + 1] = compact[r] + (row[q + 1] - row[q]);
        }
        for (auto& l : list) l.source = std::uint32_t(plan.sweep_row_of[l.source]);
        row = std::move(compact);  // rows keep their links in position order: the lists stay as they are
    };
    by_row(plan.same_row, plan.same_links);
    by_row(plan.tinted_same_row, plan.tinted_same);
}

// The first window's links into SolvePlan::near, out of the segments.
void copy_near_links(SolvePlan& plan) {
    const Links& l = *plan.links;
    const std::size_t S = std::size_t(plan.windows);
    NearLinks& near = plan.near;
    near.row.assign(plan.nodes + 1, 0);
    std::size_t count = 0;
    for (std::size_t i = 0; i < plan.nodes; ++i) count += plan.segments[i * (S + 1) + 1] - plan.segments[i * (S + 1)];
    near.links.reserve(count);
    for (std::size_t i = 0; i < plan.nodes; ++i) {
        std::uint64_t k = plan.segments[i * (S + 1)];
        const std::uint64_t end = plan.segments[i * (S + 1) + 1];
        for (; k < end; ++k) {
            const DelayTaps t = delay_taps_f(l.distance[k], plan.inv_bin_f, plan.delay, l.ff[k]);
            near.links.push_back({std::uint32_t(plan.node_slot(l.source[k])), t.lag, t.w0, t.w1});
        }
        plan.segments[i * (S + 1)] = k;
        near.row[i + 1] = near.links.size();
    }
}

// Every node's ring of C lanes per bin: patches' rings in leaf order (the bin-by-bin passes store them
// in that order), then clusters'.
void plan_rings(SolvePlan& plan) {
    plan.slots.resize(plan.nodes);
    if (plan.packs()) {
        // Packed links find their source's ring from the source alone (SolvePlan::packed_ring): every
        // ring as long as the longest, node k's k rings in. The short rings' unused bins are never read.
        int longest = 0, window = 0;
        for (std::size_t k = 0; k < plan.nodes; ++k) {
            longest = std::max(longest, plan.send_lag[k]);
            window = std::max(window, plan.send_window[k]);
        }
        plan.longest_ring = ring_bins(longest, plan.block_bins);
        const int mirror = ring_mirror_bins(window);
        plan.packed_ring_floats = std::size_t(plan.longest_ring + mirror) * std::size_t(plan.lanes);
        for (std::size_t k = 0; k < plan.nodes; ++k)
            plan.slots[k] = {k * plan.packed_ring_floats, plan.longest_ring - 1, plan.longest_ring, mirror};
        plan.ring_floats = plan.nodes * plan.packed_ring_floats;
    } else
        for (std::size_t at = 0; at < plan.nodes; ++at) {
            const std::size_t k = at < plan.patches ? plan.order[at] : at;
            const int length = ring_bins(plan.send_lag[k], plan.block_bins);
            const int mirror = ring_mirror_bins(plan.send_window[k]);
            plan.slots[k] = {plan.ring_floats, length - 1, length, mirror};
            plan.ring_floats += std::size_t(length + mirror) * std::size_t(plan.lanes);
            plan.longest_ring = std::max(plan.longest_ring, length);
        }
    std::vector<int>().swap(plan.send_lag);
    std::vector<int>().swap(plan.send_window);
}

}  // namespace

namespace {

// The sizes of what a plan of this march is given (MarchInputs).
MarchInputs plan_inputs(const PatchSet& patches, const LinkSet& set, const TimeAxis& time, const SolverOptions& options,
                        int illuminations, int channels) {
    MarchInputs in;
    TPRF_CHECK_EQ(set.surface_patches(), patches.size());
    in.patches = set.patches();
    in.nodes = set.nodes();
    in.links = set.links.size();
    in.clusters = set.tree.clusters() > 0;
    in.cluster_block_bins = set.block_bins;
    // A link's lag grows with its length: the longest link's is the largest.
    float longest = 0.0f;
    for (float d : set.links.distance) longest = std::max(longest, d);
    in.longest_lag = delay_taps_f(longest, time.inv_bin_f(), options.delay, 1.0f).lag;
    in.illuminations = illuminations;
    in.channels = channels;
    return in;
}

}  // namespace

// The plan of a march of `illuminations` illuminations of `channels` channels each, from the window's
// first block (plan_blocks moves the start to the batch's earliest pulse): the shape that march_shape
// decides, then the lists.
SolvePlan make_plan(const PatchSet& patches, const LinkSet& set, const TimeAxis& time, const SolverOptions& options,
                    const PlanFor& what) {
    const int illuminations = what.illuminations, channels = what.channels;
    const bool sizing_only = what.sizing_only;
    const Links& links = set.links;
    const MarchShape shape = march_shape(plan_inputs(patches, set, time, options, illuminations, channels), options);
    SolvePlan plan;
    plan.patches = shape.patches;
    plan.nodes = shape.nodes;
    plan.tree = &set.tree;
    plan.set = &set;
    plan.patches_of = &patches;
    plan.out_begin = set.glossy.empty() ? plan.patches : set.glossy.out_begin();
    plan.clusters = set.tree.clusters() > 0;
    plan.threads = shape.threads;
    if (plan.clusters) cut_subtrees(set.tree, plan);
    plan.source_tile = shape.source_tile;
    plan.block_bins = shape.block_bins;
    plan.illuminations = shape.illuminations;
    plan.channels = shape.channels;
    plan.lanes = shape.lanes;
    plan.delay = options.delay;
    plan.bin_map = time.bin_map();
    plan.inv_bin_f = time.inv_bin_f();
    plan.layers = plan_layers(options.max_bounces, options.bounce_terms);
    plan.layer_count = plan.layers.layers();
    plan.fed_layers = shape.layers.fed;
    plan.emit_blocks = shape.emit_blocks;
    plan.lag_bits = shape.lag_bits;
    plan.accumulator_bins = shape.window_bins;
    plan.windows = shape.windows;
    plan.recent_bins = shape.recent_bins;
    const bool wide = options.wide_vectors && cpu_has_wide_kernels();
    plan_windows(links, plan, wide, !sizing_only);
    split_links(patches, links, plan);
    split_positions(plan);
    // Each glossy patch's in-cells at consecutive positions (the march reads them as one row).
    for (std::size_t g = 0; g < set.glossy.glossy.size(); ++g)
        for (int c = 1; c < set.glossy.cells(); ++c)
            TPRF_CHECK_EQ(plan.position[set.glossy.in_row(g, c)], plan.position[set.glossy.in_row(g, 0)] + std::uint32_t(c));
    plan_sweeps(patches, plan);
    compact_same_bin(plan);
    plan_rings(plan);
    plan.bins = time.bins;
    plan.blocks = (plan.bins + plan.block_bins - 1) / plan.block_bins;
    if (shape.near_list) {
        plan.recent_kernel = recent_kernel_for(plan.lanes, plan.block_bins, wide);
        copy_near_links(plan);
    }
    bool any_kernel = plan.recent_kernel != nullptr || plan.packs();
    for (int s = 0; s < plan.windows && !plan.packs(); ++s) {
        plan.kernel[s] = pick_kernel(plan.lanes, plan.window_bins(s), wide);
        if (!plan.kernel[s]) plan.lane_kernel[s] = lane_kernel_for(plan.window_bins(s), wide);
        any_kernel = any_kernel || plan.kernel[s] || plan.lane_kernel[s];
    }
    // Wide where a wide kernel runs: windows longer than kLongestWindow without a kernel of their own
    // take gather_long_any, which has no wide copy.
    plan.wide = wide && any_kernel;
    return plan;
}

// Light sent before the window opens still travels: the march starts at the batch's earliest pulse,
// aligned to the longest window, so that every window starts at the first block.
void plan_blocks(SolvePlan& plan, std::span<const Illumination* const> batch) {
    std::int64_t first_pulse_bin = std::min<std::int64_t>(0, plan.first_emitted);
    for (const Illumination* illumination : batch)
        for (const Pulse& p : illumination->pulses) first_pulse_bin = std::min(first_pulse_bin, plan.pulse_bin(p));
    const std::int64_t align = plan.accumulator_bins;
    plan.start_bin = (first_pulse_bin >= 0) ? 0 : -((-first_pulse_bin + align - 1) / align) * align;
    plan.blocks = (plan.bins - plan.start_bin + plan.block_bins - 1) / plan.block_bins;
}

namespace {

// The shape the plan was made in (march_shape decided it).
MarchShape shape_of(const SolvePlan& p) {
    MarchShape s;
    s.patches = p.patches;
    s.nodes = p.nodes;
    s.threads = p.threads;
    s.illuminations = p.illuminations;
    s.channels = p.channels;
    s.lanes = p.lanes;
    s.layers = {p.layer_count, p.layers.terms, p.fed_layers};
    s.block_bins = p.block_bins;
    s.emit_blocks = p.emit_blocks;
    s.source_tile = p.source_tile;
    s.lag_bits = p.lag_bits;
    s.windows = p.windows;
    s.window_bins = p.accumulator_bins;
    s.recent_bins = p.recent_bins;
    s.near_list = p.recent_kernel != nullptr;
    s.tile_sum_floats = p.tile_sum_floats();
    return s;
}

// The lengths of the plan's lists and rings.
MarchLists lists_of(const SolvePlan& p) {
    MarchLists l;
    l.ring_bins = p.ring_floats / std::size_t(p.lanes);
    l.short_links = p.short_links.size();
    l.same_bin_links = p.same_links.size();
    l.sweep_rows = p.sweep_rows.size();
    l.chebyshev = p.sweep_buffers() == 3;
    l.sorted = !p.sorted.row.empty();
    l.sorted_links = p.sorted.size();
    l.near_links = p.near.links.size();
    l.packed_links = p.packed_count;
    l.tinted = !p.tinted_long_row.empty();
    l.tinted_long = p.tinted_long.size();
    l.tinted_short = p.tinted_short.size();
    l.tinted_same = p.tinted_same.size();
    return l;
}

}  // namespace

// Bytes of the ring buffers, block buffers and lists of a march on this plan.
std::size_t working_bytes(const SolvePlan& p) { return march_working_bytes(shape_of(p), lists_of(p)); }

bool pulses_grey(std::span<const Illumination* const> batch) {
    for (const Illumination* illumination : batch)
        for (const Pulse& p : illumination->pulses)
            if (!is_grey(p.energy)) return false;
    return true;
}

}  // namespace tprf::solver_detail

namespace tprf {

MarchLayers march_layers(const SolverOptions& options) {
    const solver_detail::LayerPlan plan = solver_detail::plan_layers(options.max_bounces, options.bounce_terms);
    return {plan.layers(), plan.terms, solver_detail::fed_layers(plan)};
}

bool keeps_grey(const PatchSet& patches, const Links& links) {
    for (const Rgb& a : patches.albedo)
        if (!is_grey(a)) return false;
    for (std::uint16_t t : links.tint)
        if (!(links.tints[t][0] == links.tints[t][1] && links.tints[t][1] == links.tints[t][2])) return false;
    return true;
}

bool keeps_grey(const GlossyRows& rows) {
    return std::all_of(rows.albedo.begin(), rows.albedo.end(), [](const Rgb& a) { return is_grey(a); });
}

bool scene_keeps_grey(const Scene& scene) {
    for (const Object& o : scene.objects)
        if (!is_grey(o.albedo) || !is_grey(o.emission) || !is_grey(o.material.reflectance)) return false;
    for (const Light& l : scene.lights) {
        if (const auto* p = std::get_if<PointLight>(&l); p && !is_grey(p->intensity)) return false;
        if (const auto* p = std::get_if<Laser>(&l); p && !is_grey(p->power)) return false;
    }
    return !scene.capture || is_grey(scene.capture->laser_power);
}

MarchShape march_shape(const MarchInputs& in, const SolverOptions& options) {
    using namespace solver_detail;
    MarchShape s;
    s.patches = in.patches;
    s.nodes = in.nodes;
    s.threads = thread_count(options.threads);
    s.illuminations = in.illuminations;
    s.channels = in.channels;
    s.lanes = in.illuminations * in.channels;
    s.layers = march_layers(options);
    // Sources in tiles where the rows are dense.
    s.source_tile = in.links < kDenseRow * in.nodes ? std::max<std::size_t>(in.nodes, 1) : kSourceTile;
    s.block_bins = march_block_bins(options, in.clusters ? in.cluster_block_bins : 0);
    // Short blocks reach the sink together (kSinkBins): each hand-over passes over every patch (the
    // spots, the sink's own copy); for the statue's 57k patches in blocks of two bins the output's work
    // fell from 4.0% to 2.7% of the render's CPU.
    const std::size_t out_per_bin =
        (1 + std::size_t(s.layers.terms)) * s.patches * std::size_t(s.illuminations) * 3 * sizeof(float);
    while (s.block_bins * s.emit_blocks * 2 <= kSinkBins &&
           out_per_bin * std::size_t(s.block_bins * s.emit_blocks * 2) <= kSinkBytes)
        s.emit_blocks *= 2;
    const bool wide = options.wide_vectors && cpu_has_wide_kernels();
    s.lag_bits = packed_lag_bits(in, s, wide);
    s.window_bins = std::max(s.block_bins, s.lag_bits > 0 ? kDenseLongestWindow : kLongestWindow);
    s.windows = 1 + std::countr_zero(unsigned(s.window_bins / s.block_bins));
    TPRF_CHECK_LE(s.windows, kMaxWindows);
    s.recent_bins = int(std::bit_ceil(unsigned(s.block_bins + 1)));
    // The recent bins hold the last 2 bt bins before a block (bit_ceil(bt + 1) = 2 bt), all that the
    // shortest window's links read. Packed links have kernels for every window, the shortest's included
    // (which reads the rings).
    s.near_list = s.lag_bits == 0 && s.windows > 1 && s.recent_bins >= 2 * s.block_bins &&
                  recent_kernel_for(s.lanes, s.block_bins, wide) != nullptr;
    s.tile_sum_floats = receiver_tile_floats(s.source_tile, s.nodes, s.window_bins, s.lanes);
    return s;
}

std::size_t march_working_bytes(const MarchShape& s, const MarchLists& l) {
    using namespace solver_detail;
    const std::size_t L = std::size_t(s.layers.layers), C = std::size_t(s.lanes), bt = std::size_t(s.block_bins);
    const std::size_t n = s.patches, m = s.nodes;
    const bool same_bin = l.same_bin_links > 0 || l.tinted_same > 0;
    // Per row of the same-bin system: the iterates and the last two bins' shares.
    const std::size_t sweeps = same_bin ? std::size_t(l.chebyshev ? 5 : 4) * L * l.sweep_rows * C : 0;
    const std::size_t emit_bins = bt * std::size_t(s.emit_blocks);
    const std::size_t floats = L * l.ring_bins * C + L * n * bt * C + L * m * std::size_t(s.window_bins) * C +
                               L * std::size_t(s.recent_bins) * m * C + L * n * C + sweeps +
                               (s.emit_blocks > 1 ? 2 : 1) * (1 + std::size_t(s.layers.terms)) * n * emit_bins *
                                   std::size_t(s.illuminations) * 3 +
                               std::size_t(s.threads) * s.tile_sum_floats;
    // Rows: the bin-by-bin links' by position; the same-bin links' by row of their system (or by
    // position without one); the tinted lists' likewise.
    const std::size_t same_rows = same_bin ? l.sweep_rows + 1 : n + 1;
    const std::size_t rows = (n + 1) + same_rows + (l.tinted ? 2 * (n + 1) + same_rows : 0) +
                             m * std::size_t(s.windows + 1) + (l.sorted ? m + 1 : 0) + (s.near_list ? m + 1 : 0);
    const std::size_t grey_link = sizeof(std::uint32_t) + 2 * sizeof(float);  // Links: source, ff, distance
    return floats * sizeof(float) + rows * sizeof(std::uint64_t) + (l.short_links + l.near_links) * sizeof(TapLink) +
           l.same_bin_links * sizeof(SameBinLink) + l.sweep_rows * sizeof(std::uint32_t) + n * sizeof(std::int32_t) +
           m * sizeof(RingSlot) + l.sorted_links * grey_link + l.packed_links * sizeof(PackedLink) +
           n * C * sizeof(float) + (l.tinted_long + l.tinted_short) * sizeof(TintedLink) +
           l.tinted_same * sizeof(TintedSameLink);
}

MarchSizing solve_sizing(const PatchSet& patches, const LinkSet& set, const TimeAxis& time,
                         const SolverOptions& options, int illuminations, int channels) {
    using namespace solver_detail;
    TPRF_CHECK_LE(1, illuminations);
    TPRF_CHECK_LE(illuminations, kMaxBatch);
    TPRF_CHECK(channels == 1 || channels == 3);
    check_tints(set.links);
    MarchSizing out;
    out.inputs = plan_inputs(patches, set, time, options, illuminations, channels);
    const SolvePlan plan = make_plan(patches, set, time, options, {illuminations, channels, true});
    out.shape = shape_of(plan);
    out.lists = lists_of(plan);
    out.working_bytes = march_working_bytes(out.shape, out.lists);
    return out;
}

int march_block_bins(const SolverOptions& options, int cluster_block_bins) {
    int bt = int(std::bit_ceil(unsigned(std::clamp(options.block_bins, 1, 4096))));
    // Blocks no longer than the shortest cluster link, so that no cluster link has to be expanded.
    if (cluster_block_bins > 0)
        while (bt > 1 && bt > cluster_block_bins) bt /= 2;
    return bt;
}

int ring_bins(int lag, int block_bins) { return int(std::bit_ceil(unsigned(lag + block_bins + 2))); }

int ring_mirror_bins(int window_bins) { return window_bins > 0 ? window_bins + 1 : 0; }

}  // namespace tprf
