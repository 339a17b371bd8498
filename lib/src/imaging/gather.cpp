#include "tprf/imaging/gather.h"
#include "tprf/transport/glossy_rows.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/core/random.h"
#include "tprf/core/time_kernel.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/neighbours.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/second_bounce.h"
#include "tprf/transport/light_sources.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace tprf {
namespace {

// The interpolation kernel's support, in circumradii of the patch a point lies on. The patch profile is
// already its patch's average, so a wider kernel blurs it further: on the Cornell box (96 x 96, 800
// bins, 2,520 patches) against a converged render, the median pixel error at spp 16 was 1.27% at 2,
// 1.05% at 1.75, 1.02% at 1.6, 1.10% at 1.5 and 1.24% at 1.4 (where the kernel barely reaches the
// neighbours' centroids, 1.41 circumradii away on a grid of squares, and the patches begin to show);
// 1.6 also gave the lowest or nearly lowest 90th percentile there, at 5,375 patches and on the corner
// (bench/RESULTS.md).
constexpr double kSupportRadii = 1.6;

// Interpolation candidates of every patch that holds a sensing point: the patches of the same surface
// (one object, normals within about 45 degrees) whose centroids lie within 1 + kSupportRadii of its
// circumradii. A point on patch p lies within one circumradius of its centroid and its kernel reaches
// kSupportRadii more (kernel_weights), so the candidates hold every patch a point's kernel can weigh.
// One search per patch, not per point.
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
            reach = std::max(reach, (1.0 + kSupportRadii) * radius[p]);
        }
    const Neighbours near = radius_search(patches.centroid, queries, reach, threads);
    std::vector<std::vector<std::uint32_t>> lists(patches.size());
    for (std::size_t k = 0; k < which.size(); ++k) {
        const std::uint32_t p = which[k];
        const double r2 = (1.0 + kSupportRadii) * (1.0 + kSupportRadii) * radius[p] * radius[p];
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
// kSupportRadii circumradii of p, over p's candidates, so that the profile varies continuously across patch
// borders and no faceting shows. Normalised; the patch alone when no candidate is inside the support.
void kernel_weights(const PatchSet& patches, std::uint32_t p, const Vec3& x, double radius, const Candidates& c,
                    std::vector<std::pair<std::uint32_t, double>>& weights) {
    const double support2 = kSupportRadii * kSupportRadii * radius * radius;
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

// What the exact direct light at sensing points reads: the patches, the sources, the visibility and the
// gather's options.
struct DirectScene {
    const PatchSet& patches;
    const LightSources& sources;
    const Visibility& vis;
    const GatherOptions& options;
};

// A pixel's samples (or a group of them: `count` points from `pts`) and each one's weight.
struct Samples {
    const SensingPoint* pts;
    std::size_t count;
    double weight;
};

// A glossy sensing point under an area source: the point, its BRDF, the source, and the exact form
// factor F(x) of the source times the point's weight.
struct GlossyArea {
    const SensingPoint& sp;
    const Vec3& n;
    const GlossyBrdf& brdf;
    const AreaSource& a;
    double ff_weight;
};

// Timing cells per side that resolve a glossy lobe of roughness alpha over source a seen from x: about a
// third of the lobe's width (2 alpha) per cell, up to 64.
int lobe_cells(const AreaSource& a, const Vec3& x, double alpha) {
    double extent = 0.0;
    for (int k = 0; k < a.count; ++k) extent = std::max(extent, (a.polygon()[k] - a.polygon()[(k + 1) % a.count]).norm());
    const double r = std::max((a.centroid - x).norm(), 1e-9);
    return int(std::clamp(std::ceil(3.0 * extent / (r * 2.0 * alpha)), 1.0, 64.0));
}

// Direct light of area source a at a glossy sensing point: the BRDF as its two terms, each a scalar of
// the direction towards the source times a colour (GlossyBrdf::base and lobe), the scalar weighing
// each timing cell. Pair weights are pi times the scalar times the Lambertian kernel, so that
// L_e F(x) / total turns them into radiance as for a Lambertian point (whose term is 1 / pi). The lobe's
// cells are fine enough to resolve it (lobe_cells).
void glossy_area_arrivals(const GlossyArea& g, AreaSampling sampling, const Visibility& vis,
                          std::vector<DirectArrival>& out) {
    const SensingPoint& sp = g.sp;
    const GlossyBrdf& brdf = g.brdf;
    const Vec3& n = g.n;
    const Vec3 wo = sp.view.cast<double>();
    thread_local std::vector<AreaPair> pairs;
    for (const bool lobe : {false, true}) {
        const Rgb colour = lobe ? brdf.lobe_colour() : brdf.albedo;
        if (!(colour > 0.0).any()) continue;
        if (lobe) sampling.timing = std::max(sampling.timing, lobe_cells(g.a, sp.point, brdf.roughness));
        sampling.towards = [&](const Vec3& wi) { return M_PI * (lobe ? brdf.lobe(n, wi, wo) : brdf.base(n, wi, wo)); };
        pairs.clear();
        const double total = arrive_area(g.a, sp.point, n, vis, sampling, pairs);
        if (!(total > 0.0)) continue;
        const Rgb radiance = colour * g.a.radiance * (g.ff_weight / total);
        for (const AreaPair& q : pairs) out.push_back({sp.output, q.path + sp.leg, radiance * q.weight, 1});
    }
}

// Direct light of area source a at the sensing point, seen along its leg: radiance albedo L_e F(x)
// with F the exact point-to-polygon form factor, times the unblocked share of its sampled pairs,
// spread over their paths and over the point's cell (per bin of the time axis, when there is one).
void area_arrivals(const DirectScene& scene, const SensingPoint& sp, RunSample at, double weight, const AreaSource& a,
                   std::vector<DirectArrival>& out) {
    const PatchSet& patches = scene.patches;
    const Visibility& vis = scene.vis;
    const GatherOptions& options = scene.options;
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
    if (const GlossyBrdf* brdf = patches.brdf(sp.patch)) {
        glossy_area_arrivals({sp, n, *brdf, a, ff * weight}, sampling, vis, out);
        return;
    }
    double total = arrive_area(a, sp.point, n, vis, sampling, pairs);
    if (!(total > 0.0) && (total = arrive_area_centroid(a, sp.point, n, vis, pairs)) == 0.0) return;
    const Rgb radiance = patches.albedo[sp.patch] * a.radiance * (ff * weight / total);
    for (const AreaPair& q : pairs) out.push_back({sp.output, q.path + sp.leg, radiance * q.weight, 1});
}

// Light arriving at `path` at an output from a sensing point, whose path changes by +- a and +- b along
// the point's half-axes and never comes before `lowest`.
struct CellArrival {
    std::uint32_t output;
    double path, a, b, lowest;
    Rgb radiance;
    std::uint8_t order;
};

// The arrival spread over the paths of the point's cell and cut at the bins of the time axis: one
// arrival per bin it touches. Without a time axis, one arrival.
void add_over_cell(const CellArrival& c, const TimeAxis* time, std::vector<DirectArrival>& out) {
    const std::uint32_t output = c.output;
    const double path = c.path, a = c.a, b = c.b, lowest = c.lowest;
    const Rgb& radiance = c.radiance;
    const std::uint8_t order = c.order;
    if (!time) {
        out.push_back({output, path, radiance, order});
        return;
    }
    spread_over_bins({path, a, b, lowest}, time->bin_width_m(), time->start_m(),
                     [&](double at, double share) { out.push_back({output, at, radiance * share, order}); });
}

// A pixel's samples in groups that can share the timing of an area source's light: each group the
// samples (each with its cell) in the open (no mirror or glass on the way) on one flat surface (one
// object, one plane). A pixel on one wall is one group; one across a crease or a silhouette, one per
// surface. Point samples, and samples behind mirrors or glass, are in no group (group -1). Returns
// the number of groups.
int flat_groups(const SensingPoint* pts, std::size_t count, const PatchSet& patches, std::vector<int>& group) {
    group.assign(count, -1);
    thread_local std::vector<std::size_t> first;  // each group's first sample
    first.clear();
    for (std::size_t h = 0; h < count; ++h) {
        const SensingPoint& sp = pts[h];
        if (sp.throughput != 1.0f || sp.tint != 0 || (sp.du.isZero() && sp.dv.isZero()) || patches.brdf(sp.patch)) continue;
        const Vec3& n = patches.normal[sp.patch];
        const double reach = 1e-6 * (1.0 + sp.point.norm());
        for (std::size_t g = 0; g < first.size() && group[h] < 0; ++g) {
            const SensingPoint& q = pts[first[g]];
            if (patches.object[q.patch] == patches.object[sp.patch] && patches.normal[q.patch].dot(n) >= 1.0 - 1e-12 &&
                std::abs(n.dot(sp.point - q.point)) <= reach)
                group[h] = int(g);
        }
        if (group[h] < 0) {
            group[h] = int(first.size());
            first.push_back(h);
        }
    }
    return int(first.size());
}

// A group of a pixel's samples as one: their centre, mean leg and footprint, and its four outermost
// samples (along +-u +-v). The footprint is the samples' cells side by side: along each of the cells'
// axes, as many cells as the samples' extent spans (8 x 8 for a whole pixel at spp 64, 8 x 3 for the
// part of it on one side of a crease).
struct PixelFrame {
    Vec3 centre = Vec3::Zero();
    double leg = 0.0;
    Footprint footprint;
    std::size_t outer[4] = {0, 0, 0, 0};
};

PixelFrame pixel_frame(const SensingPoint* pts, std::size_t count) {
    PixelFrame p;
    Vec3 du = Vec3::Zero(), dv = Vec3::Zero();
    double leg_du = 0.0, leg_dv = 0.0;
    for (std::size_t h = 0; h < count; ++h) {
        p.centre += pts[h].point;
        p.leg += pts[h].leg;
        du += pts[h].du.cast<double>();
        dv += pts[h].dv.cast<double>();
        leg_du += pts[h].leg_du;
        leg_dv += pts[h].leg_dv;
    }
    const double mean = 1.0 / double(count);
    p.centre *= mean;
    p.leg *= mean;
    du *= mean;
    dv *= mean;
    // Each sample's offset from the centre as a du + b dv (the cells' axes may be oblique on the surface).
    const double uu = du.squaredNorm(), uv = du.dot(dv), vv = dv.squaredNorm(), det = uu * vv - uv * uv;
    double best[4] = {-1e300, -1e300, -1e300, -1e300}, lo_u = 0, hi_u = 0, lo_v = 0, hi_v = 0;
    for (std::size_t h = 0; h < count; ++h) {
        const Vec3 r = pts[h].point - p.centre;
        const double ru = r.dot(du), rv = r.dot(dv);
        const double x = det > 0.0 ? (vv * ru - uv * rv) / det : 0.0, y = det > 0.0 ? (uu * rv - uv * ru) / det : 0.0;
        lo_u = std::min(lo_u, x);
        hi_u = std::max(hi_u, x);
        lo_v = std::min(lo_v, y);
        hi_v = std::max(hi_v, y);
        const double score[4] = {x + y, x - y, -x + y, -x - y};
        for (int k = 0; k < 4; ++k)
            if (score[k] > best[k]) {
                best[k] = score[k];
                p.outer[k] = h;
            }
    }
    // Cells along each axis: the extent in cells (two half-axes each), plus the one each end sample is in.
    const double nu = std::round(0.5 * (hi_u - lo_u)) + 1.0, nv = std::round(0.5 * (hi_v - lo_v)) + 1.0;
    p.footprint = {nu * du, nv * dv, p.leg, nu * mean * leg_du, nv * mean * leg_dv};
    return p;
}

enum class Shadow { open, hidden, penumbra, dimmed };

// The shared shadow test: from the pixel's four outermost samples, a ray to the centre of each cell of
// the coarse shadow grid that faces it, and to the source's rim (rim_probes).
Shadow probe_shadow(const SensingPoint* pts, const PixelFrame& p, const Vec3& n, const AreaSource& a,
                    const Visibility& vis, const GatherOptions& options) {
    const int g = area_sampling(a, p.centre, 0.0, 0.0, options.emitter_rays, options.penumbra_rays).shadow;
    thread_local std::vector<Vec3> probes;
    probes.resize(std::size_t(g * g) + 8);
    int count = 0;
    for (int c = 0; c < g * g; ++c) probes[std::size_t(count++)] = a.point((c % g + 0.5) / g, (c / g + 0.5) / g);
    count += rim_probes(a, probes.data() + count);
    thread_local std::vector<Vec3> from, to;
    thread_local std::vector<double> passed;
    bool open = false, blocked = false;
    for (const std::size_t h : p.outer) {
        const Vec3& x = pts[h].point;
        to.clear();
        for (int c = 0; c < count; ++c)
            if (faces_source(a, x, n, probes[std::size_t(c)])) to.push_back(probes[std::size_t(c)]);
        from.assign(to.size(), x);
        passed.resize(to.size());
        passes_from_source(a, vis, from, n, to, passed);
        for (const double q : passed) {
            if (q != 1.0 && q != 0.0) return Shadow::dimmed;
            (q == 1.0 ? open : blocked) = true;
        }
        if (open && blocked) break;  // a penumbra (glass further on is the penumbra rays' affair)
    }
    return open && blocked ? Shadow::penumbra : blocked ? Shadow::hidden : Shadow::open;
}

// The open share of each timing cell of `s` (m x m) as the samples see it: a finer grid of about `rays`
// cells (r x r in each timing cell), one ray each, from the samples in turn (the golden
// ratio's sequence spreads them over the pixel) to a jittered point of the cell (the R2 sequence). A
// timing cell that no ray faces counts as open (its light, if any, is the timing's own affair).
std::vector<double> penumbra_open(const Samples& samples, const Vec3& n, const AreaSource& a, const AreaSampling& s,
                                  const Visibility& vis, int rays) {
    const SensingPoint* pts = samples.pts;
    const std::size_t count = samples.count;
    const int m = s.timing;
    const int r = std::max(1, int(std::ceil(std::sqrt(double(std::max(rays, 1))) / m)));
    const int f = m * r;
    std::vector<double> passed(std::size_t(m * m), 0.0), facing(std::size_t(m * m), 0.0);
    const double golden = 0.5 * (std::sqrt(5.0) - 1.0);
    thread_local std::vector<Vec3> from, to;
    thread_local std::vector<std::size_t> cells;
    thread_local std::vector<double> ray_passed;
    from.clear();
    to.clear();
    cells.clear();
    for (int i = 0; i < f * f; ++i) {
        const int fu = i % f, fv = i / f;
        double ju, jv, turn;
        r2_point(double(i + 1), ju, jv);
        turn = double(i) * golden;
        const Vec3& x = pts[std::size_t((turn - std::floor(turn)) * double(count))].point;
        const Vec3 y = a.point((fu + ju) / f, (fv + jv) / f);
        if (!faces_source(a, x, n, y)) continue;
        from.push_back(x);
        to.push_back(y);
        cells.push_back(std::size_t((fv / r) * m + fu / r));
    }
    ray_passed.resize(to.size());
    passes_from_source(a, vis, from, n, to, ray_passed);
    for (std::size_t k = 0; k < cells.size(); ++k) {  // summed in the rays' order, as one by one
        facing[cells[k]] += 1.0;
        passed[cells[k]] += ray_passed[k];
    }
    for (std::size_t c = 0; c < passed.size(); ++c) passed[c] = facing[c] > 0.0 ? passed[c] / facing[c] : 1.0;
    return passed;
}

// The light of area source a at a group of samples (or a quarter of one) whose frame is p, timed once:
// as its centre sees the source's cells, spread over the paths of the group's footprint. Each sample's
// radiance is albedo L_e F(x) with its own exact F, times the open share of the source: all of it, or,
// in a penumbra, each timing cell's open share from penumbra_rays rays of the samples (penumbra_open). False
// (nothing added) when no cell centre faces a penumbra group's centre.
bool group_light(const DirectScene& scene, const Samples& samples, const PixelFrame& p, const AreaSource& a,
                 bool penumbra, std::vector<DirectArrival>& out) {
    const SensingPoint* pts = samples.pts;
    const std::size_t count = samples.count;
    const double weight = samples.weight;
    const PatchSet& patches = scene.patches;
    const GatherOptions& options = scene.options;
    const Vec3& n = patches.normal[pts[0].patch];
    Rgb radiance = Rgb::Zero();
    for (std::size_t h = 0; h < count; ++h) {
        const double ff = point_polygon_form_factor(pts[h].point, n, a.polygon(), a.count, a.normal);
        if (ff > 0.0) radiance += patches.albedo[pts[h].patch] * (ff * weight);
    }
    if (!(radiance > 0.0).any()) return true;
    thread_local std::vector<AreaPair> pairs;
    pairs.clear();
    AreaSampling sampling = area_sampling(a, p.centre, options.time->bin_width_m(), options.time->start_m() - p.leg, 0, 0);
    sampling.footprint = p.footprint;
    double total = 0.0;
    if (!penumbra) {
        total = arrive_area_open(a, p.centre, n, sampling, pairs);  // the shared rays found it open
    } else {
        total = arrive_area_shaded(a, p.centre, n, sampling,
                                   penumbra_open(samples, n, a, sampling, scene.vis, options.penumbra_rays), pairs);
    }
    if (!(total > 0.0)) {
        if (penumbra) return false;  // no cell centre faces the group's centre: sample by sample
        pairs.push_back({(p.centre - a.centroid).norm(), 1.0});
        total = 1.0;
    }
    radiance *= a.radiance / total;
    for (const AreaPair& q : pairs) out.push_back({pts[0].output, q.path + p.leg, radiance * q.weight, 1});
    return true;
}

// Direct light of area source a at a group of a pixel's samples (flat_groups), timed per group rather
// than per sample. The shared shadow test (probe_shadow) finds the source wholly open (the group is timed
// as one), wholly hidden (no light) or a penumbra (each quarter of the group timed as one, with its
// samples' shared rays). False (nothing added) when glass dims a ray, or no cell faces a quarter's
// centre: the samples are then gathered one by one.
bool area_pixel_arrivals(const DirectScene& scene, const Samples& samples, const AreaSource& a,
                         std::vector<DirectArrival>& out) {
    const SensingPoint* pts = samples.pts;
    const std::size_t count = samples.count;
    const PixelFrame p = pixel_frame(pts, count);
    const Vec3& n = scene.patches.normal[pts[0].patch];
    const Shadow shadow = probe_shadow(pts, p, n, a, scene.vis, scene.options);
    if (shadow == Shadow::dimmed) return false;
    if (shadow == Shadow::hidden) return true;
    if (shadow == Shadow::open || count < 8)
        return group_light(scene, samples, p, a, shadow == Shadow::penumbra, out);
    // A penumbra: its light comes from part of the pixel more than from the rest, so each quarter of the
    // samples (by side of the centre along the footprint's axes) is timed over its own footprint.
    thread_local std::vector<SensingPoint> quarter[4];
    for (auto& q : quarter) q.clear();
    const Vec3 u = p.footprint.du, v = p.footprint.dv;
    for (std::size_t h = 0; h < count; ++h) {
        const Vec3 r = pts[h].point - p.centre;
        quarter[(r.dot(u) < 0.0 ? 0 : 1) + (r.dot(v) < 0.0 ? 0 : 2)].push_back(pts[h]);
    }
    const std::size_t first = out.size();
    for (const auto& q : quarter)
        if (!q.empty() &&
            !group_light(scene, {q.data(), q.size(), samples.weight}, pixel_frame(q.data(), q.size()), a, true, out)) {
            out.resize(first);
            return false;
        }
    return true;
}

// The area sources' light at each group of two or more of a pixel's samples (flat_groups), where
// area_pixel_arrivals can share it; done[h * areas + a] marks sample h's light of source a as added.
void shared_area_arrivals(const DirectScene& scene, const Samples& samples, std::vector<char>& done,
                          std::vector<DirectArrival>& out) {
    const SensingPoint* pts = samples.pts;
    const std::size_t count = samples.count;
    const LightSources& sources = scene.sources;
    thread_local std::vector<int> group;
    thread_local std::vector<SensingPoint> members;
    const int groups = flat_groups(pts, count, scene.patches, group);
    const std::size_t areas = sources.areas.size();
    for (int g = 0; g < groups; ++g) {
        const std::size_t size = std::size_t(std::count(group.begin(), group.end(), g));
        if (size < 2) continue;
        const SensingPoint* at = pts;  // the whole pixel (most pixels): its own points, uncopied
        if (size < count) {
            members.clear();
            for (std::size_t h = 0; h < count; ++h)
                if (group[h] == g) members.push_back(pts[h]);
            at = members.data();
        }
        for (std::size_t a = 0; a < areas; ++a)
            if (area_pixel_arrivals(scene, {at, size, samples.weight}, sources.areas[a], out))
                for (std::size_t h = 0; h < count; ++h)
                    if (group[h] == g) done[h * areas + a] = 1;
    }
}

// A glossy sensing point's BRDF for the light of a point source towards the sensor (wo: the point's view).
Rgb reflected_towards(const GlossyBrdf& brdf, const SensingPoint& sp, const PointSource& source, const Vec3& n) {
    const Vec3 wi = (source.position - sp.point).normalized(), wo = sp.view.cast<double>();
    return brdf.eval(n, wi, wo);
}

// Exact direct light of every point and area source at the sensing point, seen along its leg; a point
// source's light is spread over the paths of the point's cell.
void direct_arrivals(const DirectScene& scene, const SensingPoint& sp, RunSample at, double weight, const char* area_done,
                     std::vector<DirectArrival>& out) {
    const PatchSet& patches = scene.patches;
    const LightSources& sources = scene.sources;
    const Rgb& albedo = patches.albedo[sp.patch];
    const GlossyBrdf* brdf = patches.brdf(sp.patch);
    const Footprint f = footprint_of(sp);
    for (const PointSource& source : sources.points) {
        if (source.patch == sp.patch) continue;
        PointArrival a;
        if (!arrive(source, sp.point, patches.normal[sp.patch], scene.vis, a)) continue;
        // Radiance towards the sensor, times the sample's weight: the BRDF times the irradiance (albedo /
        // pi for a Lambertian point).
        const Rgb radiance =
            brdf ? Rgb(reflected_towards(*brdf, sp, source, patches.normal[sp.patch]) * a.reflected(Rgb::Ones()) * weight)
                 : Rgb(a.reflected(albedo) * (weight / M_PI));
        const Vec3 away = (sp.point - source.position).normalized();  // |x - source| changes along it
        const double lowest = f.empty() ? a.path : source.path + f.least_at_corners([&](const Vec3& offset) {
            return (sp.point + offset - source.position).norm();
        });
        add_over_cell({sp.output, a.path + sp.leg, away.dot(f.du) + f.leg_du, away.dot(f.dv) + f.leg_dv, lowest + sp.leg,
                       radiance, source.order},
                      scene.options.time, out);
    }
    for (std::size_t k = 0; k < sources.areas.size(); ++k)
        if (!area_done[k]) area_arrivals(scene, sp, at, weight, sources.areas[k], out);
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
    const BinMap map = time->bin_map();
    const double bins = double(time->bins);
    const auto bin = [&](const DirectArrival& a) { return std::int64_t(std::clamp(map.bin_floor(a.path), -1.0, bins)); };
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

Gather gather_points(const SensingPoints& points, int width, int height, const GatherScene& scene,
                     const GatherOptions& options) {
    const PatchSet& patches = scene.patches;
    const LightSources& sources = scene.sources;
    const DirectScene direct_scene{patches, sources, scene.visibility, options};
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
    const GlossyRows* glossy = options.glossy && !options.glossy->empty() ? options.glossy : nullptr;
    parallel_for(runs, {options.threads, 64, true}, [&](std::size_t k) {
        std::vector<DirectArrival>& direct = run_direct[k];
        const std::size_t count = run_start[k + 1] - run_start[k], areas = sources.areas.size();
        // done[h * areas + a]: sample h's light of area source a was added with its group's.
        thread_local std::vector<char> done;
        done.assign(count * areas, 0);
        if (options.time && areas > 0) shared_area_arrivals(direct_scene, {&pts[run_start[k]], count, weight}, done, direct);
        for (std::size_t h = run_start[k]; h < run_start[k + 1]; ++h) {
            const SensingPoint& sp = pts[h];
            const float earliest = float(earliest_path(sources, sp.point)) + sp.leg;
            const double share = weight * double(sp.throughput);
            thread_local std::vector<std::pair<std::uint32_t, double>> weights;
            kernel_weights(patches, sp.patch, sp.point, radius[sp.patch], candidates, weights);
            for (const auto& [q, w] : weights) {
                const float shift = options.second_bounce ? float(options.second_bounce->shift(q, sp.point)) : 0.0f;
                run_taps[k].push_back({q, float(w * share / M_PI), sp.leg, earliest, sp.tint, shift});
                if (glossy && glossy->slot[q] >= 0 && !sp.view.isZero()) {
                    int cell[4];
                    double part[4];
                    glossy->cells_about(patches, q, sp.view.cast<double>(), cell, part);
                    for (int e = 0; e < 4; ++e)
                        if (part[e] > 0.0)
                            run_taps[k].push_back({glossy->out_row(std::size_t(glossy->slot[q]), cell[e]),
                                                   float(w * part[e] * share / M_PI), sp.leg, earliest, sp.tint, shift});
                }
            }
            const std::size_t first = direct.size();
            direct_arrivals(direct_scene, sp, {h - run_start[k], count}, share, done.data() + (h - run_start[k]) * areas,
                            direct);
            if (sp.tint != 0)
                for (std::size_t a = first; a < direct.size(); ++a) direct[a].radiance *= points.tint_of(sp);
        }
        order_arrivals(direct, options.time);
        direct.shrink_to_fit();
        if (options.time) merge_taps(run_taps[k], *options.time);
    });
    Gather g = assemble(points.outputs, width, height, run_output, run_taps, run_direct);
    g.tints = points.tints;
    if (options.progress) options.progress("camera", 1.0);
    return g;
}

void merge_taps(std::vector<PixelTap>& taps, const TimeAxis& time) {
    if (taps.size() < 2) return;
    const BinMap bins = time.bin_map();
    const auto half = [&](double leg) {  // the half bin of a leg
        const double lag = bins.lag(leg), whole = std::floor(lag);
        return std::int64_t(2.0 * whole) + (lag - whole >= 0.5 ? 1 : 0);
    };
    // Open addressing over at least twice the taps (a power of two): slot -> merged index + 1.
    thread_local std::vector<std::uint32_t> slot;
    thread_local std::vector<std::array<std::int64_t, 2>> halves;  // of the leg, of the leg plus the shift
    thread_local std::vector<std::array<double, 2>> moment;        // sums of weight x leg, weight x shift
    std::size_t size = 16;
    while (size < 2 * taps.size()) size *= 2;
    slot.assign(size, 0);
    halves.clear();
    moment.clear();
    std::size_t merged = 0;
    for (std::size_t k = 0; k < taps.size(); ++k) {
        const PixelTap t = taps[k];
        const std::array<std::int64_t, 2> hb = {half(double(t.leg)), half(double(t.leg) + double(t.shift))};
        const std::uint64_t h = (std::uint64_t(t.patch) * 0x9E3779B97F4A7C15ull) ^
                                (std::uint64_t(hb[0]) * 0xC2B2AE3D27D4EB4Full) ^
                                (std::uint64_t(hb[1] - hb[0]) * 0x27D4EB2F165667C5ull) ^
                                (std::uint64_t(t.tint) * 0x165667B19E3779F9ull);
        std::size_t s = std::size_t(h >> 40) & (size - 1);
        const auto same = [&](std::uint32_t m) {
            return taps[m].patch == t.patch && taps[m].tint == t.tint && halves[m] == hb;
        };
        while (slot[s] != 0 && !same(slot[s] - 1)) s = (s + 1) & (size - 1);
        const std::array<double, 2> moments = {double(t.weight) * double(t.leg), double(t.weight) * double(t.shift)};
        if (slot[s] == 0) {
            slot[s] = std::uint32_t(merged + 1);
            halves.push_back(hb);
            moment.push_back(moments);
            taps[merged++] = t;
            continue;
        }
        PixelTap& m = taps[slot[s] - 1];
        moment[slot[s] - 1][0] += moments[0];
        moment[slot[s] - 1][1] += moments[1];
        m.weight += t.weight;
        m.earliest = std::min(m.earliest, t.earliest);
    }
    taps.resize(merged);
    for (std::size_t k = 0; k < merged; ++k)
        if (taps[k].weight > 0.0f) {
            taps[k].leg = float(moment[k][0] / double(taps[k].weight));
            taps[k].shift = float(moment[k][1] / double(taps[k].weight));
        }
    taps.shrink_to_fit();
}

}  // namespace tprf
