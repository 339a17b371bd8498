#include "tprf/imaging/camera.h"

#include "tprf/core/parallel.h"
#include "tprf/geometry/visibility.h"

#include <cmath>
#include <limits>

namespace tprf {
namespace {

// Sub-pixel offsets: a g x g grid when spp is a square (spp = 1: the pixel centre, as SPEC says),
// else the R2 low-discrepancy sequence, which stratifies any count.
void subpixel(int s, int spp, double& sx, double& sy) {
    const int g = int(std::lround(std::sqrt(double(spp))));
    if (g * g == spp) {
        sx = (s % g + 0.5) / g;
        sy = (s / g + 0.5) / g;
        return;
    }
    const double a1 = 0.7548776662466927, a2 = 0.5698402909980532;  // 1/phi2, 1/phi2^2
    sx = std::fmod(0.5 + a1 * (s + 1), 1.0);
    sy = std::fmod(0.5 + a2 * (s + 1), 1.0);
}

}  // namespace

Vec3 camera_ray(const Camera& camera, double column, double row) {
    const Vec3 forward = (camera.look_at - camera.position).normalized();
    const Vec3 right = forward.cross(camera.up).normalized();
    const Vec3 up = right.cross(forward);
    const double tan_half = std::tan(0.5 * camera.fov_deg * M_PI / 180.0);
    const double aspect = double(camera.width) / double(camera.height);
    const double x = (2.0 * column / camera.width - 1.0) * tan_half * aspect;
    const double y = (1.0 - 2.0 * row / camera.height) * tan_half;
    return (forward + x * right + y * up).normalized();
}

SensingPoints pinhole_points(const Camera& camera, const Visibility& vis, int threads) {
    const int spp = std::max(1, camera.spp);
    std::vector<std::vector<SensingPoint>> by_row(std::size_t(camera.height));
    std::vector<std::vector<Rgb>> row_tints(std::size_t(camera.height));  // per point, with mirrors
    const bool specular = !vis.planes().empty();
    parallel_for(std::size_t(camera.height), {threads, 1, true}, [&](std::size_t r) {
        std::vector<TracedHit> hits;
        for (int c = 0; c < camera.width; ++c)
            for (int s = 0; s < spp; ++s) {
                double sx, sy;
                subpixel(s, spp, sx, sy);
                const Vec3 dir = camera_ray(camera, c + sx, double(r) + sy);
                const std::uint32_t pixel = std::uint32_t(int(r) * camera.width + c);
                if (!specular) {
                    const RayHit h = vis.intersect(camera.position, dir, std::numeric_limits<double>::infinity());
                    if (!h.hit || !h.front) continue;
                    by_row[r].push_back({pixel, h.patch, h.point, camera.unwarp ? 0.0f : float(h.distance)});
                    continue;
                }
                // Into mirrors and through glass: every diffuse front side the ray reaches, with its
                // whole path and the specular weight of the way.
                hits.clear();
                vis.trace(camera.position, dir, hits);
                for (const TracedHit& t : hits) {
                    if (!t.hit.front) continue;
                    by_row[r].push_back({pixel, t.hit.patch, t.hit.point, camera.unwarp ? 0.0f : float(t.path),
                                         float(t.weight)});
                    row_tints[r].push_back(t.tint);
                }
            }
    });
    SensingPoints points;
    points.outputs = std::size_t(camera.width) * std::size_t(camera.height);
    points.weight = 1.0 / spp;
    for (std::size_t r = 0; r < by_row.size(); ++r) {
        // Tinted mirrors' palette, in row order (the same for any thread count).
        for (std::size_t k = 0; k < row_tints[r].size(); ++k) by_row[r][k].tint = points.tint_index(row_tints[r][k]);
        points.points.insert(points.points.end(), by_row[r].begin(), by_row[r].end());
    }
    return points;
}

Gather prepare_camera(const Camera& camera, const PatchSet& patches, const LightSources& sources,
                      const Visibility& visibility, const GatherOptions& options) {
    const SensingPoints points = pinhole_points(camera, visibility, options.threads);
    if (options.progress) options.progress("camera", 0.3);
    return gather_points(points, camera.width, camera.height, patches, sources, visibility, options);
}

}  // namespace tprf
