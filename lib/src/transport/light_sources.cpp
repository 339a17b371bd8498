#include "tprf/transport/light_sources.h"

#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <variant>

namespace tprf {
namespace {

// Distance from x to a convex planar polygon: to its plane when x projects inside, else to the
// nearest edge.
double distance_to_polygon(const Vec3& x, const Vec3* poly, std::size_t count, const Vec3& normal) {
    const Vec3 projected = x - normal.dot(x - poly[0]) * normal;
    bool inside = true;
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < count; ++k) {
        const Vec3& a = poly[k];
        const Vec3& b = poly[(k + 1) % count];
        if ((b - a).cross(projected - a).dot(normal) < 0) inside = false;
        const Vec3 ab = b - a;
        const double s = std::clamp((x - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        best = std::min(best, (a + s * ab - x).norm());
    }
    return inside ? (x - projected).norm() : best;
}

// The spot as a Lambertian point: radiant intensity albedo P cos(theta) / pi about its normal.
PointSource spot_source(const LaserSpot& spot, const PatchSet& patches, const Visibility& visibility) {
    const Vec3& normal = patches.normal[spot.patch];
    PointSource s;
    s.position = spot.point + visibility.epsilon() * normal;
    s.origin = spot.point;
    s.path = spot.path;
    s.intensity = patches.albedo[spot.patch] * spot.power;  // W leaving the spot
    s.lobe = normal;
    s.patch = spot.patch;
    s.order = 2;
    return s;
}

}  // namespace

Rgb PointSource::intensity_towards(const Vec3& dir) const {
    if (lobe.isZero()) return intensity;
    return intensity * std::max(0.0, lobe.dot(dir)) / M_PI;
}

LaserSpot find_laser_spot(const Vec3& origin, const Vec3& direction, const Visibility& visibility) {
    LaserSpot spot;
    const RayHit hit = visibility.intersect(origin, direction, std::numeric_limits<double>::infinity());
    if (!hit.hit || !hit.front) return spot;
    spot.hit = true;
    spot.patch = hit.patch;
    spot.point = hit.point;
    spot.path = hit.distance;
    return spot;
}

LightSources light_sources(const Scene& scene, const PatchSet& patches, const Visibility& visibility) {
    LightSources sources;
    for (const Light& light : scene.lights)
        if (const auto* point = std::get_if<PointLight>(&light)) {
            PointSource s;
            s.position = s.origin = point->position;
            s.intensity = point->intensity;
            sources.points.push_back(s);
        }
    for (const Light& light : scene.lights)
        if (const auto* laser = std::get_if<Laser>(&light)) {
            sources.spots.push_back(find_laser_spot(laser->origin, laser->direction, visibility));
            sources.spots.back().power = laser->power;
        }
    for (const LaserSpot& spot : sources.spots)
        if (spot.hit) sources.points.push_back(spot_source(spot, patches, visibility));
    for (std::size_t i = 0; i < patches.size(); ++i)
        if ((patches.emission[i] > 0.0).any()) sources.emissive.push_back(std::uint32_t(i));
    return sources;
}

bool arrive(const PointSource& source, const Vec3& x, const Vec3& n, const Visibility& visibility,
            PointArrival& out) {
    const Vec3 d = source.position - x;
    const double r = d.norm();
    if (!(r > 0.0)) return false;
    const double cos_x = n.dot(d) / r;
    if (cos_x <= 0.0) return false;
    const Rgb intensity = source.intensity_towards(Vec3(-d / r));
    if (!(intensity > 0.0).any()) return false;
    if (visibility.occluded(x + visibility.epsilon() * n, source.position)) return false;
    out.path = source.path + r;
    out.intensity = intensity;
    out.cos_over_r2 = cos_x / (r * r);
    return true;
}

double earliest_path(const LightSources& sources, const PatchSet& patches, const Vec3& x) {
    double best = std::numeric_limits<double>::infinity();
    for (const PointSource& s : sources.points) best = std::min(best, s.path + (s.origin - x).norm());
    for (std::uint32_t e : sources.emissive)
        best = std::min(best, distance_to_polygon(x, patches.polygon(e), patches.corners(e), patches.normal[e]));
    return std::isfinite(best) ? best : 0.0;
}

}  // namespace tprf
