#include "tprf/imaging/gather.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/neighbours.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/light_sources.h"


#include <algorithm>
#include <cmath>
#include <tuple>

namespace tprf {
namespace {

// Patches whose centroids lie near each point: one search wide enough for the largest kernel; each
// point's own support (twice its patch's circumradius) is applied by kernel_weights.
Neighbours find_neighbours(const SensingPoints& points, const PatchSet& patches, const std::vector<double>& radius,
                           int threads) {
    double support = 0.0;
    std::vector<Vec3> queries(points.points.size());
    for (std::size_t h = 0; h < queries.size(); ++h) {
        queries[h] = points.points[h].point;
        support = std::max(support, 2.0 * radius[points.points[h].patch]);
    }
    return radius_search(patches.centroid, queries, support, threads);
}

// Interpolation weights at a point on patch p: a smooth compact kernel (1 - (d/support)^2)^2 over the
// patches of the same surface, so that the profile varies continuously across patch borders and no
// faceting shows. Normalised; the patch alone when no neighbour is inside the support.
std::vector<std::pair<std::uint32_t, double>> kernel_weights(const PatchSet& patches, std::uint32_t p, double radius,
                                                             const std::vector<std::size_t>& near,
                                                             const std::vector<double>& near_d2) {
    const double support = 2.0 * radius;
    const Vec3& np = patches.normal[p];
    std::vector<std::pair<std::uint32_t, double>> weights;
    double total = 0.0;
    for (std::size_t k = 0; k < near.size(); ++k) {
        const std::size_t q = near[k];
        if (patches.object[q] != patches.object[p] || patches.normal[q].dot(np) < 0.7) continue;
        const double u = near_d2[k] / (support * support);
        if (u >= 1.0) continue;
        const double w = (1 - u) * (1 - u);
        weights.emplace_back(std::uint32_t(q), w);
        total += w;
    }
    if (total <= 0.0) return {{p, 1.0}};
    for (auto& w : weights) w.second /= total;
    return weights;
}

// Direct light of area source a at the sensing point, seen along its leg: radiance albedo L_e F(x)
// with F the exact point-to-polygon form factor, times the unblocked share of its sampled pairs,
// spread over their paths (merged per bin of the time axis, when there is one).
void area_arrivals(const SensingPoint& sp, double weight, const PatchSet& patches, const AreaSource& a,
                   const Visibility& vis, const GatherOptions& options, std::vector<DirectArrival>& out) {
    const Vec3& n = patches.normal[sp.patch];
    const double ff = point_polygon_form_factor(sp.point, n, a.polygon(), a.count, a.normal);
    if (!(ff > 0.0)) return;
    const double bin_m = options.time ? options.time->bin_width_m() : 0.0;
    thread_local std::vector<AreaPair> pairs;
    pairs.clear();
    const double origin = options.time ? options.time->start_m() - sp.leg : 0.0;  // bin edges, as merged below
    double total = arrive_area(a, sp.point, n, vis,
                               area_sampling(a, sp.point, bin_m, origin, options.emitter_rays, options.penumbra_rays),
                               pairs);
    if (!(total > 0.0) && (total = arrive_area_centroid(a, sp.point, n, vis, pairs)) == 0.0) return;
    const Rgb radiance = patches.albedo[sp.patch] * a.radiance * (ff * weight / total);
    if (options.time) pairs = merge_pairs_by_bin(pairs, bin_m, options.time->start_m() - sp.leg);
    for (const AreaPair& q : pairs) out.push_back({sp.output, q.path + sp.leg, radiance * q.weight, 1});
}

// Exact direct light of every point and area source at the sensing point, seen along its leg.
void direct_arrivals(const SensingPoint& sp, double weight, const PatchSet& patches, const LightSources& sources,
                     const Visibility& vis, const GatherOptions& options, std::vector<DirectArrival>& out) {
    const Rgb& albedo = patches.albedo[sp.patch];
    for (const PointSource& source : sources.points) {
        if (source.patch == sp.patch) continue;
        PointArrival a;
        if (!arrive(source, sp.point, patches.normal[sp.patch], vis, a)) continue;
        out.push_back({sp.output, a.path + sp.leg, a.reflected(albedo) * (weight / M_PI), source.order});
    }
    for (const AreaSource& a : sources.areas) area_arrivals(sp, weight, patches, a, vis, options, out);
}

// One output's arrivals in path order; with a time axis, those that share a bin and an order are summed
// (in path order) into the earliest of them: exact for the film, which places each arrival by its bin.
void order_arrivals(std::vector<DirectArrival>& v, const TimeAxis* time) {
    const auto by_path = [](const DirectArrival& a, const DirectArrival& b) {
        return a.path != b.path ? a.path < b.path : a.radiance[0] < b.radiance[0];
    };
    if (!time) {
        std::sort(v.begin(), v.end(), by_path);
        return;
    }
    const double inv_bin = 1.0 / time->bin_width_m(), start = time->start_m();
    const auto key = [&](const DirectArrival& a) { return std::pair(std::floor((a.path - start) * inv_bin), a.order); };
    std::sort(v.begin(), v.end(),
              [&](const DirectArrival& a, const DirectArrival& b) { return key(a) != key(b) ? key(a) < key(b) : by_path(a, b); });
    std::size_t kept = 0;
    for (std::size_t k = 0; k < v.size(); ++k) {
        if (kept > 0 && key(v[kept - 1]) == key(v[k]))
            v[kept - 1].radiance += v[k].radiance;
        else
            v[kept++] = v[k];
    }
    v.resize(kept);
}

// The outputs' lists as one CSR: run k holds the points of output outputs[k] (in output order), and its
// taps and arrivals, each in order; each run's lists are freed once taken.
Gather assemble(std::size_t count, int width, int height, const std::vector<std::uint32_t>& outputs,
                std::vector<std::vector<PixelTap>>& taps, std::vector<std::vector<DirectArrival>>& direct) {
    Gather g;
    g.width = width;
    g.height = height;
    g.row.assign(count + 1, 0);
    for (std::size_t k = 0; k < outputs.size(); ++k) g.row[outputs[k] + 1] = taps[k].size();
    for (std::size_t o = 0; o < count; ++o) g.row[o + 1] += g.row[o];
    g.taps.reserve(g.row[count]);
    std::size_t arrivals = 0;
    for (const auto& d : direct) arrivals += d.size();
    g.direct.reserve(arrivals);
    for (std::size_t k = 0; k < outputs.size(); ++k) {
        g.taps.insert(g.taps.end(), taps[k].begin(), taps[k].end());
        g.direct.insert(g.direct.end(), direct[k].begin(), direct[k].end());
        std::vector<PixelTap>().swap(taps[k]);
        std::vector<DirectArrival>().swap(direct[k]);
    }
    return g;
}

}  // namespace

std::uint16_t SensingPoints::tint_index(const Rgb& tint) {
    if ((tint == 1.0).all()) return 0;
    if (tints.empty()) tints.push_back(Rgb::Ones());
    for (std::size_t k = 1; k < tints.size(); ++k)
        if ((tints[k] == tint).all()) return std::uint16_t(k);
    if (tints.size() > 0xffff) throw Error("more than 65535 tints of mirror chains in the camera's view");
    tints.push_back(tint);
    return std::uint16_t(tints.size() - 1);
}

Gather gather_points(const SensingPoints& points, int width, int height, const PatchSet& patches,
                     const LightSources& sources, const Visibility& vis, const GatherOptions& options) {
    TPRF_CHECK_EQ(points.outputs, std::size_t(width) * std::size_t(height));
    for (std::size_t h = 0; h < points.points.size(); ++h) {
        const SensingPoint& sp = points.points[h];
        TPRF_CHECK_LT(std::size_t(sp.output), points.outputs);
        TPRF_CHECK_LT(std::size_t(sp.patch), patches.size());
        if (h > 0) TPRF_CHECK_LE(points.points[h - 1].output, sp.output);  // in output order
    }
    const std::size_t n = patches.size();
    std::vector<double> radius(n);
    for (std::size_t i = 0; i < n; ++i) radius[i] = circumradius(patches, i);
    const Neighbours near = find_neighbours(points, patches, radius, options.threads);
    if (options.progress) options.progress("camera", 0.6);

    // Runs of points with one output (a pixel's samples), gathered together so that their arrivals are
    // sorted by path and, with a time axis, merged per bin before the next run's are made.
    const std::vector<SensingPoint>& pts = points.points;
    std::vector<std::size_t> run_start;
    std::vector<std::uint32_t> run_output;
    for (std::size_t h = 0; h < pts.size(); ++h)
        if (h == 0 || pts[h].output != pts[h - 1].output) {
            run_start.push_back(h);
            run_output.push_back(pts[h].output);
        }
    run_start.push_back(pts.size());
    const std::size_t runs = run_output.size();
    std::vector<std::vector<PixelTap>> run_taps(runs);
    std::vector<std::vector<DirectArrival>> run_direct(runs);
    const double weight = points.weight;
    parallel_for(runs, {options.threads, 64, true}, [&](std::size_t k) {
        std::vector<DirectArrival>& direct = run_direct[k];
        for (std::size_t h = run_start[k]; h < run_start[k + 1]; ++h) {
            const SensingPoint& sp = pts[h];
            const float earliest = float(earliest_path(sources, sp.point)) + sp.leg;
            const double share = weight * double(sp.throughput);
            for (const auto& [q, w] : kernel_weights(patches, sp.patch, radius[sp.patch], near.index[h], near.distance2[h]))
                run_taps[k].push_back({q, float(w * share / M_PI), sp.leg, earliest, sp.tint});
            const std::size_t first = direct.size();
            direct_arrivals(sp, share, patches, sources, vis, options, direct);
            if (sp.tint != 0)
                for (std::size_t a = first; a < direct.size(); ++a) direct[a].radiance *= points.tint_of(sp);
        }
        std::sort(run_taps[k].begin(), run_taps[k].end(), [](const PixelTap& a, const PixelTap& b) {
            return std::tie(a.patch, a.leg, a.tint, a.weight) < std::tie(b.patch, b.leg, b.tint, b.weight);
        });
        order_arrivals(direct, options.time);
        direct.shrink_to_fit();
    });
    Gather g = assemble(points.outputs, width, height, run_output, run_taps, run_direct);
    g.tints = points.tints;
    if (options.progress) options.progress("camera", 1.0);
    return g;
}

}  // namespace tprf
