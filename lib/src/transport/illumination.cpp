#include "tprf/transport/illumination.h"

#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/links.h"

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

// The direct light of emissive patch e at patch i through link k: the energy the exact form factor
// gives, spread over the paths between g x g points of each patch by the point-to-point kernel.
void light_from_area(const PatchSet& patches, const Visibility& vis, std::size_t i, std::size_t e, double ff,
                     int g, std::vector<Pulse>& out) {
    const Rgb energy = patches.albedo[i] * ff * M_PI * patches.emission[e];  // albedo F B_e
    if (!(energy > 0.0).any()) return;
    const Vec3 &ni = patches.normal[i], &ne = patches.normal[e];
    const double lift = vis.epsilon();
    const std::size_t first = out.size();
    double total = 0.0;
    for (int s = 0; s < g * g; ++s) {
        const Vec3 x = sample_patch(patches, i, s, g);
        for (int k = 0; k < g * g; ++k) {
            const Vec3 y = sample_patch(patches, e, k, g);
            const Vec3 d = y - x;
            const double r2 = d.squaredNorm();
            const double w = std::max(0.0, ni.dot(d)) * std::max(0.0, -ne.dot(d)) / (r2 * r2);
            if (!(w > 0.0) || vis.occluded(x + lift * ni, y + lift * ne)) continue;
            Pulse p;
            p.path = std::sqrt(r2);
            p.energy = Rgb::Constant(w);
            p.order = 1;
            out.push_back(p);
            total += w;
        }
    }
    if (total <= 0.0) {
        // Every sampled pair is blocked, yet the link's rays found a gap: the centroid path carries it.
        out.resize(first);
        Pulse p;
        p.path = (patches.centroid[i] - patches.centroid[e]).norm();
        p.energy = energy;
        p.order = 1;
        out.push_back(p);
        return;
    }
    for (std::size_t k = first; k < out.size(); ++k) out[k].energy = energy * (out[k].energy[0] / total);
}

// An emissive patch's own light, seen at path 0; its onward light goes out with exact paths through
// light_from_area, not through the links.
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

Illumination illuminate(const LightSources& sources, const PatchSet& patches, const Links& links,
                        const Visibility& vis, const IlluminationOptions& options) {
    const int grid = grid_side(options.samples), area_grid = grid_side(options.area_samples);
    std::vector<std::vector<Pulse>> per_patch(patches.size());
    parallel_for(patches.size(), {options.threads, 16, true}, [&](std::size_t i) {
        std::vector<Pulse>& out = per_patch[i];
        if ((patches.emission[i] > 0.0).any()) out.push_back(self_pulse(patches, i));
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k)
            if ((patches.emission[links.source[k]] > 0.0).any())
                light_from_area(patches, vis, i, links.source[k], links.ff[k], area_grid, out);
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
