#pragma once
/// Form factors between Lambertian patches.
///
/// The inner integral is exact: the differential-area-to-polygon form factor by Lambert's contour
/// integral, F = (1 / 2 pi) sum_k theta_k n . (a_k x b_k) / |a_k x b_k|, with the polygon clipped to
/// the hemisphere above the point. The outer integral over the sending patch is a centroid rule for
/// distant pairs and adaptive subdivision for close ones, where the integrand varies fast.

#include "tprf/core/types.h"

#include <cstddef>

namespace tprf {

/// Form factor from a differential area at x with unit normal n to the convex planar polygon
/// `poly` (`count` corners, counter-clockwise about its front normal `poly_normal`). Zero when x is
/// behind the polygon; the part of the polygon below x's horizon is clipped away. Exact.
double point_polygon_form_factor(const Vec3& x, const Vec3& n, const Vec3* poly, std::size_t count,
                                 const Vec3& poly_normal);

/// atan2(s, c) for s >= 0 (the angle between two vectors, from |a x b| and a . b), to within a few
/// units in the last place; inline and without libm's slow paths (atan2 was a third of the link stage).
/// T is double, or a GCC/Clang vector of doubles, each lane on its own (the contour integral's edges
/// several at a time): every step is a select, not a branch.
template <class T>
inline T angle_between(T s, T c) {
    // Reduced to atan(t), 0 <= t <= 1, then to |u| <= tan(pi / 12) by
    // atan(t) = pi / 6 + atan((t sqrt3 - 1) / (t + sqrt3)), where the Taylor series of atan reaches
    // double precision within 14 terms (0.268^29 / 29 < 1e-18), summed as two interleaved halves.
    constexpr double kSqrt3 = 1.7320508075688772935;
    constexpr double kTanPi12 = 0.26794919243112270647;
    constexpr double kPi = 3.14159265358979323846;
    const T zero{}, one = zero + 1.0;
    const T ac = c < zero ? -c : c;
    const T hi = s > ac ? s : ac, lo = s > ac ? ac : s;
    const T t = lo / (hi > zero ? hi : one);
    const auto reduced = t > kTanPi12;
    const T u = reduced ? (t * kSqrt3 - 1.0) / (t + kSqrt3) : t;
    const T u2 = u * u, u4 = u2 * u2;
    // (-1)^k / (2k + 1): the even k in `even`, the odd in `odd`.
    const T even = 1.0 + u4 * (1.0 / 5 + u4 * (1.0 / 9 + u4 * (1.0 / 13 + u4 * (1.0 / 17 + u4 * (1.0 / 21 + u4 * (1.0 / 25))))));
    const T odd = -1.0 / 3 + u4 * (-1.0 / 7 + u4 * (-1.0 / 11 + u4 * (-1.0 / 15 + u4 * (-1.0 / 19 + u4 * (-1.0 / 23 + u4 * (-1.0 / 27))))));
    T a = u * (even + u2 * odd) + (reduced ? zero + kPi / 6.0 : zero);
    a = s > ac ? kPi / 2.0 - a : a;
    a = c < zero ? kPi - a : a;
    return hi > zero ? a : zero;  // 0 for s = c = 0 (and NaN)
}

/// Options of polygon_form_factor's adaptive quadrature.
struct FormFactorQuadrature {
    double relative_tolerance = 1e-2;  ///< stop refining a cell when its refinement changes F by less
    int max_depth = 5;                 ///< at most 4^max_depth cells
};

/// A convex planar polygon: `count` corners (3 or 4), counter-clockwise about its unit front normal.
struct PolygonView {
    const Vec3* corners = nullptr;
    std::size_t count = 0;
    Vec3 normal = Vec3::UnitZ();
};

/// Form factor F_ab from polygon a to polygon b, without occlusion: (1 / A_a) integral over a of
/// point_polygon_form_factor(x, n_a, b).
/// Over the part of a in front of b's plane (the rest sees b's back), by adaptive subdivision until
/// each cell's estimate is stable: quad cells by the centroid rule, triangle cells (a triangle, or
/// the fan of a cut polygon) by the three-point rule of degree 2, which stops two levels earlier.
double polygon_form_factor(const PolygonView& a, const PolygonView& b, const FormFactorQuadrature& quadrature = {});

/// The same form factor by a fixed product rule over a (2 x 2 Gauss points on a quad, the 3-point
/// degree-2 rule on a triangle): error O((size / distance)^4), for pairs a few sizes apart.
double polygon_form_factor_gauss(const PolygonView& a, const PolygonView& b);

/// Area of a planar polygon, m^2.
double polygon_area(const Vec3* poly, std::size_t count);

}  // namespace tprf
