#include "tprf/geometry/form_factors.h"

#include "test_scenes.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

namespace tprf {
namespace {

// Square [x0,x0+a] x [y0,y0+b] at height z, counter-clockwise about `up` (+z or -z).
std::array<Vec3, 4> square(double x0, double y0, double a, double b, double z, bool facing_up) {
    std::array<Vec3, 4> q = {Vec3(x0, y0, z), Vec3(x0 + a, y0, z), Vec3(x0 + a, y0 + b, z), Vec3(x0, y0 + b, z)};
    if (!facing_up) std::swap(q[1], q[3]);
    return q;
}

TEST(FormFactors, PointToParallelSquareMatchesHowellB3) {
    // The point under the centre of a 2 x 2 square at distance 1 sees four corner rectangles 1 x 1.
    const auto q = square(-1, -1, 2, 2, 1.0, false);
    const double f = point_polygon_form_factor(Vec3::Zero(), Vec3::UnitZ(), q.data(), 4, -Vec3::UnitZ());
    // The contour integral is exact: only rounding separates it from the closed form.
    EXPECT_NEAR(f, 4 * test::ff_point_parallel_rectangle_corner(1, 1, 1), 1e-12);
    // Off-centre: the point under a corner of a 1 x 2 rectangle at distance 0.5.
    const auto r = square(0, 0, 1, 2, 0.5, false);
    EXPECT_NEAR(point_polygon_form_factor(Vec3::Zero(), Vec3::UnitZ(), r.data(), 4, -Vec3::UnitZ()),
                test::ff_point_parallel_rectangle_corner(1, 2, 0.5), 1e-12);
}

TEST(FormFactors, AngleBetweenMatchesAtan2) {
    // Over every octant boundary and reduction branch, tiny and huge magnitudes, and the exact
    // values: within a few units in the last place of libm's correctly rounded atan2.
    double worst = 0.0;
    std::uint64_t state = 12345;
    auto next = [&] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return double(state >> 11) * 0x1.0p-53;
    };
    for (int k = 0; k < 200000; ++k) {
        const double scale = std::ldexp(1.0, int(next() * 80) - 40);
        const double s = next() * scale, c = (2 * next() - 1) * scale;
        worst = std::max(worst, std::abs(angle_between(s, c) - std::atan2(s, c)));
    }
    for (double t : {0.0, 0.2679491924311227, 0.26794919243112276, 0.5, 1.0, 2.0, 1e-300, 1e300})
        for (double c : {1.0, -1.0, 0.0}) worst = std::max(worst, std::abs(angle_between(t, c) - std::atan2(t, c)));
    MEASURED("angle_between: worst |error| against atan2 %.3g rad\n", worst);
    EXPECT_LT(worst, 4 * std::numeric_limits<double>::epsilon());
    EXPECT_EQ(angle_between(0.0, 0.0), 0.0);
    EXPECT_EQ(angle_between(0.0, 1.0), 0.0);
    EXPECT_NEAR(angle_between(1.0, 0.0), M_PI / 2, 1e-16);
    EXPECT_NEAR(angle_between(0.0, -1.0), M_PI, 1e-15);
}

TEST(FormFactors, PointBehindOrBelowHorizonSeesNothing) {
    const auto facing_away = square(-1, -1, 2, 2, 1.0, true);
    EXPECT_EQ(point_polygon_form_factor(Vec3::Zero(), Vec3::UnitZ(), facing_away.data(), 4, Vec3::UnitZ()), 0.0);
    // A polygon entirely below the point's horizon.
    const auto below = square(-1, -1, 2, 2, -1.0, true);
    EXPECT_EQ(point_polygon_form_factor(Vec3::Zero(), Vec3::UnitZ(), below.data(), 4, Vec3::UnitZ()), 0.0);
}

TEST(FormFactors, ClippingAtTheHorizonKeepsTheVisibleHalf) {
    // A vertical square straddling the horizon of an upward-facing point: only its upper half counts,
    // and the upper half alone is a perpendicular rectangle of known form factor from the point.
    const std::array<Vec3, 4> full = {Vec3(1, -1, -1), Vec3(1, 1, -1), Vec3(1, 1, 1), Vec3(1, -1, 1)};
    const std::array<Vec3, 4> upper = {Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(1, 1, 1), Vec3(1, -1, 1)};
    std::array<Vec3, 4> f = full, u = upper;
    // Counter-clockwise about -x (facing the point at the origin).
    std::swap(f[1], f[3]);
    std::swap(u[1], u[3]);
    const double clipped = point_polygon_form_factor(Vec3::Zero(), Vec3::UnitZ(), f.data(), 4, -Vec3::UnitX());
    const double half = point_polygon_form_factor(Vec3::Zero(), Vec3::UnitZ(), u.data(), 4, -Vec3::UnitX());
    EXPECT_GT(half, 0.0);
    EXPECT_NEAR(clipped, half, 1e-12);
}

TEST(FormFactors, ParallelSquaresMatchHowellC11) {
    const auto a = square(0, 0, 1, 1, 0.0, true);
    const auto b = square(0, 0, 1, 1, 1.0, false);
    const FormFactorQuadrature fine{1e-4, 7};
    const double f = polygon_form_factor({a.data(), 4, Vec3::UnitZ()}, {b.data(), 4, -Vec3::UnitZ()}, fine);
    EXPECT_NEAR(test::ff_parallel_rectangles(1, 1, 1), 0.19982, 1e-5);  // the catalogue's value
    // Adaptive tolerance 1e-4 relative per cell: measured 1.8e-5 off in total; bound about 3 times that.
    EXPECT_NEAR(f / test::ff_parallel_rectangles(1, 1, 1), 1.0, 6e-5);
    // The default rule (1e-3 per cell, at most 4^5 cells): measured 1.6e-4; bound about 4 times that.
    const double d = polygon_form_factor({a.data(), 4, Vec3::UnitZ()}, {b.data(), 4, -Vec3::UnitZ()});
    EXPECT_NEAR(d / test::ff_parallel_rectangles(1, 1, 1), 1.0, 6e-4);
    // The fixed Gauss rule on one unit square at unit distance, far outside its intended range (pairs a
    // few sizes apart): error O((size/distance)^4), measured 7.3e-3; 1e-2 bounds that order.
    const double g = polygon_form_factor_gauss({a.data(), 4, Vec3::UnitZ()}, {b.data(), 4, -Vec3::UnitZ()});
    EXPECT_NEAR(g / test::ff_parallel_rectangles(1, 1, 1), 1.0, 1e-2);
}

TEST(FormFactors, PerpendicularSquaresSharingAnEdgeMatchHowellC14) {
    // Floor [0,1]^2 at z=0 facing up and wall x=0 facing +x share the edge x=0, z=0.
    const auto floor = square(0, 0, 1, 1, 0.0, true);
    const std::array<Vec3, 4> wall = {Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 1, 1), Vec3(0, 0, 1)};
    // Counter-clockwise about +x: (0,0,0) -> (0,1,0) -> (0,1,1) -> (0,0,1) turns from +y to +z. Good.
    const double f = polygon_form_factor({floor.data(), 4, Vec3::UnitZ()}, {wall.data(), 4, Vec3::UnitX()},
                                         FormFactorQuadrature{1e-4, 7});
    EXPECT_NEAR(test::ff_perpendicular_rectangles(1, 1, 1), 0.20004, 1e-5);
    // The integrand's gradient is singular along the shared edge: adaptive refinement at 1e-4 per
    // cell still measures 1.5e-5 off in total; bound about 4 times that.
    EXPECT_NEAR(f / test::ff_perpendicular_rectangles(1, 1, 1), 1.0, 6e-5);
    // The default (coarser, for speed) rule: measured 1.8e-4; bound about 3 times that.
    const double d = polygon_form_factor({floor.data(), 4, Vec3::UnitZ()}, {wall.data(), 4, Vec3::UnitX()});
    EXPECT_NEAR(d / test::ff_perpendicular_rectangles(1, 1, 1), 1.0, 6e-4);
}

TEST(FormFactors, AFloorReachingBehindAWallIntegratesOnlyItsPartInFront) {
    // Floor [-0.5, 1] x [0, 1] facing up; wall x = 0 facing +x. Points of the floor at x < 0 see the
    // wall's back, which sends nothing, so F = (area in front / area) F_C14 = F_C14 / 1.5. The first
    // cells of the rule straddle x = 0: a rule that integrates across the step misses the lit strip.
    const auto floor = square(-0.5, 0, 1.5, 1, 0.0, true);
    const std::array<Vec3, 4> wall = {Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 1, 1), Vec3(0, 0, 1)};
    const double expected = test::ff_perpendicular_rectangles(1, 1, 1) / 1.5;
    const double d = polygon_form_factor({floor.data(), 4, Vec3::UnitZ()}, {wall.data(), 4, Vec3::UnitX()});
    // Measured 5.5e-7 (3.9% before the rule cut the floor at the wall's plane); the bound is the default
    // rule's on the square alone (PerpendicularSquaresSharingAnEdgeMatchHowellC14).
    EXPECT_NEAR(d / expected, 1.0, 6e-4);
    // A floor wholly behind the wall: nothing.
    const auto behind = square(-1, 0, 0.5, 1, 0.0, true);
    EXPECT_EQ(polygon_form_factor({behind.data(), 4, Vec3::UnitZ()}, {wall.data(), 4, Vec3::UnitX()}), 0.0);
}

TEST(FormFactors, TheTwoTrianglesOfASquareSendWhatTheSquareSends) {
    // The floor square of the C-14 pair cut along its diagonal from the wall's corner: one triangle
    // shares an edge with the wall, the other only a corner. A_1 F_1 + A_2 F_2 = A F_C14 (A = 1).
    const std::array<Vec3, 3> edge = {Vec3(0, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
    const std::array<Vec3, 3> corner = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)};
    const std::array<Vec3, 4> wall = {Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 1, 1), Vec3(0, 0, 1)};
    const double f_edge = polygon_form_factor({edge.data(), 3, Vec3::UnitZ()}, {wall.data(), 4, Vec3::UnitX()});
    const double f_corner = polygon_form_factor({corner.data(), 3, Vec3::UnitZ()}, {wall.data(), 4, Vec3::UnitX()});
    EXPECT_GT(f_edge, f_corner);  // the triangle along the wall sees more of it
    // Measured 5.5e-7 off; the bound is the default rule's on the whole square.
    EXPECT_NEAR((0.5 * f_edge + 0.5 * f_corner) / test::ff_perpendicular_rectangles(1, 1, 1), 1.0, 6e-4);
}

}  // namespace
}  // namespace tprf
