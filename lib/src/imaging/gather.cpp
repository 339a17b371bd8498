#include "tprf/imaging/gather.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/core/random.h"
#include "tprf/core/time_kernel.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/neighbours.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/light_sources.h"


#include <algorithm>
#include <cmath>
#include <limits>

namespace tprf {
namespace {

// Interpolation candidates of every patch that holds a sensing point: the patches of the same surface
// (one object, normals within about 45 degrees) whose centroids lie within three of its circumradii.
// A point on patch p lies within one circumradius of its centroid and its kernel reaches two more
// (kernel_weights), so the candidates hold every patch a point's kernel can weigh. One search per
// patch, not per point.
struct Candidates {
    std::vector<std::uint32_t> row;  // patches + 1 offsets into `patch`
    std::vector<std::uint32_t> patch;
};

Candidates find_candidates(const SensingPoints& points, const PatchSet& patches, const std::vector<double>& radius,
                           int threads) {
    std::vector<char> used(patches.size(), 0);
    for (const SensingPoint& sp : points.points) used[sp.patch] = 1;
    std::vector<std::uint32_t> which;
    std::vector<Vec3> queries;
    double reach = 0.0;
    for (std::size_t p = 0; p < patches.size(); ++p)
        if (used[p]) {
            which.push_back(std::uint32_t(p));
            queries.push_back(patches.centroid[p]);
            reach = std::max(reach, 3.0 * radius[p]);
        }
    const Neighbours near = radius_search(patches.centroid, queries, reach, threads);
    std::vector<std::vector<std::uint32_t>> lists(patches.size());
    for (std::size_t k = 0; k < which.size(); ++k) {
        const std::uint32_t p = which[k];
        const double r2 = 9.0 * radius[p] * radius[p];
        for (std::size_t h = 0; h < near.index[k].size(); ++h) {
            const std::size_t q = near.index[k][h];
            if (near.distance2[k][h] < r2 && patches.object[q] == patches.object[p] &&
                patches.normal[q].dot(patches.normal[p]) >= 0.7)
                lists[p].push_back(std::uint32_t(q));
        }
        std::sort(lists[p].begin(), lists[p].end());  // FLANN's order is its own
    }
    Candidates c;
    c.row.assign(patches.size() + 1, 0);
    for (std::size_t p = 0; p < patches.size(); ++p) c.row[p + 1] = c.row[p] + std::uint32_t(lists[p].size());
    c.patch.reserve(c.row.back());
    for (const auto& l : lists) c.patch.insert(c.patch.end(), l.begin(), l.end());
    return c;
}

// Interpolation weights at point x on patch p: a smooth compact kernel (1 - (d/support)^2)^2, support
// two circumradii of p, over p's candidates, so that the profile varies continuously across patch
// borders and no faceting shows. Normalised; the patch alone when no candidate is inside the support.
void kernel_weights(const PatchSet& patches, std::uint32_t p, const Vec3& x, double radius, const Candidates& c,
                    std::vector<std::pair<std::uint32_t, double>>& weights) {
    const double support2 = 4.0 * radius * radius;
    weights.clear();
    double total = 0.0;
    for (std::uint32_t k = c.row[p]; k < c.row[p + 1]; ++k) {
        const std::uint32_t q = c.patch[k];
        const double u = (patches.centroid[q] - x).squaredNorm() / support2;
        if (u >= 1.0) continue;
        const double w = (1 - u) * (1 - u);
        weights.emplace_back(q, w);
        total += w;
    }
    if (total <= 0.0) {
        weights.assign(1, {p, 1.0});
        return;
    }
    for (auto& w : weights) w.second /= total;
}

// The sensing point's cell (zero for a point).
Footprint footprint_of(const SensingPoint& sp) {
    return {sp.du.cast<double>(), sp.dv.cast<double>(), sp.leg, sp.leg_du, sp.leg_dv};
}

// One of a pixel's `count` samples (a run of sensing points), the index-th.
struct RunSample {
    std::size_t index = 0, count = 1;
};

// Direct light of area source a at the sensing point, seen along its leg: radiance albedo L_e F(x)
// with F the exact point-to-polygon form factor, times the unblocked share of its sampled pairs,
// spread over their paths and over the point's cell (per bin of the time axis, when there is one).
void area_arrivals(const SensingPoint& sp, RunSample at, double weight, const PatchSet& patches, const AreaSource& a,
                   const Visibility& vis, const GatherOptions& options, std::vector<DirectArrival>& out) {
    const Vec3& n = patches.normal[sp.patch];
    const double ff = point_polygon_form_factor(sp.point, n, a.polygon(), a.count, a.normal);
    if (!(ff > 0.0)) return;
    const double bin_m = options.time ? options.time->bin_width_m() : 0.0;
    thread_local std::vector<AreaPair> pairs;
    pairs.clear();
    const double origin = options.time ? options.time->start_m() - sp.leg : 0.0;  // bin edges, as merged below
    // The pixel's samples share its penumbra rays, each at its own offsets in the cells (R2 sequence).
    const int penumbra = std::max(options.emitter_rays, int(double(options.penumbra_rays) / double(at.count)));
    AreaSampling sampling = area_sampling(a, sp.point, bin_m, origin, options.emitter_rays, penumbra);
    if (at.count > 1) r2_point(double(at.index), sampling.jitter_u, sampling.jitter_v);
    sampling.footprint = footprint_of(sp);
    double total = arrive_area(a, sp.point, n, vis, sampling, pairs);
    if (!(total > 0.0) && (total = arrive_area_centroid(a, sp.point, n, vis, pairs)) == 0.0) return;
    const Rgb radiance = patches.albedo[sp.patch] * a.radiance * (ff * weight / total);
    for (const AreaPair& q : pairs) out.push_back({sp.output, q.path + sp.leg, radiance * q.weight, 1});
}

// Light arriving at `path` from a sensing point, spread over the paths of the point's cell (its path
// changes by +- a and +- b along its half-axes, never before `lowest`) and cut at the bins of the time
// axis: one arrival per bin it touches. Without a time axis, one arrival.
void add_over_cell(std::uint32_t output, double path, double a, double b, double lowest, const Rgb& radiance,
                   std::uint8_t order, const TimeAxis* time, std::vector<DirectArrival>& out) {
    if (!time) {
        out.push_back({output, path, radiance, order});
        return;
    }
    spread_over_bins(path, a, b, time->bin_width_m(), time->start_m(), lowest,
                     [&](double at, double share) { out.push_back({output, at, radiance * share, order}); });
}

// A pixel's samples, when they can share the timing of an area source's light: all of them (spp points,
// each its own sample, with its cell), in the open (no mirror or glass on the way) and on one flat
// surface (one object, one plane).
bool one_flat_pixel(const SensingPoint* pts, std::size_t count, double weight, const PatchSet& patches) {
    if (count < 2 || double(count) != std::round(1.0 / weight)) return false;
    if (pts[0].du.isZero() && pts[0].dv.isZero()) return false;  // point samples: each at its own paths
    const Vec3& n = patches.normal[pts[0].patch];
    const double reach = 1e-6 * (1.0 + pts[0].point.norm());
    for (std::size_t h = 0; h < count; ++h) {
        const SensingPoint& sp = pts[h];
        if (sp.throughput != 1.0f || sp.tint != 0 || patches.object[sp.patch] != patches.object[pts[0].patch] ||
            patches.normal[sp.patch].dot(n) < 1.0 - 1e-12 || std::abs(n.dot(sp.point - pts[0].point)) > reach)
            return false;
        if (h > 0 && sp.output != pts[0].output) return false;
    }
    return true;
}

// Direct light of area source a at a pixel's samples that one_flat_pixel admits, when the shared shadow
// test finds the source wholly open or wholly hidden: from the pixel's four outermost samples (along its
// two axes), a ray to the centre of each cell of the coarse shadow grid that faces it. Open: each
// sample's radiance is albedo L_e F(x) with its own exact F, and the light of all of them is timed
// together, as the pixel's centre sees the source's cells, spread over the paths of the whole pixel
// (its samples' cells side by side: sqrt(spp) times a sample's half-axes). Hidden: no light. False
// (nothing added) when the rays disagree or glass dims one: the samples are then gathered one by one.
bool area_pixel_arrivals(const SensingPoint* pts, std::size_t count, double weight, const PatchSet& patches,
                         const AreaSource& a, const Visibility& vis, const GatherOptions& options,
                         std::vector<DirectArrival>& out) {
    Vec3 centre = Vec3::Zero(), du = Vec3::Zero(), dv = Vec3::Zero();
    double leg = 0.0, leg_du = 0.0, leg_dv = 0.0;
    for (std::size_t h = 0; h < count; ++h) {
        centre += pts[h].point;
        leg += pts[h].leg;
        du += pts[h].du.cast<double>();
        dv += pts[h].dv.cast<double>();
        leg_du += pts[h].leg_du;
        leg_dv += pts[h].leg_dv;
    }
    const double mean = 1.0 / double(count), side = std::sqrt(double(count));
    centre *= mean;
    leg *= mean;
    // The four samples farthest out along +-u +-v.
    const Vec3 u = du.normalized(), v = dv.normalized();
    std::size_t outer[4] = {0, 0, 0, 0};
    double best[4] = {-1e300, -1e300, -1e300, -1e300};
    for (std::size_t h = 0; h < count; ++h) {
        const Vec3 r = pts[h].point - centre;
        const double x = r.dot(u), y = r.dot(v);
        const double score[4] = {x + y, x - y, -x + y, -x - y};
        for (int k = 0; k < 4; ++k)
            if (score[k] > best[k]) {
                best[k] = score[k];
                outer[k] = h;
            }
    }
    const Vec3& n = patches.normal[pts[0].patch];
    const AreaSampling probe = area_sampling(a, centre, 0.0, 0.0, options.emitter_rays, options.penumbra_rays);
    const int g = probe.shadow;
    const double lift = vis.epsilon();
    bool open = false, blocked = false;
    for (const std::size_t h : outer) {
        const Vec3& x = pts[h].point;
        for (int c = 0; c < g * g; ++c) {
            const Vec3 y = a.point((c % g + 0.5) / g, (c / g + 0.5) / g);
            if (!(n.dot(y - x) > 0.0) || !(a.normal.dot(x - y) > 0.0)) continue;
            const double passed = vis.passes(a.chain, x + lift * n, y + lift * a.normal);
            if (passed != 1.0 && passed != 0.0) return false;  // dimmed by glass: each sample alone
            (passed == 1.0 ? open : blocked) = true;
            if (open && blocked) return false;  // a penumbra
        }
    }
    if (blocked) return true;  // wholly in its shadow
    Rgb radiance = Rgb::Zero();
    for (std::size_t h = 0; h < count; ++h) {
        const double ff = point_polygon_form_factor(pts[h].point, n, a.polygon(), a.count, a.normal);
        if (ff > 0.0) radiance += patches.albedo[pts[h].patch] * (ff * weight);
    }
    if (!(radiance > 0.0).any()) return true;
    thread_local std::vector<AreaPair> pairs;
    pairs.clear();
    const double bin_m = options.time->bin_width_m();
    AreaSampling sampling = area_sampling(a, centre, bin_m, options.time->start_m() - leg, 0, 0);
    sampling.footprint = {side * mean * du, side * mean * dv, leg, side * mean * leg_du, side * mean * leg_dv};
    double total = arrive_area_open(a, centre, n, sampling, pairs);  // the rays above found it open
    if (!(total > 0.0)) {
        pairs.push_back({(centre - a.centroid).norm(), 1.0});
        total = 1.0;
    }
    radiance *= a.radiance / total;
    for (const AreaPair& q : pairs) out.push_back({pts[0].output, q.path + leg, radiance * q.weight, 1});
    return true;
}

// Exact direct light of every point and area source at the sensing point, seen along its leg; a point
// source's light is spread over the paths of the point's cell.
void direct_arrivals(const SensingPoint& sp, RunSample at, double weight, const PatchSet& patches, const LightSources& sources,
                     const Visibility& vis, const GatherOptions& options, const std::vector<char>& pixel_done,
                     std::vector<DirectArrival>& out) {
    const Rgb& albedo = patches.albedo[sp.patch];
    const Footprint f = footprint_of(sp);
    for (const PointSource& source : sources.points) {
        if (source.patch == sp.patch) continue;
        PointArrival a;
        if (!arrive(source, sp.point, patches.normal[sp.patch], vis, a)) continue;
        const Vec3 away = (sp.point - source.position).normalized();  // |x - source| changes along it
        const double lowest = f.empty() ? a.path : source.path + f.least_at_corners([&](const Vec3& offset) {
            return (sp.point + offset - source.position).norm();
        });
        add_over_cell(sp.output, a.path + sp.leg, away.dot(f.du) + f.leg_du, away.dot(f.dv) + f.leg_dv, lowest + sp.leg,
                      a.reflected(albedo) * (weight / M_PI), source.order, options.time, out);
    }
    for (std::size_t k = 0; k < sources.areas.size(); ++k)
        if (!pixel_done[k]) area_arrivals(sp, at, weight, patches, sources.areas[k], vis, options, out);
}

// One output's arrivals in path order; with a time axis, those that share a bin and an order are summed
// into the first of them: exact for the film, which places each arrival by its bin. Arrivals before the
// window share one bin per order, as do those after it (the steady image counts them all).
void order_arrivals(std::vector<DirectArrival>& v, const TimeAxis* time) {
    if (!time) {
        std::sort(v.begin(), v.end(), [](const DirectArrival& a, const DirectArrival& b) {
            return a.path != b.path ? a.path < b.path : a.radiance[0] < b.radiance[0];
        });
        return;
    }
    if (v.empty()) return;
    const double inv_bin = 1.0 / time->bin_width_m(), start = time->start_m(), bins = double(time->bins);
    const auto bin = [&](const DirectArrival& a) {
        return std::int64_t(std::clamp(std::floor((a.path - start) * inv_bin), -1.0, bins));
    };
    std::int64_t lo = bin(v[0]), hi = lo;
    int orders = 0;
    for (const DirectArrival& a : v) {
        lo = std::min(lo, bin(a));
        hi = std::max(hi, bin(a));
        orders = std::max(orders, int(a.order) + 1);
    }
    // Dense sums over the bins the arrivals touch, one per (bin, order); an empty one has a NaN path.
    thread_local std::vector<DirectArrival> sums;
    sums.assign(std::size_t(hi - lo + 1) * std::size_t(orders), {0, std::numeric_limits<double>::quiet_NaN(), Rgb::Zero(), 0});
    for (const DirectArrival& a : v) {
        DirectArrival& s = sums[std::size_t(bin(a) - lo) * std::size_t(orders) + a.order];
        if (std::isnan(s.path)) {
            s = a;
        } else {
            s.radiance += a.radiance;
        }
    }
    v.clear();
    for (const DirectArrival& s : sums)
        if (!std::isnan(s.path)) v.push_back(s);
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
    const Candidates candidates = find_candidates(points, patches, radius, options.threads);
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
        // Area sources whose light this pixel's samples share (area_pixel_arrivals); the others per sample.
        thread_local std::vector<char> pixel_done;
        pixel_done.assign(sources.areas.size(), 0);
        const std::size_t count = run_start[k + 1] - run_start[k];
        if (options.time && !sources.areas.empty() && one_flat_pixel(&pts[run_start[k]], count, weight, patches))
            for (std::size_t a = 0; a < sources.areas.size(); ++a)
                pixel_done[a] = area_pixel_arrivals(&pts[run_start[k]], count, weight, patches, sources.areas[a], vis,
                                                    options, direct);
        for (std::size_t h = run_start[k]; h < run_start[k + 1]; ++h) {
            const SensingPoint& sp = pts[h];
            const float earliest = float(earliest_path(sources, sp.point)) + sp.leg;
            const double share = weight * double(sp.throughput);
            thread_local std::vector<std::pair<std::uint32_t, double>> weights;
            kernel_weights(patches, sp.patch, sp.point, radius[sp.patch], candidates, weights);
            for (const auto& [q, w] : weights) run_taps[k].push_back({q, float(w * share / M_PI), sp.leg, earliest, sp.tint});
            const std::size_t first = direct.size();
            direct_arrivals(sp, {h - run_start[k], count}, share, patches, sources, vis, options, pixel_done, direct);
            if (sp.tint != 0)
                for (std::size_t a = first; a < direct.size(); ++a) direct[a].radiance *= points.tint_of(sp);
        }
        order_arrivals(direct, options.time);
        direct.shrink_to_fit();
    });
    Gather g = assemble(points.outputs, width, height, run_output, run_taps, run_direct);
    g.tints = points.tints;
    if (options.progress) options.progress("camera", 1.0);
    return g;
}

}  // namespace tprf
