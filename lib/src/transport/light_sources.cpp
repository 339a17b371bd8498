#include "tprf/transport/light_sources.h"

#include "tprf/core/error.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <variant>

namespace tprf {

// To its plane when x projects inside, else to the nearest edge.
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

namespace {

AreaSource make_area_source(const Vec3* corners, std::size_t count, const Rgb& radiance, std::uint32_t object) {
    TPRF_CHECK(count == 3 || count == 4);
    AreaSource a;
    std::copy(corners, corners + count, a.corners.begin());
    a.count = std::uint8_t(count);
    const Vec3 cross = count == 4 ? Vec3((corners[2] - corners[0]).cross(corners[3] - corners[1]))
                                  : Vec3((corners[1] - corners[0]).cross(corners[2] - corners[0]));
    a.normal = cross.normalized();
    a.area = polygon_area(corners, count);
    a.centroid = Vec3::Zero();
    for (std::size_t k = 0; k < count; ++k) a.centroid += corners[k] / double(count);  // a parallelogram's or triangle's
    a.radiance = radiance;
    a.object = object;
    return a;
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
    sources.areas = area_sources(&scene, patches);
    return sources;
}

Vec3 AreaSource::point(double u, double v) const { return polygon_point(corners.data(), count, u, v); }

std::vector<AreaSource> area_sources(const Scene* scene, const PatchSet& patches) {
    std::vector<AreaSource> out;
    // One source per side of an emissive rectangle, made when its first patch on that side is met.
    std::vector<std::array<bool, 2>> made(scene ? scene->objects.size() : 0, {false, false});
    for (std::size_t i = 0; i < patches.size(); ++i) {
        if (!(patches.emission[i] > 0.0).any()) continue;
        const std::uint32_t object = patches.object[i];
        const RectangleShape* rect = nullptr;
        if (scene && object < scene->objects.size()) rect = std::get_if<RectangleShape>(&scene->objects[object].shape);
        if (!rect) {
            out.push_back(make_area_source(patches.polygon(i), patches.corners(i), patches.emission[i], object));
            continue;
        }
        const bool back = patches.normal[i].dot(rect->u.cross(rect->v)) < 0.0;
        if (made[object][back]) continue;
        made[object][back] = true;
        std::array<Vec3, 4> c = {rect->origin, rect->origin + rect->u, rect->origin + rect->u + rect->v,
                                 rect->origin + rect->v};
        if (back) std::reverse(c.begin(), c.end());
        out.push_back(make_area_source(c.data(), 4, patches.emission[i], object));
    }
    return out;
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

double earliest_path(const LightSources& sources, const Vec3& x) {
    double best = std::numeric_limits<double>::infinity();
    for (const PointSource& s : sources.points) best = std::min(best, s.path + (s.origin - x).norm());
    for (const AreaSource& a : sources.areas)
        best = std::min(best, distance_to_polygon(x, a.polygon(), a.count, a.normal));
    return std::isfinite(best) ? best : 0.0;
}

}  // namespace tprf
