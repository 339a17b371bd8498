#include "tprf/transport/solver.h"

#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"
#include "tprf/geometry/patches.h"
#include "tprf/transport/steady.h"
#include "tprf/geometry/visibility.h"

#include "test_scenes.h"

#include "tprf/core/error.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <string>
#include <utility>

namespace tprf {
namespace {

// Everything the solver needs, built from a scene.
struct Prepared {
    PatchSet patches;
    LinkSet links;
    Illumination emission;
};

Prepared prepare(const Scene& scene) {
    Prepared p;
    p.patches = build_patches(scene);
    const Visibility vis(p.patches);
    p.links = flat_link_set(p.patches, vis);
    p.emission = illuminate(light_sources(scene, p.patches, vis), p.patches, vis);
    return p;
}

// Full profiles, N x T x 3 (and the per-order terms, K x N x T x 3), collected from the block sink.
struct Profiles {
    std::size_t n = 0;
    int bins = 0;
    std::vector<float> total;
    std::vector<float> terms;
    int term_count = 0;
    SolveStats stats;

    double at(std::size_t i, int t, int c) const { return total[(i * std::size_t(bins) + std::size_t(t)) * 3 + std::size_t(c)]; }
    double term(int k, std::size_t i, int t, int c) const {
        return terms[((std::size_t(k) * n + i) * std::size_t(bins) + std::size_t(t)) * 3 + std::size_t(c)];
    }
};

Profiles solve(const PatchSet& patches, const LinkSet& links, const Illumination& emission, const TimeAxis& time,
               const SolverOptions& options = {}) {
    Profiles out;
    out.n = patches.size();
    out.bins = time.bins;
    out.total.assign(out.n * std::size_t(time.bins) * 3, 0.0f);
    out.stats = solve_transient(patches, links, emission, time, options, [&](const SolveBlock& b) {
        out.term_count = b.terms;
        if (b.terms > 0 && out.terms.empty()) out.terms.assign(std::size_t(b.terms) * out.total.size(), 0.0f);
        for (std::size_t i = 0; i < b.patches; ++i)
            for (int t = 0; t < b.bins; ++t)
                for (int c = 0; c < 3; ++c) {
                    const std::size_t src = (i * std::size_t(b.bins) + std::size_t(t)) * 3 + std::size_t(c);
                    const std::size_t dst = (i * std::size_t(time.bins) + std::size_t(b.first_bin + t)) * 3 + std::size_t(c);
                    out.total[dst] = b.radiosity[src];
                    for (int k = 0; k < b.terms; ++k)
                        out.terms[std::size_t(k) * out.total.size() + dst] = b.per_order[std::size_t(k) * b.patches * std::size_t(b.bins) * 3 + src];
                }
    });
    return out;
}

Profiles solve(const Prepared& p, const TimeAxis& time, SolverOptions options = {}) {
    return solve(p.patches, p.links, p.emission, time, options);
}

using test::time_axis;

TEST(Solver, FurnaceSteadyStateIsEmissionOverOneMinusAlbedo) {
    const double a = 0.6, le = 1.0;
    Scene scene;
    scene.max_edge = 0.25;
    test::add_closed_cube(scene, 1.0, a, le);
    const Prepared p = prepare(scene);
    const std::vector<Rgb> b = solve_steady(p.patches, p.links, p.emission);
    const double expected = M_PI * le / (1 - a);
    // The cube's rows sum to 1 within about 2e-4 (Links tests); B inherits that over 1 - a.
    for (const Rgb& v : b) EXPECT_NEAR(v[1], expected, 1e-3 * expected);
}

TEST(Solver, FurnaceBounceEnergiesFallAsPowersOfTheAlbedo) {
    const double a = 0.6, le = 1.0;
    Scene scene;
    scene.max_edge = 0.25;
    test::add_closed_cube(scene, 1.0, a, le);
    const Prepared p = prepare(scene);
    SolverOptions options;
    options.max_bounces = 4;
    options.bounce_terms = 1;
    // Four bounces of at most sqrt(3) m each stay inside 8 m.
    const Profiles pr = solve(p, time_axis(400, 0.02), options);
    ASSERT_EQ(pr.term_count, 5);
    double emitted = 0.0;
    for (std::size_t i = 0; i < p.patches.size(); ++i) emitted += p.patches.area[i] * M_PI * le;
    for (int k = 0; k <= 4; ++k) {
        double energy = 0.0;
        for (std::size_t i = 0; i < p.patches.size(); ++i)
            for (int t = 0; t < pr.bins; ++t) energy += p.patches.area[i] * pr.term(k, i, t, 0);
        EXPECT_NEAR(energy / emitted, std::pow(a, k), 1e-3 * std::pow(a, k)) << "bounce " << k;
    }
}

TEST(Solver, NothingArrivesBetweenTheDirectPulseAndTheFirstEcho) {
    // Plates z=0 (up) and z=1 (down), 2.4 x 2.4 m, a point light midway.
    Scene scene;
    scene.max_edge = 0.1;
    scene.objects.push_back(test::rectangle(Vec3(-1.2, -1.2, 0), 2.4 * Vec3::UnitX(), 2.4 * Vec3::UnitY()));
    scene.objects.push_back(test::rectangle(Vec3(-1.2, -1.2, 1), 2.4 * Vec3::UnitY(), 2.4 * Vec3::UnitX()));
    scene.lights.push_back(PointLight{Vec3(0, 0, 0.5), Rgb::Constant(1.0)});
    const Prepared p = prepare(scene);
    const double w = 0.01;
    SolverOptions options;
    options.bounce_terms = 5;  // orders 0..3 and 4+
    const Profiles pr = solve(p, time_axis(400, w), options);
    // The bottom plate's patch under the light.
    std::size_t centre = 0;
    for (std::size_t i = 0; i < p.patches.size(); ++i)
        if (p.patches.object[i] == 0 && (p.patches.centroid[i] - Vec3(0.05, 0.05, 0)).norm() < 1e-9) centre = i;
    ASSERT_NEAR(p.patches.centroid[centre].x(), 0.05, 1e-9);
    auto energy = [&](int order, double from, double to) {
        double e = 0.0;
        for (int t = int(std::floor(from / w + 1e-9)); t < int(std::ceil(to / w - 1e-9)); ++t)
            e += order < 0 ? pr.at(centre, t, 0) : pr.term(order, centre, t, 0);
        return e;
    };
    // The direct pulse: paths from the light to the patch run from 0.5 to |(0.1, 0.1, 0.5)| < 0.52.
    EXPECT_GT(energy(1, 0.5, 0.52), 0.0);
    EXPECT_EQ(energy(1, 0.52, 4.0), 0.0);
    // The gap: the first echo travels at least 0.5 up and 1 down (1.5), less a bin of placement.
    for (int t = int(std::ceil(0.52 / w)); (t + 1) * w <= 1.49; ++t) EXPECT_EQ(pr.at(centre, t, 0), 0.0) << "bin " << t;
    // Each echo starts one gap (1 m) after the previous one: order k + 1 needs at least 0.5 + k metres.
    for (int k = 1; k <= 3; ++k) {
        const double onset = 0.5 + k - 1;
        EXPECT_EQ(energy(k, 0.0, onset - 0.01), 0.0) << "order " << k;
        EXPECT_GT(energy(k, onset - 0.01, onset + 0.2), 0.0) << "order " << k;
    }
    EXPECT_GT(energy(4, 3.49, 4.0), 0.0);
}

// A closed grey cube (1 m, albedo 0.5) in squares of `max_edge`, lit by a unit point light.
Prepared lit_cube(double max_edge, const Vec3& light) {
    Scene scene;
    scene.max_edge = max_edge;
    test::add_closed_cube(scene, 1.0, 0.5);
    scene.lights.push_back(PointLight{light, Rgb::Constant(1.0)});
    return prepare(scene);
}

// Every patch's profile summed over the bins against the steady state, in `channels` channels: float
// accumulation over ~40 bounces and the steady solve's 1e-8 make 1e-4 relative (plus `floor`, for
// channels that carry almost nothing).
void expect_integrals_are_steady(const Profiles& pr, const std::vector<Rgb>& steady, int channels, double floor = 0.0) {
    for (std::size_t i = 0; i < steady.size(); ++i)
        for (int c = 0; c < channels; ++c) {
            double sum = 0.0;
            for (int t = 0; t < pr.bins; ++t) sum += pr.at(i, t, c);
            EXPECT_NEAR(sum, steady[i][c], 1e-4 * steady[i][c] + floor) << "patch " << i << " channel " << c;
        }
}

TEST(Solver, TimeIntegralOfEveryProfileIsTheSteadyState) {
    Scene scene;
    scene.max_edge = 0.2;
    test::add_closed_cube(scene, 1.0, 0.5);
    scene.objects[2].albedo = Rgb(0.7, 0.2, 0.2);  // a coloured wall: three channels are solved
    scene.lights.push_back(PointLight{Vec3(0.5, 0.5, 0.8), Rgb(1.0, 2.0, 3.0)});
    const Prepared p = prepare(scene);
    const std::vector<Rgb> steady = solve_steady(p.patches, p.links, p.emission);
    // Light loses at least half its energy per bounce of at most sqrt(3) m: after 40 m, below 1e-6.
    for (DelayMode mode : {DelayMode::Linear, DelayMode::Nearest}) {
        SolverOptions options;
        options.delay = mode;
        const Profiles pr = solve(p, time_axis(800, 0.05), options);
        EXPECT_EQ(pr.stats.channels, 3);
        expect_integrals_are_steady(pr, steady, 3, 1e-9);
    }
}

// A closed cube of 600 patches (0.1 m) lit inside: all see most of the others, so the long pass tiles
// its sources (solver_plan.h: kDenseRow) and adds each receiver tile's sums up apart. With
// `unlinked_patches`, a plane below the cube facing away from it adds that many patches that link to
// nothing, so that the same links are too sparse to tile.
Scene dense_cube(bool unlinked_patches) {
    Scene scene;
    scene.max_edge = 0.1;
    test::add_closed_cube(scene, 1.0, 0.5);
    scene.objects[2].albedo = Rgb(0.7, 0.2, 0.2);
    scene.lights.push_back(PointLight{Vec3(0.3, 0.6, 0.7), Rgb(1.0, 2.0, 3.0)});
    if (unlinked_patches)  // 4 m x 4 m at z = -0.5, normal -z: 1,600 patches
        scene.objects.push_back(test::rectangle(Vec3(-1.5, -1.5, -0.5), Vec3(0, 4, 0), Vec3(4, 0, 0), 0.5));
    return scene;
}

TEST(Solver, TiledSourcesKeepEveryProfilesIntegral) {
    // Blocks of 8 (windows of 8 to 32 bins, links as the set has them: 3 lanes x 8 bins make no whole
    // 16-float vectors) and of 16 (packed links in windows of 16 to 64), at 5 cm (lags of 2 to 35 bins)
    // and 2 cm (4 to 87, so that every window has links): each window's sums reach their own bins.
    // Light loses half its energy per bounce of at most sqrt(3) m: after 40 m, below 1e-6.
    const Prepared p = prepare(dense_cube(false));
    ASSERT_EQ(p.patches.size(), 600u);
    ASSERT_GE(p.links.links.size(), 256 * p.patches.size());
    const std::vector<Rgb> steady = solve_steady(p.patches, p.links, p.emission);
    for (int block : {8, 16})
        for (const TimeAxis& time : {time_axis(800, 0.05), time_axis(2000, 0.02)}) {
            SolverOptions options;
            options.block_bins = block;
            const Profiles pr = solve(p, time, options);
            EXPECT_EQ(pr.stats.block_bins, block);
            EXPECT_EQ(pr.stats.packed_links > 0, block == 16);
            // A plan made only to size the march counts the packed links it does not make.
            EXPECT_EQ(pr.stats.working_bytes, solve_working_bytes(p.patches, p.links, time, options, 1, 3));
            expect_integrals_are_steady(pr, steady, 3, 1e-9);
        }
}

TEST(Solver, TiledAndUntiledSourcesGiveTheSameProfiles) {
    // The cube alone (tiled sources) against the cube with 1,600 unlinked patches beside it (the same
    // links, untiled): the same sums in another order, bin by bin, for blocks of 8 bins (tiled links as
    // the set has them) and of 16 and 32 (packed links, in windows up to 64 bins).
    const Prepared tiled = prepare(dense_cube(false)), untiled = prepare(dense_cube(true));
    ASSERT_EQ(untiled.patches.size(), 2200u);
    ASSERT_EQ(untiled.links.links.size(), tiled.links.links.size());
    ASSERT_LT(untiled.links.links.size(), 256 * untiled.patches.size());
    for (int b : {8, 16, 32}) {
        SolverOptions options;
        options.block_bins = b;
        const Profiles t = solve(tiled, time_axis(300, 0.02), options), u = solve(untiled, time_axis(300, 0.02), options);
        EXPECT_EQ(t.stats.packed_links > 0, b > 8);
        EXPECT_EQ(u.stats.packed_links, 0u);
        float peak = 0.0f;
        for (float v : t.total) peak = std::max(peak, v);
        ASSERT_GT(peak, 0.0f);
        float worst = 0.0f;
        for (std::size_t k = 0; k < t.total.size(); ++k) worst = std::max(worst, std::abs(t.total[k] - u.total[k]));
        EXPECT_LE(worst, 1e-5f * peak) << "blocks of " << b << " bins";
        for (std::size_t k = t.total.size(); k < u.total.size(); ++k) ASSERT_EQ(u.total[k], 0.0f);
    }
}

TEST(Solver, ZeroDelayLinksNeitherLoseNorInventEnergy) {
    // Bins of 10 m: every link of a 1 m cube has delay 0, so all the light lands in bin 0.
    const Prepared p = lit_cube(0.25, Vec3(0.3, 0.4, 0.5));
    const std::vector<Rgb> steady = solve_steady(p.patches, p.links, p.emission);
    for (DelayMode mode : {DelayMode::Linear, DelayMode::Nearest}) {
        SolverOptions options;
        options.delay = mode;
        const Profiles pr = solve(p, time_axis(4, 10.0), options);
        EXPECT_GT(pr.stats.max_jacobi_iterations, 1);
        expect_integrals_are_steady(pr, steady, 1);
    }
}

// Bins of 0.25 m put the links across the cube's edges (centroids 0.14 m apart) within one bin and
// the others (0.32 m and more) later: with the linear delay (the nearest one rounds them to a bin),
// the same-bin system holds the 96 squares along the edges only, and the brightest squares (the
// floor's middle, under the light) lie outside it, where the sweeps' stopping rule has to take their
// values from. The sweeps of each bin start from the last two bins' shares; wherever they start, the
// time integral is the steady state, for one thread or two alike.
TEST(Solver, ASameBinSystemOnPartOfTheSceneConvergesToTheSteadyState) {
    const Prepared p = lit_cube(0.2, Vec3(0.5, 0.5, 0.3));
    const std::vector<Rgb> steady = solve_steady(p.patches, p.links, p.emission);
    for (int block : {8, 32}) {  // windows of 8 to 32 bins, and one window
        SolverOptions one, two;
        one.threads = 1;
        two.threads = 2;
        one.block_bins = two.block_bins = block;
        // Light loses at least half its energy per bounce of at most sqrt(3) m: after 60 m, below 1e-6.
        const Profiles a = solve(p, time_axis(240, 0.25), one), b = solve(p, time_axis(240, 0.25), two);
        EXPECT_GT(a.stats.max_jacobi_iterations, 1);
        EXPECT_EQ(a.total, b.total);
        expect_integrals_are_steady(a, steady, 1);
    }
}

TEST(Solver, LinearDelaySplitsABinBetweenTheTwoItOverlaps) {
    // Two 1 cm squares facing each other 1.2345 m apart, bins of 0.1 m: the link's delay is 12.345
    // bins. A pulse at path 0 on the lower square fills its bin 0 = [0, 0.1 m); shifted by 1.2345 m it
    // covers [1.2345, 1.3345), which overlaps bin 12 by 0.0655 m and bin 13 by 0.0345 m. So the upper
    // square's first-bounce light is 65.5% in bin 12 and 34.5% in bin 13 (linear), all of it in bin 12
    // (nearest: 12.345 rounds to 12), and none anywhere else.
    const double w = 0.1, d = 1.2345, s = 0.01, albedo = 0.5;
    PatchSet patches;
    const Vec3 lo[4] = {Vec3(0, 0, 0), Vec3(s, 0, 0), Vec3(s, s, 0), Vec3(0, s, 0)};
    const Vec3 hi[4] = {Vec3(0, 0, d), Vec3(0, s, d), Vec3(s, s, d), Vec3(s, 0, d)};
    add_patch(patches, lo, 4, Rgb::Constant(albedo), Rgb::Constant(1.0), 0);
    add_patch(patches, hi, 4, Rgb::Constant(albedo), Rgb::Zero(), 1);
    const Visibility vis(patches);
    Prepared p;
    p.patches = patches;
    p.links = flat_link_set(patches, vis);
    // The pulse by hand, so that it goes through the link (an emissive patch's own light would be
    // sent with exact point-to-point paths instead): exitance pi W s / m^2 at path 0.
    p.emission.row = {0, 1, 1};
    Pulse pulse;
    pulse.energy = Rgb::Constant(M_PI);
    p.emission.pulses = {pulse};
    ASSERT_EQ(p.links.links.size(), 2u);
    // What reaches the upper square: albedo F pi, with F from Howell's C-11. The link stage takes the
    // centroid rule this far out, whose error is second order in size / distance, (0.007 / 1.23)^2 =
    // 3e-5 (measured: 2.2e-5 high); 1e-4 is about 4 times that.
    const double arrived = albedo * test::ff_parallel_rectangles(s, s, d) * M_PI;
    const double tolerance = 1e-4 * arrived;
    for (DelayMode mode : {DelayMode::Linear, DelayMode::Nearest}) {
        SolverOptions options;
        options.delay = mode;
        options.max_bounces = 1;
        const Profiles pr = solve(p, time_axis(40, w), options);
        const char* name = mode == DelayMode::Linear ? "linear" : "nearest";
        const double share12 = mode == DelayMode::Linear ? 0.655 : 1.0;
        // The split is 12.345 bins in single precision (1e-6 of a bin): far inside the tolerance.
        EXPECT_NEAR(pr.at(1, 12, 0), share12 * arrived, tolerance) << name;
        EXPECT_NEAR(pr.at(1, 13, 0), (1.0 - share12) * arrived, tolerance) << name;
        for (int t = 0; t < pr.bins; ++t) {
            if (t != 12 && t != 13) {
                EXPECT_EQ(pr.at(1, t, 0), 0.0) << "bin " << t;
            }
        }
    }
}

TEST(Solver, AreaLightPulsesCarryExactPathsAndTheFormFactorsEnergy) {
    // A 0.4 m emitter square facing down at height 1, a 0.4 m receiver on the floor offset by 0.6:
    // each one patch, so a centroid delay would put all light at one path.
    Scene scene;
    scene.max_edge = 0.5;
    scene.objects.push_back(test::rectangle(Vec3(0.6, 0, 0), 0.4 * Vec3::UnitX(), 0.4 * Vec3::UnitY(), 0.5));
    scene.objects.push_back(test::rectangle(Vec3(0, 0, 1), 0.4 * Vec3::UnitY(), 0.4 * Vec3::UnitX(), 0.5, 2.0));
    const Prepared p = prepare(scene);
    ASSERT_EQ(p.patches.size(), 2u);
    ASSERT_EQ(p.links.links.size(), 2u);
    // The receiver's pulses: order 1, between the nearest and farthest corner pairs, many paths.
    double lo = 1e9, hi = 0.0;
    for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b) {
            const double d = (p.patches.polygon(0)[a] - p.patches.polygon(1)[b]).norm();
            lo = std::min(lo, d);
            hi = std::max(hi, d);
        }
    Rgb total = Rgb::Zero();
    std::vector<double> paths;
    for (std::uint64_t k = p.emission.row[0]; k < p.emission.row[1]; ++k) {
        const Pulse& pulse = p.emission.pulses[k];
        EXPECT_EQ(pulse.order, 1);
        EXPECT_GE(pulse.path, lo);
        EXPECT_LE(pulse.path, hi);
        paths.push_back(pulse.path);
        total += pulse.energy;
    }
    // Not one centroid path: 2 x 2 receiver points and 4 x 4 emitter cells give distinct paths
    // spanning most of the geometric range (cell centres lie 1/8 of a side inside the emitter).
    std::sort(paths.begin(), paths.end());
    EXPECT_GE(std::unique(paths.begin(), paths.end()) - paths.begin(), 16);
    EXPECT_GT(paths.back() - paths.front(), 0.6 * (hi - lo));
    // Energy: albedo pi L_e F with F the receiver's mean of Howell's B-3 to the emitter (a 400 x 400
    // midpoint rule of the closed form, within 1e-6). illuminate() integrates the same over the patch
    // adaptively to a relative 1e-3 per cell, with Richardson's step: measured 7e-6.
    double ff = 0.0;
    const int m = 400;
    for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b)
            ff += test::ff_point_to_parallel_rectangle(0.6 + 0.4 * (a + 0.5) / m, 0.4 * (b + 0.5) / m, 0, 0.4, 0, 0.4, 1.0);
    ff /= double(m) * m;
    EXPECT_NEAR(total[0], 0.5 * M_PI * 2.0 * ff, 1e-4 * total[0]);
    // The emitter shows its own exitance at path 0 and does not send it through the links again.
    ASSERT_EQ(p.emission.row[2] - p.emission.row[1], 1u);
    EXPECT_FALSE(p.emission.pulses[p.emission.row[1]].propagates);
}

TEST(Solver, LaserEnergyIsCountedOnce) {
    // A laser into a closed cube of albedo a: the spot sends a P, and each later bounce keeps a of it,
    // so the exitance power of all patches together is a P / (1 - a).
    const double a = 0.5, power = 2.0;
    Scene scene;
    scene.max_edge = 0.1;
    test::add_closed_cube(scene, 1.0, a);
    Laser laser;
    laser.origin = Vec3(0.5, 0.5, 0.9);
    laser.direction = Vec3(0.1, 0.05, -1).normalized();
    laser.power = Rgb::Constant(power);
    scene.lights.push_back(laser);
    const Prepared p = prepare(scene);
    const std::vector<Rgb> steady = solve_steady(p.patches, p.links, p.emission);
    double exitance = 0.0;
    for (std::size_t i = 0; i < p.patches.size(); ++i) exitance += p.patches.area[i] * steady[i][0];
    // 16 samples per patch integrate the point source's irradiance to about 1% near the spot.
    EXPECT_NEAR(exitance, a * power / (1 - a), 0.01 * a * power / (1 - a));
    // The spot's own patch shows a P / A once, in the bin of |origin - X|.
    SolverOptions options;
    options.max_bounces = 1;
    options.bounce_terms = 1;
    const Profiles pr = solve(p, time_axis(200, 0.05), options);
    const LaserSpot spot = find_laser_spot(laser.origin, laser.direction, Visibility(p.patches));
    ASSERT_TRUE(spot.hit);
    double seen = 0.0;
    for (int t = 0; t < pr.bins; ++t) seen += pr.term(1, spot.patch, t, 0);
    EXPECT_NEAR(seen, a * power / p.patches.area[spot.patch], 1e-5 * seen);
    EXPECT_GT(pr.term(1, spot.patch, int(spot.path / 0.05), 0), 0.0);
}

TEST(Solver, OneAndTwoThreadsGiveIdenticalProfiles) {
    Scene scene;
    scene.max_edge = 0.2;
    test::add_closed_cube(scene, 1.0, 0.5);
    scene.lights.push_back(PointLight{Vec3(0.5, 0.5, 0.8), Rgb::Constant(1.0)});
    const Prepared p = prepare(scene);
    SolverOptions one, two;
    one.threads = 1;
    two.threads = 2;
    // Short blocks and fine bins exercise long links and short links (the nearest centroids are
    // 0.14 m apart: 7 bins, so no link falls within one bin here).
    one.block_bins = two.block_bins = 8;
    const Profiles a = solve(p, time_axis(300, 0.02), one), b = solve(p, time_axis(300, 0.02), two);
    EXPECT_GT(a.stats.short_links, 0u);
    EXPECT_EQ(a.total, b.total);
    // Bins of 0.25 m put every link between neighbouring squares (0.14 m to 0.2 m apart) within one
    // bin: the same-bin Jacobi iteration, whose max-reduction is shared by the threads, must run
    // (more than one sweep) and give the same profiles for one and two threads.
    const Profiles c = solve(p, time_axis(40, 0.25), one), d = solve(p, time_axis(40, 0.25), two);
    EXPECT_GT(c.stats.max_jacobi_iterations, 1);
    EXPECT_EQ(c.stats.max_jacobi_iterations, d.stats.max_jacobi_iterations);
    EXPECT_EQ(c.total, d.total);
    // Dense rows: tiles of receivers and of sources, each receiver tile's sums in a thread's own array.
    const Prepared dense = prepare(dense_cube(false));
    EXPECT_EQ(solve(dense, time_axis(300, 0.02), one).total, solve(dense, time_axis(300, 0.02), two).total);
}

TEST(Solver, EveryBlockLengthGivesTheSameProfiles) {
    // Delays of 7 to 72 bins: blocks of 1 to 16 bins apply them in windows of 1 to 32 bins (rows of
    // a flat set sorted into windows), blocks of 32 in one window, and blocks of 64 partly bin by
    // bin. Every schedule sums the same terms, in another order: float rounding apart, one answer.
    Scene scene;
    scene.max_edge = 0.2;
    test::add_closed_cube(scene, 1.0, 0.7);
    scene.lights.push_back(PointLight{Vec3(0.3, 0.6, 0.8), Rgb(1.0, 0.5, 0.25)});
    const Prepared p = prepare(scene);
    SolverOptions reference;
    reference.block_bins = 32;
    const Profiles r = solve(p, time_axis(300, 0.02), reference);
    float peak = 0.0f;
    for (float v : r.total) peak = std::max(peak, v);
    ASSERT_GT(peak, 0.0f);
    for (int b : {1, 2, 4, 16, 64}) {
        SolverOptions options;
        options.block_bins = b;
        const Profiles q = solve(p, time_axis(300, 0.02), options);
        ASSERT_EQ(q.stats.block_bins, b);
        float worst = 0.0f;
        for (std::size_t k = 0; k < r.total.size(); ++k) worst = std::max(worst, std::abs(q.total[k] - r.total[k]));
        EXPECT_LE(worst, 1e-5f * peak) << "blocks of " << b << " bins";
    }
}

TEST(Solver, WorkingMemoryDoesNotGrowWithBins) {
    // A grey 1 m cube cut into 4 x 4 squares per wall: N = 96 patches, each linked to the 80 squares of
    // the other five walls. The longest link joins opposite corner squares of opposite walls,
    // sqrt(0.75^2 + 0.75^2 + 1) = 1.458 m: D = 72 whole bins of 2 cm. Blocks of B = 32 bins.
    Scene scene;
    scene.max_edge = 0.25;
    test::add_closed_cube(scene, 1.0, 0.5);
    scene.lights.push_back(PointLight{Vec3(0.5, 0.5, 0.8), Rgb::Constant(1.0)});
    const Prepared p = prepare(scene);
    const std::size_t n = 96, links = 96 * 80;
    const int d = 72, b = 32;
    ASSERT_EQ(p.patches.size(), n);
    ASSERT_EQ(p.links.links.size(), links);
    SolverOptions options;
    options.block_bins = b;
    std::vector<std::size_t> bytes;
    for (int bins : {256, 8192}) {
        const SolveStats stats = solve_transient(p.patches, p.links, p.emission, time_axis(bins, 0.02), options, {});
        ASSERT_EQ(stats.block_bins, b);
        ASSERT_EQ(stats.channels, 1);
        // solver.h: each patch keeps a ring of its recent radiosity as long as the largest delay plus
        // one block (plus the second tap), at most doubled by rounding up to a power of two.
        EXPECT_GE(stats.ring_bins, d + 1 + b) << bins << " bins";
        EXPECT_LE(stats.ring_bins, 2 * (d + 2 + b)) << bins << " bins";
        // Working memory O(N x (D + B) + links), whatever the number of bins: at least the rings,
        // N x ring x 4 bytes; at most rings with a mirrored block, N x (2 (D + 2 + B) + B + 1) floats,
        // the block buffers (in, out and the RGB block handed to the sink), N x B x 5 floats, and 16
        // bytes per link and per patch for the link lists. The cube itself, N x T x 3 floats, is 9.4 MB
        // for 8192 bins.
        const std::size_t floats = n * std::size_t(2 * (d + 2 + b) + b + 1) + n * std::size_t(b) * 5;
        EXPECT_GE(stats.working_bytes, n * std::size_t(stats.ring_bins) * 4) << bins << " bins";
        EXPECT_LE(stats.working_bytes, 4 * floats + 16 * (links + n + 1)) << bins << " bins";
        bytes.push_back(stats.working_bytes);
    }
    EXPECT_EQ(bytes[0], bytes[1]);
}

// ---------------------------------------------------------------------------------------------------
// Batches: K illuminations of the same patches and links in one march.

// Every illumination's profiles from one batched solve, each laid out as a single solve's.
std::vector<Profiles> solve_batch(const PatchSet& patches, const LinkSet& links, const std::vector<Illumination>& batch,
                                  const TimeAxis& time, const SolverOptions& options) {
    const std::size_t K = batch.size(), n = patches.size();
    std::vector<const Illumination*> pointers;
    for (const Illumination& e : batch) pointers.push_back(&e);
    std::vector<Profiles> out(K);
    for (Profiles& pr : out) {
        pr.n = n;
        pr.bins = time.bins;
        pr.total.assign(n * std::size_t(time.bins) * 3, 0.0f);
    }
    const SolveStats stats = solve_transient(
        patches, links, std::span<const Illumination* const>(pointers), time, options, [&](const SolveBlock& b) {
            EXPECT_EQ(b.illuminations, int(K));
            const std::size_t term_size = b.patches * std::size_t(b.bins) * K * 3;  // N x bins x K x 3
            for (std::size_t k = 0; k < K; ++k) {
                Profiles& pr = out[k];
                pr.term_count = b.terms;
                if (b.terms > 0 && pr.terms.empty()) pr.terms.assign(std::size_t(b.terms) * pr.total.size(), 0.0f);
                for (std::size_t i = 0; i < b.patches; ++i)
                    for (int t = 0; t < b.bins; ++t)
                        for (int c = 0; c < 3; ++c) {
                            const std::size_t src = ((i * std::size_t(b.bins) + std::size_t(t)) * K + k) * 3 + std::size_t(c);
                            const std::size_t dst =
                                (i * std::size_t(time.bins) + std::size_t(b.first_bin + t)) * 3 + std::size_t(c);
                            pr.total[dst] = b.radiosity[src];
                            for (int term = 0; term < b.terms; ++term)
                                pr.terms[std::size_t(term) * pr.total.size() + dst] =
                                    b.per_order[std::size_t(term) * term_size + src];
                        }
            }
        });
    for (Profiles& pr : out) pr.stats = stats;
    return out;
}

// The largest difference between a batched and a single solve of one illumination over every patch's
// profile (the total, then each per-order term), relative to that profile's peak in the single solve;
// infinite where the single solve has no light and the batch has some. 0 when they are identical.
// `tail`: the last term is every order from its index on, computed as the total less the exact orders,
// so its rounding is the total's: it is measured against the patch's total peak.
double worst_relative(const Profiles& batch, const Profiles& single, bool tail = false) {
    EXPECT_EQ(batch.term_count, single.term_count);
    if (batch.term_count != single.term_count) return INFINITY;
    auto value = [](const Profiles& pr, int term, std::size_t i, int t, int c) {
        return term < 0 ? pr.at(i, t, c) : pr.term(term, i, t, c);
    };
    double worst = 0.0;
    for (std::size_t i = 0; i < single.n; ++i) {
        double total_peak = 0.0;
        for (int term = -1; term < single.term_count; ++term) {
            double peak = 0.0, diff = 0.0;
            for (int t = 0; t < single.bins; ++t)
                for (int c = 0; c < 3; ++c) {
                    peak = std::max(peak, std::abs(value(single, term, i, t, c)));
                    diff = std::max(diff, std::abs(value(batch, term, i, t, c) - value(single, term, i, t, c)));
                }
            if (term < 0) total_peak = peak;
            if (tail && term == single.term_count - 1) peak = total_peak;
            if (diff > 0.0) worst = std::max(worst, peak > 0.0 ? diff / peak : INFINITY);
        }
    }
    return worst;
}

// Pulses given by hand, grouped into an illumination's CSR rows.
struct PulseSpec {
    std::size_t patch;
    double path;
    Rgb energy;
    int order;
    bool propagates;
};

Illumination by_hand(std::size_t n, std::vector<PulseSpec> specs) {
    std::stable_sort(specs.begin(), specs.end(), [](const PulseSpec& a, const PulseSpec& b) { return a.patch < b.patch; });
    Illumination e;
    e.row.assign(n + 1, 0);
    for (const PulseSpec& s : specs) {
        Pulse p;
        p.path = s.path;
        p.energy = s.energy;
        p.order = std::uint8_t(s.order);
        p.propagates = s.propagates;
        e.pulses.push_back(p);
        ++e.row[s.patch + 1];
    }
    std::partial_sum(e.row.begin(), e.row.end(), e.row.begin());
    return e;
}

// Illumination k of a batch: 1 to 3 pulses of orders 0 to 2 on patches, at paths and with energies
// that differ with k (over four decades, so that each illumination's same-bin sweeps have to stop on
// its own scale, not on the brightest one's); every third one also a spot that is seen but not
// propagated. `coloured`: the first pulse of every other illumination is coloured. `early`: illumination
// 0 also fires 0.3 m before the window opens, so that a batch holding it starts earlier than the other
// illuminations' single solves.
Illumination pulses_for(int k, std::size_t n, bool coloured, bool early = true) {
    std::vector<PulseSpec> specs;
    const double scale = std::pow(10.0, double(k % 5) - 2.0);
    for (int j = 0; j <= k % 3; ++j) {
        PulseSpec s{(std::size_t(k) * 37 + std::size_t(j) * 53 + 5) % n, 0.03 * k + 0.21 * j + 0.013,
                    Rgb::Constant(scale * (1.0 + 0.5 * j)), (k + j) % 3, true};
        if (coloured && j == 0 && k % 2 == 1) s.energy = scale * Rgb(1.0, 0.3 + 0.05 * k, 0.1);
        specs.push_back(s);
    }
    if (k % 3 == 2) specs.push_back({(std::size_t(k) * 11 + 3) % n, 0.5 + 0.01 * k, Rgb::Constant(0.8), 1, false});
    if (k == 0 && early) specs.push_back({7 % n, -0.3, Rgb::Constant(0.5), 1, true});
    return by_hand(n, std::move(specs));
}

std::vector<Illumination> batch_of(int K, std::size_t n, bool coloured, bool early = true) {
    std::vector<Illumination> out;
    for (int k = 0; k < K; ++k) out.push_back(pulses_for(k, n, coloured, early));
    return out;
}

// A corner: a 1 m floor (z = 0, albedo 0.6) and a 1 m wall (x = 0) meeting along the y axis, cut into
// 8 x 8 squares each (128 patches), with flat links; no light (the tests bring their own pulses).
Prepared corner(const Rgb& wall_albedo = Rgb::Constant(0.6), double max_edge = 0.125) {
    Scene scene;
    scene.max_edge = max_edge;
    scene.objects.push_back(test::rectangle(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY(), 0.6));  // normal +z
    scene.objects.push_back(test::rectangle(Vec3::Zero(), Vec3::UnitY(), Vec3::UnitZ(), 0.6));  // normal +x
    scene.objects[1].albedo = wall_albedo;
    Prepared p;
    p.patches = build_patches(scene);
    const Visibility vis(p.patches);
    p.links = flat_link_set(p.patches, vis);
    return p;
}

// Schedules that run every kernel: on the corner, delays of 4 to 75 bins of 2 cm with blocks of 32
// (short links and one window of 32) and of 4 (windows of 4 to 32); bins of 10 cm put the squares
// along the corner's edge (8.8 cm apart) within one bin, which the same-bin sweeps solve.
struct Schedule {
    const char* name;
    TimeAxis time;
    int block_bins;
};
const Schedule kSchedules[] = {
    {"2 cm bins, blocks of 32", time_axis(250, 0.02), 32},
    {"2 cm bins, blocks of 4", time_axis(250, 0.02), 4},
    {"10 cm bins", time_axis(50, 0.1), 32},
};

// Why 1e-6: a batch's lanes go through the same float operations in the same order as a single
// solve's channels, in every kernel (the generic one sums a link's window in a local array, as the
// specialised ones do), so most profiles come out identical. What may differ is where the same-bin
// sweeps stop: a batch sweeps until its slowest illumination has converged, so the others take a few
// more sweeps than alone, each moving a value by at most 1e-7 of that illumination's largest value
// in the bin (the stopping test); over the bins that stays well inside 1e-6 of a profile's peak.
constexpr double kBatchTolerance = 1e-6;

// Every illumination of batches of `sizes` against its single solve, on every schedule.
void expect_batches_match_singles(const Prepared& p, const std::vector<Illumination>& all, const std::vector<int>& sizes,
                                  SolverOptions options, int channels) {
    for (const Schedule& schedule : kSchedules) {
        options.block_bins = schedule.block_bins;
        std::vector<Profiles> singles;
        for (const Illumination& e : all) singles.push_back(solve(p.patches, p.links, e, schedule.time, options));
        for (int K : sizes) {
            const std::vector<Illumination> batch(all.begin(), all.begin() + K);
            const std::vector<Profiles> out = solve_batch(p.patches, p.links, batch, schedule.time, options);
            const SolveStats& stats = out[0].stats;
            EXPECT_EQ(stats.illuminations, K) << schedule.name;
            EXPECT_EQ(stats.channels, channels) << schedule.name;
            EXPECT_EQ(stats.lanes, K * channels) << schedule.name;
            EXPECT_EQ(stats.working_bytes, solve_working_bytes(p.patches, p.links, schedule.time, options, K, channels));
            if (schedule.time.bin_width > 0.05) {
                EXPECT_GT(stats.max_jacobi_iterations, 1) << schedule.name;
            }
            for (int k = 0; k < K; ++k) {
                ASSERT_GT(*std::max_element(singles[std::size_t(k)].total.begin(), singles[std::size_t(k)].total.end()), 0.0f);
                const bool tail = options.max_bounces < 0 && options.bounce_terms > 1;
                const double worst = worst_relative(out[std::size_t(k)], singles[std::size_t(k)], tail);
                MEASURED("%s, K = %d, illumination %d: %.3g\n", schedule.name, K, k, worst);
                EXPECT_LE(worst, kBatchTolerance) << schedule.name << ", K = " << K << ", illumination " << k;
            }
        }
    }
}

TEST(Solver, ShortBlocksReachTheSinkTogetherAndEveryBinOnce) {
    // Blocks of 2 bins hand their bins over 32 at a time (SolveBlock), from the first bin asked for
    // (7 before the window) to the last (a partial block of 301): contiguous, each bin once, with the
    // per-order terms and a spot that is seen but not propagated, as longer blocks give them. Links of
    // a cluster tree, so that the march's patch positions are not the patches' ids.
    Scene scene;
    scene.max_edge = 0.2;
    test::add_closed_cube(scene, 1.0, 0.7);
    Prepared p = prepare(scene);
    const std::size_t n = p.patches.size();
    HierarchyOptions h;
    h.tolerance = 0.05;
    h.bin_width_m = 0.02;
    p.links = hierarchical_link_set(p.patches, Visibility(p.patches), {}, h);
    ASSERT_GT(p.links.nodes(), n);
    bool identity = true;
    for (std::size_t k = 0; k < n; ++k) identity = identity && p.links.tree.leaf_order[k] == k;
    ASSERT_FALSE(identity);
    p.emission = by_hand(n, {{3, 0.05, Rgb(1.0, 0.5, 0.25), 0, true}, {40, 0.3, Rgb::Constant(0.7), 1, true},
                             {17, 1.234, Rgb::Constant(0.8), 1, false}});
    const TimeAxis time = time_axis(301, 0.02);
    auto run = [&](int block_bins, std::vector<std::pair<int, int>>* blocks) {
        SolverOptions options;
        options.block_bins = block_bins;
        options.bounce_terms = 3;
        options.first_bin = -7;
        Profiles out;
        out.n = n;
        out.bins = time.bins;
        out.total.assign(n * std::size_t(time.bins) * 3, 0.0f);
        out.terms.assign(3 * out.total.size(), 0.0f);
        out.stats = solve_transient(p.patches, p.links, p.emission, time, options, [&](const SolveBlock& b) {
            if (blocks) blocks->push_back({b.first_bin, b.bins});
            ASSERT_EQ(b.terms, 3);
            for (std::size_t i = 0; i < n; ++i)
                for (int t = std::max(0, -b.first_bin); t < b.bins; ++t)
                    for (std::size_t c = 0; c < 3; ++c) {
                        const std::size_t src = (i * std::size_t(b.bins) + std::size_t(t)) * 3 + c;
                        const std::size_t dst = (i * std::size_t(time.bins) + std::size_t(b.first_bin + t)) * 3 + c;
                        out.total[dst] = b.radiosity[src];
                        for (std::size_t k = 0; k < 3; ++k)
                            out.terms[k * out.total.size() + dst] = b.per_order[k * n * std::size_t(b.bins) * 3 + src];
                    }
        });
        return out;
    };
    std::vector<std::pair<int, int>> blocks;
    const Profiles short_blocks = run(2, &blocks);
    const Profiles reference = run(32, nullptr);  // the set's longest blocks
    ASSERT_EQ(short_blocks.stats.block_bins, 2);
    ASSERT_GT(reference.stats.block_bins, 2);
    ASSERT_FALSE(blocks.empty());
    EXPECT_EQ(blocks.front().first, -7);
    for (std::size_t k = 0; k < blocks.size(); ++k) {
        EXPECT_LE(blocks[k].second, kSinkBins);
        if (k + 1 < blocks.size()) {
            EXPECT_EQ(blocks[k].first + blocks[k].second, blocks[k + 1].first);
            EXPECT_EQ(blocks[k].second % 2 == 0 || k == 0, true) << "only the first block starts mid-block";
        }
    }
    EXPECT_EQ(blocks.back().first + blocks.back().second, 301);
    EXPECT_LE(blocks.size(), std::size_t(308 / 32 + 2));  // not one per block of 2 bins
    float peak = 0.0f;
    for (float v : reference.total) peak = std::max(peak, v);
    ASSERT_GT(peak, 0.0f);
    float worst = 0.0f;
    for (std::size_t k = 0; k < reference.total.size(); ++k)
        worst = std::max(worst, std::abs(short_blocks.total[k] - reference.total[k]));
    for (std::size_t k = 0; k < reference.terms.size(); ++k)
        worst = std::max(worst, std::abs(short_blocks.terms[k] - reference.terms[k]));
    EXPECT_LE(worst, 1e-5f * peak);
    // Each patch's own row: the pulse of patch 3 is its order-0 light in bin 2, the spot (its energy
    // is the patch's radiosity in that bin) patch 17's order-1 light in its bin.
    EXPECT_FLOAT_EQ(float(short_blocks.term(0, 3, 2, 0)), 1.0f);
    EXPECT_FLOAT_EQ(float(short_blocks.term(0, 3, 2, 2)), 0.25f);
    for (std::size_t i = 0; i < n; ++i)
        if (i != 3) {
            EXPECT_EQ(short_blocks.term(0, i, 2, 0), 0.0) << i;
        }
    const int spot_bin = int(1.234 / 0.02);
    EXPECT_GE(short_blocks.term(1, 17, spot_bin, 0), 0.8 * (1 - 1e-6));
    EXPECT_GE(short_blocks.at(17, spot_bin, 0), 0.8 * (1 - 1e-6));
}

TEST(SolverBatch, GreyBatchesMatchSingleSolves) {
    // K = 1 and 3 (no specialisation for 3 grey lanes: the generic kernels), 5, 8 and 16 (their own).
    const Prepared p = corner();
    ASSERT_EQ(p.patches.size(), 128u);
    expect_batches_match_singles(p, batch_of(16, p.patches.size(), false), {1, 3, 5, 8, 16}, {}, 1);
}

TEST(SolverBatch, ColouredBatchesMatchSingleSolves) {
    // A coloured wall: 3 K lanes (3 with kernels of its own; 6, 15, 24 and 48 generic), with coloured
    // pulses in some illuminations.
    const Prepared p = corner(Rgb(0.7, 0.4, 0.2));
    expect_batches_match_singles(p, batch_of(16, p.patches.size(), true), {1, 2, 5, 8, 16}, {}, 3);
}

TEST(SolverBatch, OneColouredIlluminationColoursTheWholeBatch) {
    // Grey patches; illumination 1 (of 4) has a coloured pulse, so the batch marches 12 lanes while the
    // grey illuminations alone march one: each grey one's three lanes must still equal its grey solve.
    const Prepared p = corner();
    std::vector<Illumination> all = batch_of(4, p.patches.size(), false);
    all[1] = pulses_for(1, p.patches.size(), true);
    expect_batches_match_singles(p, all, {4}, {}, 3);
}

// Cluster links over a corner's patches (tolerance 0.05, for bins of 2 cm): the march pushes their
// light to the patches and pulls the patches' radiosity up at every bin.
LinkSet corner_clusters(const PatchSet& patches) {
    const Visibility vis(patches);
    HierarchyOptions h;
    h.tolerance = 0.05;
    h.bin_width_m = 0.02;
    return hierarchical_link_set(patches, vis, {}, h);
}

TEST(SolverBatch, HierarchicalLinksBatchesMatchSingleSolves) {
    // 512 patches with cluster links, K = 4.
    const Prepared flat = corner(Rgb::Constant(0.6), 0.0625);
    const LinkSet set = corner_clusters(flat.patches);
    ASSERT_GT(set.nodes(), set.patches());
    const TimeAxis time = time_axis(200, 0.02);
    const std::vector<Illumination> all = batch_of(4, flat.patches.size(), false);
    const std::vector<Profiles> out = solve_batch(flat.patches, set, all, time, {});
    EXPECT_EQ(out[0].stats.lanes, 4);
    for (int k = 0; k < 4; ++k) {
        const Profiles single = solve(flat.patches, set, all[std::size_t(k)], time);
        const double worst = worst_relative(out[std::size_t(k)], single);
        MEASURED("hierarchical, illumination %d: %.3g\n", k, worst);
        EXPECT_LE(worst, kBatchTolerance) << "illumination " << k;
    }
}

TEST(SolverBatch, PerOrderTermsMatchSingleSolves) {
    // Orders 0..3 exactly (max_bounces), and orders 0..3 plus the tail (bounce_terms with every order):
    // pulses of orders 0 to 2 and spots enter their own layers and terms, per illumination.
    const Prepared grey = corner(), coloured = corner(Rgb(0.7, 0.4, 0.2));
    SolverOptions exact, tail;
    exact.max_bounces = 3;
    exact.bounce_terms = 1;
    tail.bounce_terms = 5;
    for (const SolverOptions& options : {exact, tail}) {
        expect_batches_match_singles(grey, batch_of(8, grey.patches.size(), false), {5, 8}, options, 1);
        expect_batches_match_singles(coloured, batch_of(3, coloured.patches.size(), true), {3}, options, 3);
    }
}

TEST(SolverBatch, TimeIntegralOfEveryIlluminationIsItsSteadyState) {
    // A closed 1 m cube (96 patches, a coloured wall in the second case) lit by K illuminations of
    // pulses within the window: by linearity each one's profiles, summed over the bins, are its own
    // steady state. Light loses at least half its energy per bounce of at most sqrt(3) m: after 40 m,
    // below 1e-6.
    for (const bool colour : {false, true}) {
        Scene scene;
        scene.max_edge = 0.25;
        test::add_closed_cube(scene, 1.0, 0.5);
        if (colour) scene.objects[2].albedo = Rgb(0.7, 0.2, 0.2);
        const Prepared p = prepare(scene);
        const int K = colour ? 6 : 8;
        const std::vector<Illumination> all = batch_of(K, p.patches.size(), colour, false);
        const std::vector<Profiles> out = solve_batch(p.patches, p.links, all, time_axis(800, 0.05), {});
        EXPECT_EQ(out[0].stats.lanes, colour ? 3 * K : K);
        for (int k = 0; k < K; ++k) {
            const std::vector<Rgb> steady = solve_steady(p.patches, p.links, all[std::size_t(k)]);
            for (std::size_t i = 0; i < p.patches.size(); ++i)
                for (int c = 0; c < 3; ++c) {
                    double sum = 0.0;
                    for (int t = 0; t < out[std::size_t(k)].bins; ++t) sum += out[std::size_t(k)].at(i, t, c);
                    // As in Solver.TimeIntegralOfEveryProfileIsTheSteadyState: 1e-4 relative.
                    EXPECT_NEAR(sum, steady[i][c], 1e-4 * steady[i][c] + 1e-9)
                        << "illumination " << k << " patch " << i << " channel " << c;
                }
        }
    }
}

TEST(SolverBatch, WorkingMemoryGrowsWithTheLanes) {
    // Everything the march keeps per node and bin holds one float per lane, so the working memory is
    // a + b x lanes for a batch of grey illuminations: the steps from 1 to 2 and from 8 to 16 lanes
    // are 1 and 8 times one lane's share.
    const Prepared p = corner();
    const TimeAxis time = time_axis(250, 0.02);
    auto bytes = [&](int K) { return double(solve_working_bytes(p.patches, p.links, time, {}, K, 1)); };
    const double lane = bytes(2) - bytes(1);
    EXPECT_GT(lane, 0.0);
    EXPECT_EQ(bytes(16) - bytes(8), 8 * lane);
    // 4 coloured illuminations march 12 lanes, as 12 grey ones do; only the blocks handed to the sink
    // (N x 32 bins x K x 3 floats) differ.
    const std::size_t n = p.patches.size();
    EXPECT_EQ(solve_working_bytes(p.patches, p.links, time, {}, 12, 1) - solve_working_bytes(p.patches, p.links, time, {}, 4, 3),
              n * 32 * (12 - 4) * 3 * sizeof(float));
}

TEST(Solver, WideKernelsGiveBitIdenticalProfiles) {
    // The long-link kernels compiled for AVX-512 add the same products in the same order as the
    // library's own: on every schedule, a coloured illumination (3 lanes), grey batches of 1, 5, 8 and
    // 16 lanes (5: the generic kernels) and hierarchical links (the shortest window's kernel) give the
    // same floats either way.
    const Prepared flat = corner(Rgb(0.7, 0.4, 0.2));
    const Prepared fine = corner(Rgb(0.7, 0.4, 0.2), 0.0625);
    const Illumination coloured = pulses_for(1, flat.patches.size(), true);
    const Illumination fine_light = pulses_for(1, fine.patches.size(), true);
    const std::vector<Illumination> grey = batch_of(16, flat.patches.size(), false);
    const LinkSet set = corner_clusters(fine.patches);
    ASSERT_GT(set.nodes(), set.patches());
    if (!solve(flat.patches, flat.links, coloured, time_axis(10, 0.1)).stats.wide_kernels)
        GTEST_SKIP() << "this build or CPU has no AVX-512 kernels";
    for (const Schedule& schedule : kSchedules) {
        SolverOptions wide, narrow;
        wide.block_bins = narrow.block_bins = schedule.block_bins;
        narrow.wide_vectors = false;
        const Profiles a = solve(flat.patches, flat.links, coloured, schedule.time, wide);
        const Profiles n = solve(flat.patches, flat.links, coloured, schedule.time, narrow);
        EXPECT_TRUE(a.stats.wide_kernels);
        EXPECT_FALSE(n.stats.wide_kernels);
        EXPECT_EQ(a.total, n.total) << schedule.name;
        for (std::size_t K : {1, 5, 8, 16}) {
            const std::vector<Illumination> batch(grey.begin(), grey.begin() + std::ptrdiff_t(K));
            const std::vector<Profiles> wa = solve_batch(flat.patches, flat.links, batch, schedule.time, wide);
            const std::vector<Profiles> na = solve_batch(flat.patches, flat.links, batch, schedule.time, narrow);
            for (std::size_t k = 0; k < K; ++k)
                EXPECT_EQ(wa[k].total, na[k].total) << schedule.name << ", " << K << " lanes, illumination " << k;
        }
        const Profiles ha = solve(fine.patches, set, fine_light, schedule.time, wide);
        const Profiles hn = solve(fine.patches, set, fine_light, schedule.time, narrow);
        EXPECT_EQ(ha.total, hn.total) << schedule.name << ", hierarchical links";
    }
    // Dense rows: the kernels add into a receiver tile's own sums (contiguous) instead; from blocks of
    // 16 bins on, the packed kernels (whole 16-float vectors of sums), whose AVX2 copy sums 8-float vectors and
    // long windows in parts: coloured and grey, windows of 16 to 64 bins.
    Scene grey_cube = dense_cube(false);
    for (Object& o : grey_cube.objects) o.albedo = Rgb::Constant(0.5);
    grey_cube.lights[0] = PointLight{Vec3(0.3, 0.6, 0.7), Rgb::Constant(2.0)};
    for (const Prepared& dense : {prepare(dense_cube(false)), prepare(grey_cube)}) {
        ASSERT_GE(dense.links.links.size(), 256 * dense.patches.size());
        for (int block : {8, 16, 32}) {
            SolverOptions wide, narrow;
            wide.block_bins = narrow.block_bins = block;
            narrow.wide_vectors = false;
            const Profiles a = solve(dense, time_axis(300, 0.02), wide), n = solve(dense, time_axis(300, 0.02), narrow);
            EXPECT_EQ(a.stats.packed_links > 0, block > 8);
            EXPECT_EQ(a.stats.packed_links, n.stats.packed_links);
            EXPECT_EQ(a.total, n.total) << "dense rows, " << a.stats.channels << " channels, blocks of " << block;
        }
    }
}

TEST(SolverBatch, PackedBatchesMatchTheirSinglesWithEitherKernelCopy) {
    // Dense rows with 8 grey lanes and with 24 (8 coloured illuminations) take packed kernels too, whose
    // sums of a lane are those of its illumination alone (1 or 3 packed lanes): each illumination of the
    // batch against its single solve, and the AVX-512 copy against the AVX2 one, bit for bit.
    Scene grey_cube = dense_cube(false);
    for (Object& o : grey_cube.objects) o.albedo = Rgb::Constant(0.5);
    grey_cube.lights.clear();
    Scene coloured_cube = dense_cube(false);
    coloured_cube.lights.clear();
    for (const bool coloured : {false, true}) {
        const Prepared p = prepare(coloured ? coloured_cube : grey_cube);
        ASSERT_GE(p.links.links.size(), 256 * p.patches.size());
        const std::vector<Illumination> batch = batch_of(8, p.patches.size(), coloured);
        SolverOptions wide, narrow;
        narrow.wide_vectors = false;
        const TimeAxis time = time_axis(300, 0.02);
        const std::vector<Profiles> a = solve_batch(p.patches, p.links, batch, time, wide);
        const std::vector<Profiles> n = solve_batch(p.patches, p.links, batch, time, narrow);
        EXPECT_EQ(a[0].stats.lanes, coloured ? 24 : 8);
        EXPECT_GT(a[0].stats.packed_links, 0u);
        for (std::size_t k = 0; k < batch.size(); ++k) {
            EXPECT_EQ(a[k].total, n[k].total) << (coloured ? "coloured" : "grey") << ", illumination " << k;
            const Profiles single = solve(p.patches, p.links, batch[k], time, wide);
            EXPECT_GT(single.stats.packed_links, 0u);
            ASSERT_GT(*std::max_element(single.total.begin(), single.total.end()), 0.0f);
            EXPECT_LE(worst_relative(a[k], single), kBatchTolerance) << (coloured ? "coloured" : "grey") << ", illumination " << k;
        }
    }
}

TEST(SolverBatch, RejectsEmptyAndOversizedBatches) {
    const Prepared p = corner();
    const Illumination e = pulses_for(1, p.patches.size(), false);
    std::vector<const Illumination*> batch;
    const TimeAxis time = time_axis(10, 0.1);
    EXPECT_THROW(solve_transient(p.patches, p.links, std::span<const Illumination* const>(batch), time, {}, {}),
                 InternalError);
    batch.assign(std::size_t(kMaxBatch) + 1, &e);
    EXPECT_THROW(solve_transient(p.patches, p.links, std::span<const Illumination* const>(batch), time, {}, {}),
                 InternalError);
    batch.assign(std::size_t(kMaxBatch), &e);
    EXPECT_EQ(solve_transient(p.patches, p.links, std::span<const Illumination* const>(batch), time, {}, {}).lanes,
              kMaxBatch);
}

}  // namespace
}  // namespace tprf
