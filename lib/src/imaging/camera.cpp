#include "tprf/imaging/camera.h"

#include "tprf/core/parallel.h"
#include "tprf/core/random.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace tprf {
namespace {

// Sub-pixel offsets: a g x g grid when spp is a square (spp = 1: the pixel centre, docs/scene.md),
// else the R2 low-discrepancy sequence, which stratifies any count.
void subpixel(int s, int spp, double& sx, double& sy) {
    const int g = int(std::lround(std::sqrt(double(spp))));
    if (g * g == spp) {
        sx = (s % g + 0.5) / g;
        sy = (s / g + 0.5) / g;
        return;
    }
    r2_point(double(s + 1), sx, sy);
}

}  // namespace

namespace {

// A sample's ray: its unnormalised direction from the camera and how that changes per column and per
// row (for the sample's cell on the surface).
struct PixelRay {
    Vec3 towards, per_column, per_row;
};

// The pinhole's frame and intrinsics: the unnormalised direction through the image position (column,
// row) in pixels (0, 0 the top-left corner of the image, so that pixel (c, r)'s centre is at (c + 0.5,
// r + 0.5), OpenCV's (c, r)) is forward + x right - y up, where (x, y) are the normalised coordinates
// that the distortion carries to ((column - 0.5 - cx) / fx, (row - 0.5 - cy) / fy): y points down.
struct Pinhole {
    Vec3 forward, right, up;
    Intrinsics k;
    Distortion distortion;

    explicit Pinhole(const Camera& camera) : k(camera.pinhole()), distortion(camera.distortion) {
        forward = (camera.look_at - camera.position).normalized();
        right = forward.cross(camera.up).normalized();
        up = right.cross(forward);
        if (camera.mirrored) right = -right;  // column 0 on the right
    }
    // The ray through (column, row); none where the distortion has no undistorted point for it.
    std::optional<PixelRay> ray(double column, double row) const {
        const Vec2 distorted((column - 0.5 - k.cx) / k.fx, (row - 0.5 - k.cy) / k.fy);
        const std::optional<Vec2> xy = distortion.undo(distorted);
        if (!xy) return std::nullopt;
        // d(x, y) / d(column, row): the inverse of the distortion's Jacobian, over the focal lengths.
        const Eigen::Matrix2d inverse =
            distortion.none() ? Eigen::Matrix2d(Eigen::Matrix2d::Identity()) : Eigen::Matrix2d(distortion.jacobian(*xy).inverse());
        const Vec2 per_column = inverse.col(0) / k.fx, per_row = inverse.col(1) / k.fy;
        return PixelRay{forward + xy->x() * right - xy->y() * up, per_column.x() * right - per_column.y() * up,
                        per_row.x() * right - per_row.y() * up};
    }
};

// Where a sample's ray ends: its unnormalised direction from the camera, the reflections `turn` it took,
// its unfolded path and the normal n of the surface it reaches.
struct RayEnd {
    const Vec3& direction;
    const Eigen::Matrix3d& turn;
    double path;
    const Vec3& n;
};

// Half-axes of a sample's cell (half_px pixels either side of it) on the surface it reaches: ray
// differentials through the reflections, onto the plane of normal n at distance `path` along the
// unfolded ray (first order; a cell that meets the plane almost edge-on is capped at 100 times the
// cell's width across the ray, rather than spread to infinity).
void cell_on_surface(const PixelRay& ray, const RayEnd& end, double half_px, SensingPoint& sp) {
    const Vec3& direction = end.direction;
    const Eigen::Matrix3d& turn = end.turn;
    const double path = end.path;
    const Vec3& n = end.n;
    const Vec3 d = turn * direction;  // unnormalised, unfolded
    const double s = path / direction.norm(), nd = n.dot(d);
    const auto on_surface = [&](const Vec3& change) {
        const Vec3 across = s * (turn * change) * half_px;
        const Vec3 along = -d * (n.dot(across) / nd);
        const double cap = 100.0 * across.norm();
        return std::abs(nd) > 0.0 && along.norm() <= cap ? Vec3(across + along) : Vec3(across);
    };
    const Vec3 du = on_surface(ray.per_column), dv = on_surface(ray.per_row);
    sp.du = du.cast<float>();
    sp.dv = dv.cast<float>();
    if (sp.leg > 0.0f) {  // the leg |x - camera'| changes by the unit direction's component along the axis
        const Vec3 unit = d.normalized();
        sp.leg_du = float(unit.dot(du));
        sp.leg_dv = float(unit.dot(dv));
    }
}

// What a pixel's samples are taken with: the camera and its pinhole frame, the scene, the samples per
// pixel and each one's half share of the pixel's side.
struct Sampler {
    const Camera& camera;
    const Pinhole& pin;
    const PatchSet& patches;
    const Visibility& vis;
    int spp;
    double half_px;
};

// Pixel (c, r)'s samples in a scene without mirrors or glass, a packet of rays at a time (they leave
// one point nearly together): each reaches at most one surface, kept when it meets its front.
void straight_samples(const Sampler& sampler, int r, int c, std::vector<SensingPoint>& out) {
    const Camera& camera = sampler.camera;
    const Pinhole& pin = sampler.pin;
    const int spp = sampler.spp;
    const std::uint32_t pixel = std::uint32_t(r * camera.width + c);
    static const Eigen::Matrix3d straight = Eigen::Matrix3d::Identity();
    for (int s0 = 0; s0 < spp; s0 += Visibility::kBatch) {
        const int count = std::min(Visibility::kBatch, spp - s0);
        PixelRay rays[Visibility::kBatch];
        Vec3 dir[Visibility::kBatch];
        bool seen[Visibility::kBatch];
        for (int k = 0; k < count; ++k) {
            double sx, sy;
            subpixel(s0 + k, spp, sx, sy);
            const std::optional<PixelRay> ray = pin.ray(c + sx, double(r) + sy);
            seen[k] = bool(ray);
            rays[k] = ray.value_or(PixelRay{pin.forward, Vec3::Zero(), Vec3::Zero()});
            dir[k] = rays[k].towards.normalized();
        }
        RayHit hits[Visibility::kBatch];
        sampler.vis.intersect_from(camera.position, dir, count, std::numeric_limits<double>::infinity(), hits);
        for (int k = 0; k < count; ++k) {
            const RayHit& h = hits[k];
            if (!seen[k] || !h.hit || !h.front) continue;
            SensingPoint& sp =
                out.emplace_back(SensingPoint{pixel, h.patch, h.point, camera.unwarp ? 0.0f : float(h.distance)});
            sp.view = (-dir[k]).cast<float>();
            if (camera.footprint)
                cell_on_surface(rays[k], {rays[k].towards, straight, h.distance, sampler.patches.normal[h.patch]},
                                sampler.half_px, sp);
        }
    }
}

}  // namespace

Vec3 camera_ray(const Camera& camera, double column, double row) {
    const std::optional<PixelRay> ray = Pinhole(camera).ray(column, row);
    return ray ? Vec3(ray->towards.normalized()) : Vec3(Vec3::Zero());
}

SensingPoints pinhole_points(const Camera& camera, const PatchSet& patches, const Visibility& vis, int threads) {
    const int spp = std::max(1, camera.spp);
    const Pinhole pin(camera);
    const double half_px = 0.5 / std::sqrt(double(spp));  // a sample's share of the pixel, as a square
    std::vector<std::vector<SensingPoint>> by_row(std::size_t(camera.height));
    std::vector<std::vector<Rgb>> row_tints(std::size_t(camera.height));  // per point, with mirrors
    const bool specular = !vis.planes().empty();
    parallel_for(std::size_t(camera.height), {threads, 1, true}, [&](std::size_t r) {
        std::vector<TracedHit> hits;
        by_row[r].reserve(std::size_t(camera.width) * std::size_t(spp));
        for (int c = 0; c < camera.width; ++c) {
            if (!specular) {
                straight_samples({camera, pin, patches, vis, spp, half_px}, int(r), c, by_row[r]);
                continue;
            }
            const std::uint32_t pixel = std::uint32_t(int(r) * camera.width + c);
            for (int s = 0; s < spp; ++s) {
                double sx, sy;
                subpixel(s, spp, sx, sy);
                const std::optional<PixelRay> ray = pin.ray(c + sx, double(r) + sy);
                if (!ray) continue;
                const Vec3& towards = ray->towards;
                const Vec3 dir = towards.normalized();
                // Into mirrors and through glass: every diffuse front side the ray reaches, with its
                // whole path and the specular weight of the way.
                hits.clear();
                vis.trace(camera.position, dir, hits);
                for (const TracedHit& t : hits) {
                    if (!t.hit.front) continue;
                    SensingPoint& sp = by_row[r].emplace_back(SensingPoint{
                        pixel, t.hit.patch, t.hit.point, camera.unwarp ? 0.0f : float(t.path), float(t.weight)});
                    sp.view = (-(t.turn * dir)).normalized().cast<float>();
                    if (camera.footprint)
                        cell_on_surface(*ray, {towards, t.turn, t.path, patches.normal[t.hit.patch]}, half_px, sp);
                    row_tints[r].push_back(t.tint);
                }
            }
        }
    });
    SensingPoints points;
    points.outputs = std::size_t(camera.width) * std::size_t(camera.height);
    points.weight = 1.0 / spp;
    std::size_t total = 0;
    for (const auto& row : by_row) total += row.size();
    points.points.reserve(total);
    for (std::size_t r = 0; r < by_row.size(); ++r) {
        // Tinted mirrors' palette, in row order (the same for any thread count).
        for (std::size_t k = 0; k < row_tints[r].size(); ++k) by_row[r][k].tint = points.tint_index(row_tints[r][k]);
        points.points.insert(points.points.end(), by_row[r].begin(), by_row[r].end());
    }
    return points;
}

Gather prepare_camera(const Camera& camera, const PatchSet& patches, const LightSources& sources,
                      const Visibility& visibility, const GatherOptions& options) {
    const SensingPoints points = pinhole_points(camera, patches, visibility, options.threads);
    if (options.progress) options.progress("camera", 0.3);
    return gather_points(points, camera.width, camera.height, {patches, sources, visibility}, options);
}

}  // namespace tprf
