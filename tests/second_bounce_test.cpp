// The second bounce read at each sample's own time (SecondBounceLight, camera.shift_second_bounce): the
// light it separates is exactly the solver's second bounce, and each pixel's second-bounce light
// arrives at the mean path its visible point has, as a quadrature over the other plane gives it.

#include "tprf/transport/second_bounce.h"

#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/imaging/camera.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/light_sources.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/solver.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

namespace tprf {
namespace {

// A two-plane corner: floor z = 0 (albedo 0.6) and wall x = 0 (albedo 0.5), 1 x 1 m, a point light,
// a camera at pixel centres (spp 1, no footprint) and per-order cubes.
const Vec3 kLight(0.6, 0.3, 0.7);

nlohmann::json corner(int bins, double bin_width, double max_edge, bool shift) {
    return {{"time", {{"bins", bins}, {"bin_width", bin_width}}},
            {"camera", {{"position", {1.6, 0.5, 0.6}}, {"look_at", {0.3, 0.5, 0.3}}, {"up", {0, 0, 1}}, {"fov", 60},
                        {"width", 24}, {"height", 20}, {"spp", 1}, {"footprint", false},
                        {"shift_second_bounce", shift}}},
            {"lights", {{{"type", "point"}, {"position", {kLight.x(), kLight.y(), kLight.z()}}, {"intensity", 1.0}}}},
            {"objects", {{{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", 0.6}},
                         {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {0, 1, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.5}}}},
            {"solver", {{"bounces", true}}},
            {"patches", {{"max_edge", max_edge}}}};
}

Scene corner_scene(int bins, double bin_width, double max_edge, bool shift) {
    return parse_scene(corner(bins, bin_width, max_edge, shift).dump(), "corner.json");
}

// The solver's second bounce (its order-2 term) of every patch and bin, (N, T, 3).
std::vector<float> solver_second_bounce(const PatchSet& patches, const LinkSet& links, const Illumination& light,
                                        const TimeAxis& time, DelayMode delay) {
    const std::size_t n = patches.size(), T = std::size_t(time.bins);
    SolverOptions options;
    options.delay = delay;
    options.bounce_terms = 4;
    std::vector<float> second(n * T * 3, 0.0f);
    solve_transient(patches, links, light, time, options, [&](const SolveBlock& b) {
        const float* term = b.per_order + 2 * n * std::size_t(b.bins) * 3;
        for (std::size_t i = 0; i < n; ++i)
            for (int t = 0; t < b.bins; ++t)
                if (b.first_bin + t >= 0 && b.first_bin + t < int(T))
                    for (int c = 0; c < 3; ++c)
                        second[(i * T + std::size_t(b.first_bin + t)) * 3 + std::size_t(c)] =
                            term[(i * std::size_t(b.bins) + std::size_t(t)) * 3 + std::size_t(c)];
    });
    return second;
}

// `set` with its patch-to-patch links only (the tree kept, clusters left without links).
LinkSet patch_links_only(const LinkSet& set) {
    LinkSet out;
    out.tree = set.tree;
    out.block_bins = set.block_bins;
    const Links& l = set.links;
    const std::size_t n = set.patches();
    out.links.row.assign(set.nodes() + 1, 0);
    for (std::size_t m = 0; m < set.nodes(); ++m) {
        for (std::uint64_t k = l.row[m]; k < l.row[m + 1]; ++k)
            if (m < n && l.source[k] < n) {
                out.links.source.push_back(l.source[k]);
                out.links.ff.push_back(l.ff[k]);
                out.links.distance.push_back(l.distance[k]);
            }
        out.links.row[m + 1] = out.links.source.size();
    }
    return out;
}

TEST(SecondBounceLight, HoldsExactlyTheSolversSecondBounce) {
    // Flat links: SecondBounceLight's light is the solver's whole second bounce. Hierarchical links: it
    // is what their patch-to-patch links carry (the solver's second bounce on those links alone), and
    // what cluster links bring stays in the profiles: nowhere more than the solver's whole second bounce.
    for (const LinkMethod method : {LinkMethod::Flat, LinkMethod::Hierarchical}) {
        const char* name = method == LinkMethod::Flat ? "flat" : "hierarchical";
        Scene scene = corner_scene(700, 0.005, 0.1, true);
        scene.links.method = method;
        scene.links.tolerance = 0.01;
        const PatchSet patches = build_patches(scene);
        const std::unique_ptr<Visibility> vis = scene_visibility(scene, patches);
        const LinkSet links = make_link_set(patches, *vis, scene.links, scene.time.bin_width_m());
        const LinkSet own = patch_links_only(links);
        if (method == LinkMethod::Hierarchical) {
            ASSERT_GT(links.tree.clusters(), 0u);
            ASSERT_LT(own.links.size(), links.links.size());  // cluster links exist
        }
        const LightSources sources = light_sources(scene, patches, *vis);
        const Illumination light = illuminate(sources, patches, *vis, {});
        const std::size_t n = patches.size(), T = std::size_t(scene.time.bins);
        for (const DelayMode delay : {DelayMode::Linear, DelayMode::Nearest}) {
            const char* mode = delay == DelayMode::Linear ? "linear" : "nearest";
            const std::vector<float> second = solver_second_bounce(patches, own, light, scene.time, delay);
            const std::vector<float> whole = solver_second_bounce(patches, links, light, scene.time, delay);
            const SecondBounceLight first(patches, links, light, scene.time, {.delay = delay});
            std::vector<float> rows(n * T * 3, 1.0f);  // fill overwrites every bin
            std::vector<char> lit;
            // In two pieces, as films ask for it: the first ends inside the second bounce's bins.
            first.fill({0, 300}, [](int order) { return order == 2; }, rows.data(), T * 3, lit);
            std::vector<float> tail(n * (T - 300) * 3);
            first.fill({300, T - 300}, [](int order) { return order == 2; }, tail.data(), (T - 300) * 3, lit);
            for (std::size_t i = 0; i < n; ++i)
                std::copy_n(tail.data() + i * (T - 300) * 3, (T - 300) * 3, rows.data() + (i * T + 300) * 3);
            double peak = 0.0, worst = 0.0, total = 0.0, above = 0.0, total_whole = 0.0;
            for (float v : second) peak = std::max(peak, double(v));
            for (std::size_t k = 0; k < second.size(); ++k) {
                worst = std::max(worst, std::abs(double(rows[k]) - double(second[k])));
                above = std::max(above, double(rows[k]) - double(whole[k]));
                total += second[k];
                total_whole += whole[k];
            }
            std::printf("%s, %s: patch links carry %.4f of the second bounce\n", name, mode, total / total_whole);
            ASSERT_GT(peak, 0.0);
            EXPECT_GT(total, 0.0);
            // The same sums in float, in another order: rounding only.
            EXPECT_LT(worst, 1e-5 * peak) << name << ", " << mode;
            EXPECT_LT(above, 1e-5 * peak) << name << ", " << mode;
            if (method == LinkMethod::Flat) {
                EXPECT_NEAR(total, total_whole, 1e-5 * total_whole) << mode;
            } else {
                EXPECT_LT(total, (1.0 - 1e-3) * total_whole) << mode;  // the cluster links' share stays apart
            }
            // Other orders are not first-link light: order 1 (the pulses themselves) and order 3 give nothing.
            first.fill({0, T}, [](int order) { return order != 2; }, rows.data(), T * 3, lit);
            EXPECT_EQ(*std::max_element(rows.begin(), rows.end()), 0.0f);
            EXPECT_EQ(std::count(lit.begin(), lit.end(), 1), 0);
        }
    }
}

// Each pixel's second-bounce light, as the render's transient_bounce_2 cube holds it: its mean path
// (bin centres), against the quadrature of its visible point's second bounce over the other plane
// (the point light's irradiance times the kernel cos cos / (pi r^2)), plus the camera leg.
struct MeanPaths {
    std::vector<double> error;  // metres, per pixel that sees the corner
    std::vector<double> light;  // per pixel: the whole cube's light (every order), summed over time
};

MeanPaths second_bounce_paths(bool shift, double bin_width, double max_edge) {
    const int bins = int(std::ceil(5.0 / bin_width));
    const Scene scene = corner_scene(bins, bin_width, max_edge, shift);
    RenderOptions options;
    options.threads = 2;
    const RenderResult r = render_scene(scene, options);
    EXPECT_NE(r.record.find(shift ? "\"second_bounce_shifted\": true" : "\"second_bounce_shifted\": false"),
              std::string::npos);
    const FloatArray& cube = r.arrays.at("transient_bounce_2");
    const PatchSet patches = build_patches(scene);
    const Visibility vis(patches);
    const Camera& cam = *scene.camera;
    MeanPaths out;
    const FloatArray& all = r.arrays.at("transient");
    for (std::size_t px = 0; px < all.data.size() / (std::size_t(bins) * 3); ++px) {
        double sum = 0.0;
        for (std::size_t k = px * std::size_t(bins) * 3; k < (px + 1) * std::size_t(bins) * 3; ++k) sum += all.data[k];
        out.light.push_back(sum);
    }
    constexpr int kCells = 200;  // midpoint rule over the other plane
    for (int row = 0; row < cam.height; ++row)
        for (int col = 0; col < cam.width; ++col) {
            const RayHit h = vis.intersect(cam.position, camera_ray(cam, col + 0.5, row + 0.5), 1e30);
            if (!h.hit || !h.front) continue;
            const Vec3 x = h.point;
            const bool floor = std::abs(x.z()) < 1e-6;
            const Vec3 nx = floor ? Vec3::UnitZ() : Vec3::UnitX();
            const Vec3 ny = floor ? Vec3::UnitX() : Vec3::UnitZ();
            double weight = 0.0, moment = 0.0;
            for (int a = 0; a < kCells; ++a)
                for (int b = 0; b < kCells; ++b) {
                    const double u = (a + 0.5) / kCells, v = (b + 0.5) / kCells;
                    const Vec3 y = floor ? Vec3(0.0, u, v) : Vec3(u, v, 0.0);
                    const Vec3 to_light = kLight - y, to_x = x - y;
                    const double rl = to_light.norm(), rx = to_x.norm();
                    const double irradiance = std::max(0.0, ny.dot(to_light)) / (rl * rl * rl);
                    const double kernel = std::max(0.0, ny.dot(to_x)) * std::max(0.0, -nx.dot(to_x)) /
                                          (std::numbers::pi * rx * rx * rx * rx);
                    const double w = irradiance * kernel;
                    weight += w;
                    moment += w * (rl + rx);
                }
            const double expected = moment / weight + h.distance;
            const float* p = cube.data.data() + (std::size_t(row) * std::size_t(cam.width) + std::size_t(col)) * std::size_t(bins) * 3;
            double sum = 0.0, first = 0.0;
            for (int t = 0; t < bins; ++t) {
                sum += p[std::size_t(t) * 3];
                first += p[std::size_t(t) * 3] * (t + 0.5) * bin_width;
            }
            if (!(sum > 0.0)) continue;
            out.error.push_back(first / sum - expected);
        }
    return out;
}

double quantile(std::vector<double> v, double q) {
    for (double& e : v) e = std::abs(e);
    std::sort(v.begin(), v.end());
    return v[std::size_t(q * double(v.size() - 1))];
}

TEST(SecondBounceLight, PixelsSeeTheSecondBounceAtTheirOwnPointsMeanPath) {
    // Patches of 0.1 m (circumradius 71 mm): read at their centroid's time, a pixel's second bounce is
    // off by its sender-weighted |x - c_j| - |c_k - c_j|, up to a few cm. Read with the shift to second
    // order, what is left is the senders' own discretisation (their light weighed at centroids). At
    // 0.05 m patches both fall about 3.3 times (median 1.15 and 0.16 mm), and neither depends on the
    // bins (1 mm bins give the same to 0.02 mm).
    const double bin = 0.002, edge = 0.1;
    const MeanPaths centroid = second_bounce_paths(false, bin, edge);
    const MeanPaths shifted = second_bounce_paths(true, bin, edge);
    ASSERT_EQ(centroid.error.size(), shifted.error.size());
    ASSERT_GT(shifted.error.size(), 200u);
    double c[3], s[3];
    const double q[3] = {0.5, 0.9, 1.0};
    for (int k = 0; k < 3; ++k) {
        c[k] = quantile(centroid.error, q[k]);
        s[k] = quantile(shifted.error, q[k]);
        std::printf("mean path error, quantile %.1f: centroid %.2f mm, shifted %.2f mm\n", q[k], 1e3 * c[k], 1e3 * s[k]);
    }
    // Measured: median 3.74 -> 0.55 mm, p90 10.4 -> 2.3 mm, worst 26 -> 6.1 mm.
    EXPECT_GT(c[0], 0.002);      // the error the shift is for is there: 2% of the patch edge
    EXPECT_LT(s[0], 0.01 * edge);  // 1% of the patch edge
    EXPECT_LT(s[1], 0.03 * edge);
    EXPECT_LT(s[0], c[0] / 4);
    EXPECT_LT(s[1], c[1] / 3);
    EXPECT_LT(s[2], c[2] / 3);
    // Only the timing moves: each pixel's light over time is the same.
    ASSERT_EQ(centroid.light.size(), shifted.light.size());
    const double peak = *std::max_element(centroid.light.begin(), centroid.light.end());
    for (std::size_t px = 0; px < centroid.light.size(); ++px)
        EXPECT_NEAR(shifted.light[px], centroid.light[px], 1e-5 * peak) << "pixel " << px;
}

}  // namespace
}  // namespace tprf
