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

/// Options of polygon_form_factor's adaptive quadrature.
struct FormFactorQuadrature {
    double relative_tolerance = 1e-2;  ///< stop refining a cell when its refinement changes F by less
    int max_depth = 5;                 ///< at most 4^max_depth cells
};

/// Form factor F_ab from polygon a to polygon b (both convex, planar, CCW about their normals),
/// without occlusion: (1 / A_a) integral over a of point_polygon_form_factor(x, n_a, b).
/// Adaptive subdivision of a until each cell's estimate is stable.
double polygon_form_factor(const Vec3* a, std::size_t a_count, const Vec3& a_normal, const Vec3* b,
                           std::size_t b_count, const Vec3& b_normal,
                           const FormFactorQuadrature& quadrature = {});

/// The same form factor by a fixed product rule over a (2 x 2 Gauss points on a quad, the 3-point
/// degree-2 rule on a triangle): error O((size / distance)^4), for pairs a few sizes apart.
double polygon_form_factor_gauss(const Vec3* a, std::size_t a_count, const Vec3& a_normal, const Vec3* b,
                                 std::size_t b_count, const Vec3& b_normal);

/// Area of a planar polygon, m^2.
double polygon_area(const Vec3* poly, std::size_t count);

}  // namespace tprf
