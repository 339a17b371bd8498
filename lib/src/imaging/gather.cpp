#include "tprf/imaging/gather.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/neighbours.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/light_sources.h"


#include <algorithm>
#include <cmath>

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

// Exact direct light of every point source at the sensing point, seen along its leg.
void direct_arrivals(const SensingPoint& sp, double weight, const PatchSet& patches, const LightSources& sources,
                     const Visibility& vis, std::vector<DirectArrival>& out) {
    const Rgb& albedo = patches.albedo[sp.patch];
    for (const PointSource& source : sources.points) {
        if (source.patch == sp.patch) continue;
        PointArrival a;
        if (!arrive(source, sp.point, patches.normal[sp.patch], vis, a)) continue;
        out.push_back({sp.output, a.path + sp.leg, a.reflected(albedo) * (weight / M_PI), source.order});
    }
}

// Sorts each run of consecutive elements of one output by `less`.
template <class T, class Output, class Less>
void sort_runs(std::vector<T>& v, Output output, Less less) {
    for (std::size_t a = 0; a < v.size();) {
        std::size_t b = a + 1;
        while (b < v.size() && output(v[b]) == output(v[a])) ++b;
        std::sort(v.begin() + std::ptrdiff_t(a), v.begin() + std::ptrdiff_t(b), less);
        a = b;
    }
}

// The points' lists as one CSR by output: the points come in output order, so their lists laid end to
// end give every output's taps and arrivals in one run.
Gather assemble(const SensingPoints& points, int width, int height, const std::vector<std::vector<PixelTap>>& taps,
                const std::vector<std::vector<DirectArrival>>& direct) {
    Gather g;
    g.width = width;
    g.height = height;
    g.row.assign(points.outputs + 1, 0);
    for (std::size_t h = 0; h < taps.size(); ++h) g.row[points.points[h].output + 1] += taps[h].size();
    for (std::size_t o = 0; o < points.outputs; ++o) g.row[o + 1] += g.row[o];
    g.taps.reserve(g.row[points.outputs]);
    for (std::size_t h = 0; h < taps.size(); ++h) {
        g.taps.insert(g.taps.end(), taps[h].begin(), taps[h].end());
        g.direct.insert(g.direct.end(), direct[h].begin(), direct[h].end());
    }
    for (std::size_t o = 0; o < points.outputs; ++o)
        std::sort(g.taps.begin() + std::ptrdiff_t(g.row[o]), g.taps.begin() + std::ptrdiff_t(g.row[o + 1]),
                  [](const PixelTap& a, const PixelTap& b) {
                      return a.patch != b.patch ? a.patch < b.patch : a.leg != b.leg ? a.leg < b.leg : a.weight < b.weight;
                  });
    sort_runs(g.direct, [](const DirectArrival& d) { return d.pixel; }, [](const DirectArrival& a, const DirectArrival& b) {
        return a.path != b.path ? a.path < b.path : a.radiance[0] < b.radiance[0];
    });
    return g;
}

}  // namespace

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

    const std::vector<SensingPoint>& pts = points.points;
    std::vector<std::vector<PixelTap>> per_point_taps(pts.size());
    std::vector<std::vector<DirectArrival>> per_point_direct(pts.size());
    const double weight = points.weight;
    parallel_for(pts.size(), {options.threads, 256, true}, [&](std::size_t h) {
        const SensingPoint& sp = pts[h];
        const float earliest = float(earliest_path(sources, sp.point)) + sp.leg;
        for (const auto& [q, w] : kernel_weights(patches, sp.patch, radius[sp.patch], near.index[h], near.distance2[h]))
            per_point_taps[h].push_back({q, float(w * weight / M_PI), sp.leg, earliest});
        direct_arrivals(sp, weight, patches, sources, vis, per_point_direct[h]);
    });
    Gather g = assemble(points, width, height, per_point_taps, per_point_direct);
    if (options.progress) options.progress("camera", 1.0);
    return g;
}

}  // namespace tprf
