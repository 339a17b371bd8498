#include "tprf/transport/illumination.h"

#include "tprf/core/error.h"
#include "tprf/transport/links.h"
#include "tprf/geometry/patches.h"
#include "tprf/scene/scene.h"
#include "tprf/geometry/visibility.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <variant>

namespace tprf {
namespace {

// Stratified sample s of n = g * g over the patch.
Vec3 sample_patch(const PatchSet& patches, std::size_t i, int s, int g) {
    return patch_point(patches, i, (s % g + 0.5) / g, (s / g + 0.5) / g);
}

// Direct light from a point source at `source` with radiant intensity `intensity(direction)`,
// reflected by patch i: one pulse per stratified sample that sees the source.
template <class IntensityFn>
void light_from_point(const PatchSet& patches, const Visibility& vis, std::size_t i, const Vec3& source,
                      double path_offset, std::uint8_t order, int grid, const IntensityFn& intensity,
                      std::vector<Pulse>& out) {
    const int samples = grid * grid;
    const Vec3& n = patches.normal[i];
    for (int s = 0; s < samples; ++s) {
        const Vec3 x = sample_patch(patches, i, s, grid);
        const Vec3 d = source - x;
        const double r = d.norm();
        if (r <= 0.0) continue;
        const double cos_x = n.dot(d) / r;
        if (cos_x <= 0.0) continue;
        const Rgb radiant = intensity(Vec3(-d / r));
        if (!(radiant > 0.0).any()) continue;
        if (vis.occluded(x + vis.epsilon() * n, source)) continue;
        Pulse p;
        p.path = path_offset + r;
        p.energy = patches.albedo[i] * radiant * (cos_x / (r * r)) / double(samples);
        p.order = order;
        p.propagates = true;
        p.exact_at_camera = true;
        out.push_back(p);
    }
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

}  // namespace

LaserSpot find_laser_spot(const Vec3& origin, const Vec3& direction, const PatchSet& /*patches*/,
                          const Visibility& visibility) {
    LaserSpot spot;
    const RayHit hit = visibility.intersect(origin, direction, std::numeric_limits<double>::infinity());
    if (!hit.hit || !hit.front) return spot;
    spot.hit = true;
    spot.patch = hit.patch;
    spot.point = hit.point;
    spot.path = hit.distance;
    return spot;
}

std::vector<LaserSpot> find_laser_spots(const Scene& scene, const PatchSet& patches, const Visibility& visibility) {
    std::vector<LaserSpot> spots;
    for (const Light& light : scene.lights)
        if (const auto* laser = std::get_if<Laser>(&light)) {
            spots.push_back(find_laser_spot(laser->origin, laser->direction, patches, visibility));
            spots.back().power = laser->power;
        }
    return spots;
}

Emission compute_emission(const Scene& scene, const PatchSet& patches, const Links& links, const Visibility& vis,
                          const EmitterOptions& options) {
    const std::size_t n = patches.size();
    const int grid = std::max(1, int(std::lround(std::sqrt(double(std::max(options.samples, 1))))));
    const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
    const int area_grid = std::max(1, int(std::lround(std::sqrt(double(std::max(options.area_samples, 1))))));

    const std::vector<LaserSpot> spots = find_laser_spots(scene, patches, vis);

    std::vector<std::vector<Pulse>> per_patch(n);
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads)
    for (std::size_t i = 0; i < n; ++i) {
        std::vector<Pulse>& out = per_patch[i];
        if ((patches.emission[i] > 0.0).any()) {
            // Seen at path 0; its onward light is sent below with exact paths, not through the links.
            Pulse p;
            p.energy = M_PI * patches.emission[i];  // exitance of a Lambertian emitter: pi L_e
            p.order = 0;
            p.propagates = false;
            out.push_back(p);
        }
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k)
            if ((patches.emission[links.source[k]] > 0.0).any())
                light_from_area(patches, vis, i, links.source[k], links.ff[k], area_grid, out);
        for (const Light& light : scene.lights)
            if (const auto* point = std::get_if<PointLight>(&light))
                light_from_point(patches, vis, i, point->position, 0.0, 1, grid,
                                 [&](const Vec3&) { return point->intensity; }, out);
        for (std::size_t l = 0; l < spots.size(); ++l) {
            const LaserSpot& spot = spots[l];
            if (!spot.hit) continue;
            const Rgb reflected = patches.albedo[spot.patch] * spot.power;  // W leaving X
            if (i == spot.patch) {
                Pulse p;
                p.path = spot.path;
                p.energy = reflected / patches.area[i];
                p.order = 1;
                p.propagates = false;
                out.push_back(p);
                continue;
            }
            const Vec3& nx = patches.normal[spot.patch];
            const Vec3 lifted = spot.point + vis.epsilon() * nx;
            // X is a Lambertian point: radiant intensity albedo P cos(theta) / pi.
            light_from_point(patches, vis, i, lifted, spot.path, 2, grid,
                             [&](const Vec3& dir) { return reflected * std::max(0.0, nx.dot(dir)) / M_PI; }, out);
        }
    }

    Emission e;
    e.row.assign(n + 1, 0);
    for (std::size_t i = 0; i < n; ++i) e.row[i + 1] = e.row[i] + per_patch[i].size();
    e.pulses.reserve(e.row[n]);
    for (auto& v : per_patch) e.pulses.insert(e.pulses.end(), v.begin(), v.end());
    return e;
}

}  // namespace tprf
