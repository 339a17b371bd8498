#include "tprf/transport/illumination.h"

#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/geometry/form_factors.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

namespace tprf {
namespace {

// Stratified sample s of n = g * g over the patch.
Vec3 sample_patch(const PatchSet& patches, std::size_t i, int s, int g) {
    return patch_point(patches, i, (s % g + 0.5) / g, (s / g + 0.5) / g);
}

// Side of the stratified grid for about `samples` points.
int grid_side(int samples) { return std::max(1, int(std::lround(std::sqrt(double(std::max(samples, 1)))))); }

// Direct light of point source k reflected by patch i: one pulse per stratified sample that it
// reaches, through the same arrive() that sensing points use.
void light_from_point(const PatchSet& patches, const Visibility& vis, std::size_t i, const PointSource& source,
                      std::int32_t k, int grid, std::vector<Pulse>& out) {
    const int samples = grid * grid;
    for (int s = 0; s < samples; ++s) {
        PointArrival a;
        if (!arrive(source, sample_patch(patches, i, s, grid), patches.normal[i], vis, a)) continue;
        Pulse p;
        p.path = a.path;
        p.energy = a.reflected(patches.albedo[i]) / double(samples);
        p.order = source.order;
        p.point_source = k;
        out.push_back(p);
    }
}

// The spot's own patch: the reflected power, spread over the patch, seen at the spot's path; its
// onward light is the spot's point source, not the links.
Pulse spot_pulse(const PatchSet& patches, std::size_t i, const PointSource& spot) {
    Pulse p;
    p.path = spot.path;
    p.energy = spot.intensity / patches.area[i];
    p.order = 1;
    p.propagates = false;
    return p;
}

// How finely the first bounce of an area source is sampled at one receiving patch.
struct AreaGrid {
    int receiver = 2;   // receiver points per side
    int timing = 4;     // source cells per side whose paths set the pulses' times
    int shadow = 4;     // source cells per side that shadow rays test first
    int penumbra = 16;  // cells per side, a ray each, where those disagree (or `timing`, if finer)
};

// One unblocked point pair of an area source's first bounce: its path and its kernel weight.
struct PairSample {
    double path;
    double weight;
};

// The grid for patch i and source a: enough timing cells that a cell's paths span about half a bin
// (at most 32 per side), as seen from the patch's centroid.
AreaGrid area_grid(const PatchSet& patches, std::size_t i, const AreaSource& a, const IlluminationOptions& options) {
    AreaGrid g;
    g.receiver = grid_side(options.area_samples);
    if (options.merge_bins) {
        const Vec3& x = patches.centroid[i];
        double far = 0.0;
        for (int k = 0; k < a.count; ++k) far = std::max(far, (a.corners[std::size_t(k)] - x).norm());
        const double spread = far - distance_to_polygon(x, a.polygon(), a.count, a.normal);
        g.timing = int(std::clamp(std::ceil(2.0 * spread / options.merge_bins->bin_width_m()), 2.0, 32.0));
    }
    g.shadow = grid_side(options.emitter_rays);
    g.penumbra = std::max(grid_side(options.penumbra_rays), g.shadow);
    return g;
}

// Whether anything of patch i is in front of source a and anything of a in front of patch i.
bool faces(const PatchSet& patches, std::size_t i, const AreaSource& a) {
    bool receiver_front = false, source_front = false;
    for (std::size_t k = 0; k < patches.corners(i); ++k)
        receiver_front |= a.normal.dot(patches.polygon(i)[k] - a.centroid) > 0.0;
    for (int k = 0; k < a.count; ++k)
        source_front |= patches.normal[i].dot(a.corners[std::size_t(k)] - patches.centroid[i]) > 0.0;
    return receiver_front && source_front;
}

Pulse area_pulse(double path, const Rgb& energy) {
    Pulse p;
    p.path = path;
    p.energy = energy;
    p.order = 1;
    return p;
}

// The first bounce of area source a at patch i. Its energy is albedo pi L_e F, with F the exact
// patch-to-polygon form factor (Lambert's contour integral, adaptive over the patch), times the share
// of the kernel cos cos / r^2 over point pairs (receiver points x source cells) that shadow rays find
// unblocked: exact where nothing is in the way. Its time spread is that kernel, each pair at its own
// path.
void light_from_area(const PatchSet& patches, const Visibility& vis, std::size_t i, const AreaSource& a,
                     const IlluminationOptions& options, std::vector<PairSample>& pairs, std::vector<Pulse>& out) {
    if (!faces(patches, i, a)) return;
    FormFactorQuadrature quadrature;
    quadrature.relative_tolerance = 1e-3;
    const double ff = polygon_form_factor(patches.polygon(i), patches.corners(i), patches.normal[i], a.polygon(),
                                          a.count, a.normal, quadrature);
    const Rgb energy = patches.albedo[i] * ff * M_PI * a.radiance;
    if (!(energy > 0.0).any()) return;
    const AreaGrid g = area_grid(patches, i, a, options);
    const Vec3& ni = patches.normal[i];
    const double lift = vis.epsilon();
    pairs.clear();
    double total = 0.0;  // the kernel over every pair, blocked or not, times its cell's share of the source
    const int coarse = g.shadow;
    // The kernel from x to the centre of cell (u, v) of an n x n grid over the source, and its path.
    const auto kernel = [&](const Vec3& x, int u, int v, int n, double& path) {
        const Vec3 d = a.point((u + 0.5) / n, (v + 0.5) / n) - x;
        const double r2 = d.squaredNorm();
        path = std::sqrt(r2);
        return std::max(0.0, ni.dot(d)) * std::max(0.0, -a.normal.dot(d)) / (r2 * r2);
    };
    // Whether the ray from x to the centre of that cell is unblocked.
    const auto open_to = [&](const Vec3& x, int u, int v, int n) {
        return !vis.occluded(x + lift * ni, a.point((u + 0.5) / n, (v + 0.5) / n) + lift * a.normal);
    };
    std::vector<char> coarse_open(std::size_t(coarse * coarse));
    for (int s = 0; s < g.receiver * g.receiver; ++s) {
        const Vec3 x = sample_patch(patches, i, s, g.receiver);
        // Shadow rays to the coarse cells that face x. Where they disagree (a penumbra), the pairs take a
        // finer grid and a ray each; elsewhere each pair takes its coarse cell's ray.
        bool any_open = false, any_blocked = false;
        for (int c = 0; c < coarse * coarse; ++c) {
            double path;
            const int u = c % coarse, v = c / coarse;
            char& o = coarse_open[std::size_t(c)];
            o = 2;  // not tested
            if (!(kernel(x, u, v, coarse, path) > 0.0)) continue;
            o = char(open_to(x, u, v, coarse));
            (o ? any_open : any_blocked) = true;
        }
        const bool penumbra = any_open && any_blocked;
        const int n = penumbra ? std::max(g.timing, g.penumbra) : g.timing;
        for (int c = 0; c < n * n; ++c) {
            const int u = c % n, v = c / n;
            double path;
            const double w = kernel(x, u, v, n, path) / (double(n) * n);
            if (!(w > 0.0)) continue;
            total += w;
            bool open;
            if (penumbra) {
                open = open_to(x, u, v, n);
            } else {
                const int cu = u * coarse / n, cv = v * coarse / n;
                char& o = coarse_open[std::size_t(cv * coarse + cu)];
                if (o == 2) o = char(open_to(x, cu, cv, coarse));  // its centre faces away, this pair does not
                open = o != 0;
            }
            if (open) pairs.push_back({path, w});
        }
    }
    if (!(total > 0.0)) {
        // No sampled pair faces both ways, yet F > 0 (a sliver near a horizon): the centroids' path
        // carries it, if unblocked.
        const Vec3& x = patches.centroid[i];
        if (vis.occluded(x + lift * ni, a.centroid + lift * a.normal)) return;
        pairs.push_back({(x - a.centroid).norm(), 1.0});
        total = 1.0;
    }
    const Rgb scale = energy / total;
    if (!options.merge_bins) {
        for (const PairSample& q : pairs) out.push_back(area_pulse(q.path, scale * q.weight));
        return;
    }
    // Merged per bin of the axis here, without sorting: one pulse per bin at its first pair's path.
    const double inv_bin = 1.0 / options.merge_bins->bin_width_m(), start = options.merge_bins->start_m();
    const auto bin = [&](double path) { return std::floor((path - start) * inv_bin); };
    double lowest = std::numeric_limits<double>::infinity(), highest = -lowest;
    for (const PairSample& q : pairs) {
        lowest = std::min(lowest, bin(q.path));
        highest = std::max(highest, bin(q.path));
    }
    if (pairs.empty()) return;
    std::vector<PairSample> per_bin(std::size_t(highest - lowest) + 1, PairSample{0.0, 0.0});
    for (const PairSample& q : pairs) {
        PairSample& b = per_bin[std::size_t(bin(q.path) - lowest)];
        if (b.weight == 0.0) b.path = q.path;
        b.weight += q.weight;
    }
    for (const PairSample& b : per_bin)
        if (b.weight > 0.0) out.push_back(area_pulse(b.path, scale * b.weight));
}

// An emissive patch's own light, seen at path 0; its onward light goes out with exact paths through
// its area source (light_from_area), not through the links.
Pulse self_pulse(const PatchSet& patches, std::size_t i) {
    Pulse p;
    p.energy = M_PI * patches.emission[i];  // exitance of a Lambertian emitter: pi L_e
    p.order = 0;
    p.propagates = false;
    return p;
}

// Merges the pulses of one patch that share a bin of `time`, an order, a source and a propagation.
void merge_by_bin(std::vector<Pulse>& pulses, const TimeAxis& time) {
    if (pulses.size() < 2) return;
    const double inv_bin = 1.0 / time.bin_width_m(), start = time.start_m();
    auto key = [&](const Pulse& p) {
        return std::make_tuple(std::floor((p.path - start) * inv_bin), p.order, p.propagates, p.point_source);
    };
    std::stable_sort(pulses.begin(), pulses.end(), [&](const Pulse& a, const Pulse& b) { return key(a) < key(b); });
    std::size_t kept = 0;
    for (std::size_t k = 0; k < pulses.size(); ++k) {
        if (kept > 0 && key(pulses[kept - 1]) == key(pulses[k]))
            pulses[kept - 1].energy += pulses[k].energy;
        else
            pulses[kept++] = pulses[k];
    }
    pulses.resize(kept);
    pulses.shrink_to_fit();
}

Illumination to_csr(std::vector<std::vector<Pulse>>& per_patch) {
    const std::size_t n = per_patch.size();
    Illumination e;
    e.row.assign(n + 1, 0);
    for (std::size_t i = 0; i < n; ++i) e.row[i + 1] = e.row[i] + per_patch[i].size();
    e.pulses.reserve(e.row[n]);
    for (auto& v : per_patch) e.pulses.insert(e.pulses.end(), v.begin(), v.end());
    return e;
}

}  // namespace

Illumination illuminate(const LightSources& sources, const PatchSet& patches, const Visibility& vis,
                        const IlluminationOptions& options) {
    const int grid = grid_side(options.samples);
    std::vector<std::vector<Pulse>> per_patch(patches.size());
    parallel_for(patches.size(), {options.threads, 16, true}, [&](std::size_t i) {
        thread_local std::vector<PairSample> pairs;
        std::vector<Pulse>& out = per_patch[i];
        if ((patches.emission[i] > 0.0).any()) out.push_back(self_pulse(patches, i));
        for (const AreaSource& a : sources.areas) light_from_area(patches, vis, i, a, options, pairs, out);
        for (std::size_t s = 0; s < sources.points.size(); ++s) {
            const PointSource& source = sources.points[s];
            if (source.patch == i)
                out.push_back(spot_pulse(patches, i, source));
            else
                light_from_point(patches, vis, i, source, std::int32_t(s), grid, out);
        }
        if (options.merge_bins) merge_by_bin(out, *options.merge_bins);
    });
    return to_csr(per_patch);
}

}  // namespace tprf
