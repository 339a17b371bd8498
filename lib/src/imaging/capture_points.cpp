#include "tprf/imaging/capture_points.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/scene/scene.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace tprf {
namespace {

std::string show(const Vec3& v) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "(%.6g, %.6g, %.6g)", v.x(), v.y(), v.z());
    return buf;
}

std::string show_metres(double m) {
    char buf[48];
    std::snprintf(buf, sizeof buf, "%.3g m", m);
    return buf;
}

// One grid and the device that aims at it, with where errors point.
struct GridRequest {
    const CaptureGrid& grid;
    const Vec3& device;
    const char* device_name;   // "laser" or "sensor"
    std::string grid_path;     // capture.grid or capture.sensor_grid
    std::string device_path;   // capture.laser.position or capture.sensor.position
};

// Point (a, b) of the grid as its device sees it: the first surface along the line from the device
// must be the front of a surface through the point.
WallPoint locate(const Scene& scene, const PatchSet& patches, const Visibility& visibility, const GridRequest& r,
                 int a, int b) {
    const Vec3 target = r.grid.point(a, b);
    const Vec3 d = target - r.device;
    const double dist = d.norm();
    const std::string where = "point (" + std::to_string(a) + ", " + std::to_string(b) + ") at " + show(target);
    if (!(dist > 10.0 * visibility.epsilon()))
        fail_input(scene.file, r.device_path, std::string("lies on grid ") + where + "; the " + r.device_name +
                                                   " must stand in front of the wall");
    // Embree's rays are single precision: a point on the surface is met within a few epsilons.
    const double tolerance = 10.0 * visibility.epsilon() + 1e-6 * dist;
    RayHit hit = visibility.intersect(r.device, d / dist, dist + tolerance);
    // A ray at a corner shared by patches can slip between them in single precision: a point that
    // lies on a surface is met by rays aimed a hair beside it.
    const Vec3 across[4] = {r.grid.u.normalized(), -r.grid.u.normalized(), r.grid.v.normalized(),
                            -r.grid.v.normalized()};
    for (int k = 0; k < 4 && !hit.hit; ++k) {
        const Vec3 aside = target + 0.5 * tolerance * across[k] - r.device;
        hit = visibility.intersect(r.device, aside.normalized(), aside.norm() + tolerance);
    }
    if (!hit.hit)
        fail_input(scene.file, r.grid_path, where + " lies on no surface: the line from the " + r.device_name +
                                                " at " + show(r.device) + " meets nothing there");
    const std::string object = "objects[" + std::to_string(patches.object[hit.patch]) + "]";
    if (hit.distance < dist - tolerance) {
        if (!hit.front)
            fail_input(scene.file, r.device_path,
                       show(r.device) + " is inside or behind " + object + ": the line to grid " + where +
                           " meets the back of its surface " + show_metres(hit.distance) + " from the " +
                           r.device_name);
        fail_input(scene.file, r.grid_path,
                   where + " is hidden from the " + r.device_name + " at " + show(r.device) + " by " + object + ", " +
                       show_metres(dist - hit.distance) + " before the point");
    }
    if (!hit.front)
        fail_input(scene.file, r.device_path,
                   show(r.device) + " is behind " + object + ": the " + r.device_name + " sees grid " + where +
                       " on the back of its surface (one-sided: its front is where the normal points)");
    WallPoint w;
    w.point = target;
    w.normal = patches.normal[hit.patch];
    w.patch = hit.patch;
    w.device_leg = dist;
    return w;
}

std::vector<WallPoint> locate_grid(const Scene& scene, const PatchSet& patches, const Visibility& visibility,
                                   const GridRequest& r) {
    std::vector<WallPoint> out;
    out.reserve(r.grid.size());
    for (int a = 0; a < r.grid.nu; ++a)
        for (int b = 0; b < r.grid.nv; ++b) out.push_back(locate(scene, patches, visibility, r, a, b));
    return out;
}

}  // namespace

CapturePoints locate_capture_points(const Scene& scene, const PatchSet& patches, const Visibility& visibility) {
    TPRF_CHECK(scene.capture.has_value());
    const Capture& c = *scene.capture;
    const std::string at = c.json_path;
    CapturePoints points;
    points.laser = locate_grid(scene, patches, visibility,
                               {c.laser_grid, c.laser_position, "laser", at + "." + c.laser_grid_key,
                                at + ".laser.position"});
    if (c.type == CaptureType::Confocal && c.sensor_position == c.laser_position) {
        points.sensor = points.laser;
        return points;
    }
    points.sensor = locate_grid(scene, patches, visibility,
                                {c.sensor_grid, c.sensor_position, "sensor", at + "." + c.sensor_grid_key,
                                 at + ".sensor.position"});
    return points;
}

std::int64_t grid_cell(const CaptureGrid& grid, const Vec3& x, double tolerance) {
    const Vec3 n = grid.u.cross(grid.v);
    const Vec3 d = x - grid.origin;
    if (std::abs(d.dot(n.normalized())) > tolerance) return -1;
    // x - origin = alpha u + beta v in the grid's plane (u and v need not be orthogonal).
    const double uu = grid.u.dot(grid.u), uv = grid.u.dot(grid.v), vv = grid.v.dot(grid.v);
    const double du = d.dot(grid.u), dv = d.dot(grid.v), det = uu * vv - uv * uv;
    const double alpha = (du * vv - dv * uv) / det, beta = (dv * uu - du * uv) / det;
    const double a = std::floor(alpha * grid.nu), b = std::floor(beta * grid.nv);
    if (a < 0 || b < 0 || a >= grid.nu || b >= grid.nv) return -1;
    return std::int64_t(a) * grid.nv + std::int64_t(b);
}

}  // namespace tprf
