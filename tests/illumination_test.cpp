// Area sources: emissive polygons whose first bounce is integrated per receiving patch
// (transport/illumination.h), checked against closed forms with and without a shadow.

#include "tprf/transport/illumination.h"

#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/light_sources.h"

#include "test_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace tprf {
namespace {

// Total order-1 energy of patch i's pulses, first channel.
double first_bounce(const Illumination& e, std::size_t i) {
    double sum = 0.0;
    for (std::uint64_t k = e.row[i]; k < e.row[i + 1]; ++k)
        if (e.pulses[k].order == 1) sum += e.pulses[k].energy[0];
    return sum;
}

// Mean over patch i (an axis-aligned floor square) of f(x, y), by an m x m midpoint rule.
template <class F>
double patch_mean(const PatchSet& patches, std::size_t i, F f, int m = 200) {
    const Vec3* p = patches.polygon(i);
    double x0 = p[0].x(), x1 = x0, y0 = p[0].y(), y1 = y0;
    for (std::size_t k = 1; k < patches.corners(i); ++k) {
        x0 = std::min(x0, p[k].x());
        x1 = std::max(x1, p[k].x());
        y0 = std::min(y0, p[k].y());
        y1 = std::max(y1, p[k].y());
    }
    double sum = 0.0;
    for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b) sum += f(x0 + (x1 - x0) * (a + 0.5) / m, y0 + (y1 - y0) * (b + 0.5) / m);
    return sum / (double(m) * m);
}

TEST(AreaSources, AnEmissiveRectangleIsOneSourcePerSideHoweverFinelyItIsCut) {
    for (double max_edge : {1.0, 0.1, 0.03}) {
        Scene scene;
        scene.max_edge = max_edge;
        Object light = test::rectangle(Vec3(0, 0, 1), Vec3(0, 0.4, 0), Vec3(0.3, 0, 0), 0.5, 2.0);
        light.two_sided = true;
        scene.objects.push_back(light);
        scene.objects.push_back(test::rectangle(Vec3(-1, -1, 0), Vec3(2, 0, 0), Vec3(0, 2, 0)));
        const PatchSet patches = build_patches(scene);
        const std::vector<AreaSource> areas = area_sources(&scene, patches);
        ASSERT_EQ(areas.size(), 2u) << max_edge;
        for (const AreaSource& a : areas) {
            EXPECT_EQ(a.count, 4);
            EXPECT_NEAR(polygon_area(a.polygon(), a.count), 0.12, 1e-12);
            EXPECT_NEAR((a.centroid - Vec3(0.15, 0.2, 1)).norm(), 0.0, 1e-12);
            EXPECT_EQ(a.radiance[0], 2.0);
            EXPECT_EQ(a.object, 0u);
        }
        EXPECT_NEAR(areas[0].normal.z(), -1.0, 1e-12);  // u x v of the front points down
        EXPECT_NEAR(areas[1].normal.z(), 1.0, 1e-12);
        // Without the scene, each emissive patch is a source of its own.
        std::size_t emissive = 0;
        for (const Rgb& e : patches.emission) emissive += (e > 0.0).any();
        EXPECT_EQ(area_sources(nullptr, patches).size(), emissive);
    }
}

// A 0.5 m square emitter (L_e = 1) facing down at z = 1 over a 1 m floor of albedo 1; with `blocker`,
// an opaque plate at z = 0.5 over x < 0. The segment from a floor point (px, py, 0) to an emitter point
// (ex, ey, 1) crosses z = 0.5 at x = (px + ex) / 2, so the plate hides exactly the emitter's part with
// ex < -px: what the point sees is a rectangle, and Howell's B-3 gives its form factor in closed form.
struct ShadowScene {
    Scene scene;
    PatchSet patches;
    explicit ShadowScene(bool blocker) {
        scene.max_edge = 0.1;
        scene.objects.reserve(3);  // no reallocation: GCC 12 warns (-Wrestrict, a false positive) on its string moves
        scene.objects.push_back(test::rectangle(Vec3(-0.5, -0.5, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), 1.0));
        scene.objects.push_back(test::rectangle(Vec3(-0.25, -0.25, 1), Vec3(0, 0.5, 0), Vec3(0.5, 0, 0), 0.0, 1.0));
        if (blocker) {
            Object plate = test::rectangle(Vec3(-2, -2, 0.5), Vec3(2, 0, 0), Vec3(0, 4, 0), 0.0);
            plate.two_sided = true;
            scene.objects.push_back(plate);
        }
        patches = build_patches(scene);
    }
    // The exact first bounce of floor patch i: albedo pi L_e times the patch mean of the visible form factor.
    double exact(std::size_t i, bool blocker) const {
        return M_PI * patch_mean(patches, i, [&](double px, double py) {
                   const double from = blocker ? std::max(-0.25, -px) : -0.25;
                   return from < 0.25 ? test::ff_point_to_parallel_rectangle(px, py, from, 0.25, -0.25, 0.25, 1.0) : 0.0;
               });
    }
    Illumination lit(const IlluminationOptions& options = {}) const {
        const Visibility vis(patches);
        return illuminate(light_sources(scene, patches, vis), patches, vis, options);
    }
};

TEST(AreaSources, UnshadowedFloorGetsTheClosedFormToTheEmitter) {
    const ShadowScene s(false);
    const Illumination e = s.lit();
    double worst = 0.0;
    for (std::size_t i = 0; i < s.patches.size(); ++i) {
        if (s.patches.object[i] != 0) continue;
        const double exact = s.exact(i, false);
        worst = std::max(worst, std::abs(first_bounce(e, i) / exact - 1));
    }
    MEASURED("unshadowed floor: worst relative error %.2e\n", worst);
    // Lambert's contour integral is exact per point; the patch mean is adaptive to 1e-3 per cell, with
    // Richardson's step (measured 2e-6 here).
    EXPECT_LT(worst, 1e-4);
}

TEST(AreaSources, PenumbraConvergesToTheClosedFormOfTheVisiblePart) {
    const ShadowScene s(true);
    IlluminationOptions fine;
    fine.area_samples = 64;
    fine.emitter_rays = 1024;
    fine.penumbra_rays = 1024;
    const Illumination coarse = s.lit(), refined = s.lit(fine);
    double worst_default = 0.0, worst_fine = 0.0, lit_sum = 0.0, exact_sum = 0.0;
    int penumbra = 0, umbra = 0;
    for (std::size_t i = 0; i < s.patches.size(); ++i) {
        if (s.patches.object[i] != 0) continue;
        const double exact = s.exact(i, true), full = s.exact(i, false);
        lit_sum += s.patches.area[i] * first_bounce(coarse, i);
        exact_sum += s.patches.area[i] * exact;
        if (exact == 0.0) {
            // Umbra: every ray blocked, no light at all.
            EXPECT_EQ(first_bounce(coarse, i), 0.0) << i;
            ++umbra;
            continue;
        }
        if (exact < 0.999 * full) ++penumbra;
        // Errors relative to the unshadowed light, so that a sliver of penumbra is not a large ratio.
        worst_default = std::max(worst_default, std::abs(first_bounce(coarse, i) - exact) / full);
        worst_fine = std::max(worst_fine, std::abs(first_bounce(refined, i) - exact) / full);
    }
    MEASURED("penumbra: %d patches (%d umbra), worst error / unshadowed light: default %.2e, 8x8 points and "
             "32x32 cells %.2e; total %.2e\n", penumbra, umbra, worst_default, worst_fine, lit_sum / exact_sum - 1);
    EXPECT_GE(penumbra, 40);  // the columns of patches with -0.25 < px < 0.25
    EXPECT_GE(umbra, 20);
    // A receiver point's shadow edge falls inside one of 16 columns of cells: up to 1/32 of the light.
    EXPECT_LT(worst_default, 0.03);
    EXPECT_LT(worst_fine, 0.25 * worst_default);  // it converges
    EXPECT_NEAR(lit_sum / exact_sum, 1.0, 0.005);
}

TEST(AreaSources, PulsesLieBetweenTheShortestAndLongestPathsOnePerBin) {
    const ShadowScene s(false);
    const TimeAxis time = test::time_axis(200, 0.01);
    IlluminationOptions options;
    options.merge_bins = &time;
    const Illumination merged = s.lit(options), unmerged = s.lit();
    for (std::size_t i = 0; i < s.patches.size(); ++i) {
        if (s.patches.object[i] != 0) continue;
        double nearest = 1e9, farthest = 0.0;
        for (const Vec3& y : {Vec3(-0.25, -0.25, 1), Vec3(0.25, -0.25, 1), Vec3(0.25, 0.25, 1), Vec3(-0.25, 0.25, 1)})
            for (std::size_t k = 0; k < s.patches.corners(i); ++k) farthest = std::max(farthest, (y - s.patches.polygon(i)[k]).norm());
        for (std::size_t k = 0; k < s.patches.corners(i); ++k) {
            const Vec3& x = s.patches.polygon(i)[k];
            nearest = std::min(nearest, Vec3(std::clamp(x.x(), -0.25, 0.25) - x.x(), std::clamp(x.y(), -0.25, 0.25) - x.y(), 1).norm());
        }
        std::int64_t last_bin = -1;
        for (std::uint64_t k = merged.row[i]; k < merged.row[i + 1]; ++k) {
            const Pulse& p = merged.pulses[k];
            EXPECT_GE(p.path, nearest - 1e-12);
            EXPECT_LE(p.path, farthest + 1e-12);
            const auto bin = std::int64_t(std::floor(p.path / 0.01));
            EXPECT_GT(bin, last_bin) << "one pulse per bin, in order";
            last_bin = bin;
        }
        // Merged per bin, the energy is the same (the exact form factor's).
        EXPECT_NEAR(first_bounce(merged, i), first_bounce(unmerged, i), 1e-12 * first_bounce(merged, i));
    }
}

// The time profile of an area source's light at a point x: the timing cells of arrive_area_open (each
// spanning about kAreaBinsPerTimingCell bins, its light spread over its paths to first order) against the
// truth, a 400 x 400 midpoint rule over the emitter binned by path: the relative L1 of the profile per
// 5 mm bin within 1.5% (measured: 1.1% near the source, where the paths curve most, 0.4% beside it),
// and the first bin exact. Bins of 5 mm; from a point under the
// emitter's edge (paths from 0.6 to 0.9 m) and from one beside it; then with x's own cell (a pixel
// sample's: 2 cm across, seen along a 2 m leg), against the truth over 12 x 12 points of that cell too.
TEST(AreaSources, TimingCellsGiveTheSourcesDistributionOfPaths) {
    Scene scene;
    scene.objects.push_back(test::rectangle(Vec3(-0.2, -0.2, 0.6), Vec3(0, 0.4, 0), Vec3(0.4, 0, 0), 0.0, 1.0));
    const PatchSet patches = build_patches(scene);
    const std::vector<AreaSource> areas = area_sources(&scene, patches);
    ASSERT_EQ(areas.size(), 1u);
    const AreaSource& a = areas[0];
    const double bin = 0.005;
    const int T = 400;
    const Vec3 n = Vec3::UnitZ();
    const auto profile_of = [&](const std::vector<AreaPair>& pairs) {
        std::vector<double> p(T, 0.0);
        double total = 0.0;
        for (const AreaPair& q : pairs) total += q.weight;
        for (const AreaPair& q : pairs) p[std::size_t(std::floor(q.path / bin))] += q.weight / total;
        return p;
    };
    const auto truth_of = [&](const Vec3& x, const Footprint& f, int cell) {
        std::vector<double> p(T, 0.0);
        double total = 0.0;
        const int m = 400;
        for (int i = 0; i < cell; ++i)
            for (int j = 0; j < cell; ++j) {
                const double s = cell > 1 ? 2.0 * (i + 0.5) / cell - 1.0 : 0.0, t = cell > 1 ? 2.0 * (j + 0.5) / cell - 1.0 : 0.0;
                const Vec3 xs = x + s * f.du + t * f.dv;
                const double leg = f.leg_at(s, t) - f.leg;
                for (int u = 0; u < m; ++u)
                    for (int v = 0; v < m; ++v) {
                        const Vec3 d = a.point((u + 0.5) / m, (v + 0.5) / m) - xs;
                        const double r2 = d.squaredNorm(), k = std::max(0.0, n.dot(d)) * std::max(0.0, -a.normal.dot(d)) / (r2 * r2);
                        p[std::size_t(std::floor((std::sqrt(r2) + leg) / bin))] += k;
                        total += k;
                    }
            }
        for (double& v : p) v /= total;
        return p;
    };
    const auto compare = [&](const std::vector<double>& p, const std::vector<double>& q, double& l1) {
        l1 = 0.0;
        int first_p = -1, first_q = -1;
        for (int b = 0; b < T; ++b) {
            l1 += std::abs(p[std::size_t(b)] - q[std::size_t(b)]);
            if (first_p < 0 && p[std::size_t(b)] > 0.0) first_p = b;
            if (first_q < 0 && q[std::size_t(b)] > 1e-9) first_q = b;
        }
        return first_p - first_q;
    };
    Footprint cell;
    cell.du = Vec3(0.01, 0.0, 0.0);
    cell.dv = Vec3(0.0, 0.01, 0.0);
    cell.leg = 2.0;
    cell.leg_du = 0.004;
    cell.leg_dv = -0.003;
    for (const Vec3& x : {Vec3(-0.2, 0.05, 0.0), Vec3(-0.5, -0.3, 0.0)})
        for (const bool footprint : {false, true}) {
            AreaSampling s = area_sampling(a, x, bin, 0.0, kAreaShadowRays, kAreaPenumbraRays);
            if (footprint) s.footprint = cell;
            std::vector<AreaPair> pairs;
            ASSERT_GT(arrive_area_open(a, x, n, s, pairs), 0.0);
            const std::vector<double> truth = truth_of(x, cell, footprint ? 12 : 1);
            double l1 = 0.0;
            const int early = compare(profile_of(pairs), truth, l1);
            // Cells of half the size, for comparison: the error left is the cells' (second order).
            const int m = s.timing;
            s.timing = std::min(32, 2 * m);
            pairs.clear();
            arrive_area_open(a, x, n, s, pairs);
            double finer = 0.0;
            compare(profile_of(pairs), truth, finer);
            MEASURED("area timing from (%.2f, %.2f)%s: L1 %.4f with %d cells per side, %.4f with %d\n", x.x(), x.y(),
                     footprint ? " with a cell" : "", l1, m, finer, s.timing);
            EXPECT_LT(l1, 0.015) << x.transpose() << (footprint ? " with a cell" : "");
            EXPECT_EQ(early, 0) << "first bin, from " << x.transpose() << (footprint ? " with a cell" : "");
        }
}

}  // namespace
}  // namespace tprf
