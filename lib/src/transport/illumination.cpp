#include "tprf/transport/illumination.h"

#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/geometry/form_factors.h"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace tprf {
namespace {

// Stratified sample s of n = g * g over the patch.
Vec3 sample_patch(const PatchSet& patches, std::size_t i, int s, int g) {
    return patch_point(patches, i, (s % g + 0.5) / g, (s / g + 0.5) / g);
}

// Side of the stratified grid for about `samples` points.
int grid_side(int samples) { return std::max(1, int(std::lround(std::sqrt(double(std::max(samples, 1)))))); }

// Patch i of the patches, as light reaches it past the visibility's occluders.
struct LitPatch {
    const PatchSet& patches;
    const Visibility& vis;
    std::size_t i;
};

// Direct light of point source k reflected by the patch: one pulse per stratified sample (grid x grid)
// that it reaches, through the same arrive() that sensing points use.
void light_from_point(const LitPatch& at, const PointSource& source, std::int32_t k, int grid, std::vector<Pulse>& out) {
    const PatchSet& patches = at.patches;
    const Visibility& vis = at.vis;
    const std::size_t i = at.i;
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
    p.energy = spot.power_sent() / patches.area[i];
    p.order = 1;
    p.propagates = false;
    return p;
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

Pulse area_pulse(double path, const Rgb& energy, std::int32_t source) {
    Pulse p;
    p.path = path;
    p.energy = energy;
    p.order = 1;
    p.area_source = source;
    return p;
}

// The first bounce of area source a at patch i. Its energy is albedo pi L_e F, with F the exact
// patch-to-polygon form factor (Lambert's contour integral, adaptive over the patch), times the share
// of the kernel cos cos / r^2 over point pairs (receiver points x source cells) that shadow rays find
// unblocked: exact where nothing is in the way. Its time spread is that kernel, each pair at its own
// path.
void light_from_area(const LitPatch& at, const AreaSource& a, std::int32_t source, const IlluminationOptions& options,
                     std::vector<AreaPair>& pairs, std::vector<Pulse>& out) {
    const PatchSet& patches = at.patches;
    const Visibility& vis = at.vis;
    const std::size_t i = at.i;
    if (!faces(patches, i, a)) return;
    FormFactorQuadrature quadrature;
    quadrature.relative_tolerance = 1e-3;
    const double ff =
        polygon_form_factor({patches.polygon(i), patches.corners(i), patches.normal[i]}, {a.polygon(), a.count, a.normal},
                            quadrature);
    const Rgb energy = patches.albedo[i] * ff * M_PI * a.radiance;
    if (!(energy > 0.0).any()) return;
    const Vec3& ni = patches.normal[i];
    const double bin_m = options.merge_bins ? options.merge_bins->bin_width_m() : 0.0;
    const double origin = options.merge_bins ? options.merge_bins->start_m() : 0.0;  // as merged below
    const AreaSampling sampling =
        area_sampling(a, patches.centroid[i], bin_m, origin, options.emitter_rays, options.penumbra_rays);
    const int g = grid_side(options.area_samples);
    pairs.clear();
    double total = 0.0;  // the weight of every pair, blocked or not
    for (int s = 0; s < g * g; ++s) total += arrive_area(a, sample_patch(patches, i, s, g), ni, vis, sampling, pairs);
    if (!(total > 0.0) && (total = arrive_area_centroid(a, patches.centroid[i], ni, vis, pairs)) == 0.0) return;
    const Rgb scale = energy / total;
    if (options.merge_bins) pairs = merge_pairs_by_bin(pairs, bin_m, options.merge_bins->start_m());
    for (const AreaPair& q : pairs) out.push_back(area_pulse(q.path, scale * q.weight, source));
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
    const BinMap bins = time.bin_map();
    auto key = [&](const Pulse& p) {
        return std::make_tuple(bins.bin_floor(p.path), p.order, p.propagates, p.point_source,
                               p.area_source);
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
        thread_local std::vector<AreaPair> pairs;
        std::vector<Pulse>& out = per_patch[i];
        if ((patches.emission[i] > 0.0).any()) out.push_back(self_pulse(patches, i));
        for (std::size_t a = 0; a < sources.areas.size(); ++a)
            light_from_area({patches, vis, i}, sources.areas[a], std::int32_t(a), options, pairs, out);
        for (std::size_t s = 0; s < sources.points.size(); ++s) {
            const PointSource& source = sources.points[s];
            if (source.patch == i)
                out.push_back(spot_pulse(patches, i, source));
            else
                light_from_point({patches, vis, i}, source, std::int32_t(s), grid, out);
        }
        if (options.merge_bins) merge_by_bin(out, *options.merge_bins);
    });
    return to_csr(per_patch);
}

}  // namespace tprf
