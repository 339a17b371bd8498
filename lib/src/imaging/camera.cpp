#include "tprf/imaging/camera.h"

#include "tprf/transport/illumination.h"
#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"

#include <flann/flann.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <variant>

namespace tprf {
namespace {

struct Hit {
    std::uint32_t pixel;
    std::uint32_t patch;
    Vec3 point;
    float leg;
};

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

CameraGather prepare_camera(const Camera& camera, const Scene& scene, const PatchSet& patches, const Visibility& vis,
                            const CameraOptions& options) {
    const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
    const std::size_t pixels = std::size_t(camera.width) * std::size_t(camera.height);
    const int spp = std::max(1, camera.spp);
    CameraGather g;
    g.width = camera.width;
    g.height = camera.height;

    // 1. Primary visibility: every sample that hits the front of a surface.
    std::vector<std::vector<Hit>> hits_by_row(std::size_t(camera.height));
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int r = 0; r < camera.height; ++r) {
        for (int c = 0; c < camera.width; ++c)
            for (int s = 0; s < spp; ++s) {
                double sx, sy;
                subpixel(s, spp, sx, sy);
                const Vec3 dir = camera_ray(camera, c + sx, r + sy);
                const RayHit h = vis.intersect(camera.position, dir, std::numeric_limits<double>::infinity());
                if (!h.hit || !h.front) continue;
                hits_by_row[std::size_t(r)].push_back({std::uint32_t(r * camera.width + c), h.patch, h.point,
                                                       camera.unwarp ? 0.0f : float(h.distance)});
            }
    }
    std::vector<Hit> hits;
    for (auto& row : hits_by_row) hits.insert(hits.end(), row.begin(), row.end());
    hits_by_row.clear();
    if (options.progress) options.progress("camera", 0.3);

    // 2. Neighbouring patches of each hit: one batched radius search wide enough for the largest
    //    kernel, each hit's own support (twice its patch's circumradius) applied after.
    const std::size_t n = patches.size();
    std::vector<double> radius(n);
    for (std::size_t i = 0; i < n; ++i) radius[i] = circumradius(patches, i);
    std::vector<std::vector<std::size_t>> found(hits.size());
    std::vector<std::vector<double>> found_d2(hits.size());
    if (!hits.empty()) {
        std::vector<double> xyz(3 * n), queries(3 * hits.size());
        for (std::size_t i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) xyz[3 * i + std::size_t(k)] = patches.centroid[i][k];
        for (std::size_t h = 0; h < hits.size(); ++h)
            for (int k = 0; k < 3; ++k) queries[3 * h + std::size_t(k)] = hits[h].point[k];
        flann::Matrix<double> points(xyz.data(), n, 3), query(queries.data(), hits.size(), 3);
        flann::Index<flann::L2_Simple<double>> index(points, flann::KDTreeSingleIndexParams(12));
        index.buildIndex();
        double support = 0.0;
        for (std::size_t h = 0; h < hits.size(); ++h) support = std::max(support, 2.0 * radius[hits[h].patch]);
        flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, 0.0f, false);
        params.cores = threads;
        index.radiusSearch(query, found, found_d2, float(support * support), params);
    }
    if (options.progress) options.progress("camera", 0.6);

    // 3. Taps (interpolated profiles) and exact direct light, per pixel.
    const std::vector<LaserSpot> spots = find_laser_spots(scene, patches, vis);
    std::vector<std::size_t> emissive;
    for (std::size_t i = 0; i < n; ++i)
        if ((patches.emission[i] > 0.0).any()) emissive.push_back(i);
    auto earliest_path = [&](const Vec3& x) {
        double best = std::numeric_limits<double>::infinity();
        for (const Light& light : scene.lights)
            if (const auto* point = std::get_if<PointLight>(&light)) best = std::min(best, (point->position - x).norm());
        for (const LaserSpot& spot : spots)
            if (spot.hit) best = std::min(best, spot.path + (spot.point - x).norm());
        for (std::size_t e : emissive) best = std::min(best, distance_to_polygon(x, patches.polygon(e), patches.corners(e), patches.normal[e]));
        return std::isfinite(best) ? best : 0.0;
    };
    const double per_sample = 1.0 / spp;
    std::vector<std::vector<PixelTap>> taps(pixels);
    std::vector<std::vector<DirectArrival>> direct(pixels);
#pragma omp parallel for schedule(dynamic, 256) num_threads(threads)
    for (std::size_t h = 0; h < hits.size(); ++h) {
        const Hit& hit = hits[h];
        const std::uint32_t p = hit.patch;
        const Vec3& np = patches.normal[p];
        // A smooth compact kernel (1 - (d/support)^2)^2 over the patches of the same surface: the
        // profile varies continuously across patch borders, so no faceting shows.
        const double support = 2.0 * radius[p];
        std::vector<std::pair<std::uint32_t, double>> weights;
        double total = 0.0;
        for (std::size_t k = 0; k < found[h].size(); ++k) {
            const std::size_t q = found[h][k];
            if (patches.object[q] != patches.object[p] || patches.normal[q].dot(np) < 0.7) continue;
            const double u = found_d2[h][k] / (support * support);
            if (u >= 1.0) continue;
            const double w = (1 - u) * (1 - u);
            weights.emplace_back(std::uint32_t(q), w);
            total += w;
        }
        if (total <= 0.0) {
            weights.assign(1, {p, 1.0});
            total = 1.0;
        }
        const float earliest = float(earliest_path(hit.point)) + hit.leg;
        std::vector<PixelTap>& out = taps[hit.pixel];
#pragma omp critical(camera_taps)
        for (const auto& [q, w] : weights) out.push_back({q, float(w / total * per_sample / M_PI), hit.leg, earliest});

        // Exact direct light at the visible point.
        const Rgb& albedo = patches.albedo[p];
        const Vec3 lifted = hit.point + vis.epsilon() * np;
        std::vector<DirectArrival> arrivals;
        auto add_point_source = [&](const Vec3& source, double path_offset, const Rgb& intensity_towards_x,
                                    std::uint8_t order) {
            const Vec3 d = source - hit.point;
            const double r = d.norm();
            const double cos_x = np.dot(d) / r;
            if (!(r > 0.0) || cos_x <= 0.0 || !(intensity_towards_x > 0.0).any()) return;
            if (vis.occluded(lifted, source)) return;
            arrivals.push_back({hit.pixel, path_offset + r + hit.leg,
                                albedo * intensity_towards_x * (cos_x / (r * r)) * (per_sample / M_PI), order});
        };
        for (const Light& light : scene.lights)
            if (const auto* point = std::get_if<PointLight>(&light)) add_point_source(point->position, 0.0, point->intensity, 1);
        for (std::size_t l = 0; l < spots.size(); ++l) {
            const LaserSpot& spot = spots[l];
            if (!spot.hit || spot.patch == p) continue;
            const Vec3& nx = patches.normal[spot.patch];
            const Vec3 source = spot.point + vis.epsilon() * nx;
            const Vec3 towards_x = (hit.point - source).normalized();
            const Rgb intensity = patches.albedo[spot.patch] * spot.power * std::max(0.0, nx.dot(towards_x)) / M_PI;
            add_point_source(source, spot.path, intensity, 2);
        }
        if (!arrivals.empty()) {
#pragma omp critical(camera_direct)
            direct[hit.pixel].insert(direct[hit.pixel].end(), arrivals.begin(), arrivals.end());
        }
    }

    // Order inside a pixel follows the threads' interleaving; sort so that results do not depend on it.
    g.row.assign(pixels + 1, 0);
    for (std::size_t px = 0; px < pixels; ++px) {
        std::sort(taps[px].begin(), taps[px].end(), [](const PixelTap& a, const PixelTap& b) {
            return a.patch != b.patch ? a.patch < b.patch : a.leg != b.leg ? a.leg < b.leg : a.weight < b.weight;
        });
        std::sort(direct[px].begin(), direct[px].end(), [](const DirectArrival& a, const DirectArrival& b) {
            return a.path != b.path ? a.path < b.path : a.radiance[0] < b.radiance[0];
        });
        g.row[px + 1] = g.row[px] + taps[px].size();
    }
    g.taps.reserve(g.row[pixels]);
    for (auto& t : taps) g.taps.insert(g.taps.end(), t.begin(), t.end());
    for (auto& d : direct) g.direct.insert(g.direct.end(), d.begin(), d.end());
    if (options.progress) options.progress("camera", 1.0);
    return g;
}

}  // namespace tprf
