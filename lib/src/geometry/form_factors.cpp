#include "tprf/geometry/form_factors.h"

#include "tprf/core/error.h"

#include <algorithm>
#include <array>
#include <cmath>
#ifdef __AVX__
#include <immintrin.h>
#endif

namespace tprf {
namespace {

// A convex planar cell of the outer quadrature: a triangle or a quad.
struct Cell {
    std::array<Vec3, 4> v;
    std::size_t count = 0;
};

// Polygon clipped to a half-space: a convex n-gon cut by a plane has at most n + 1 corners.
struct Clipped {
    std::array<Vec3, 9> v;
    std::size_t count = 0;
};

// Area and area centroid of a convex polygon, by a fan of triangles (a triangle's and a
// parallelogram's directly: their centroid is the corners' mean).
void area_centroid(const Vec3* p, std::size_t count, double& area, Vec3& centroid) {
    if (count == 3) {
        area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).norm();
        centroid = (p[0] + p[1] + p[2]) / 3.0;
        return;
    }
    if (count == 4 && (p[0] + p[2] - p[1] - p[3]).squaredNorm() <= 1e-24 * (p[2] - p[0]).squaredNorm()) {
        area = (p[1] - p[0]).cross(p[3] - p[0]).norm();
        centroid = 0.25 * (p[0] + p[1] + p[2] + p[3]);
        return;
    }
    Vec3 twice_normal_area = Vec3::Zero();
    Vec3 weighted = Vec3::Zero();
    for (std::size_t k = 1; k + 1 < count; ++k) {
        const Vec3 cross = (p[k] - p[0]).cross(p[k + 1] - p[0]);
        twice_normal_area += cross;
        weighted += cross.norm() * (p[0] + p[k] + p[k + 1]) / 3.0;
    }
    const double twice = twice_normal_area.norm();
    area = 0.5 * twice;
    // Weights are |cross|; their sum equals |sum of cross| for a convex planar polygon.
    double wsum = 0.0;
    for (std::size_t k = 1; k + 1 < count; ++k) wsum += (p[k] - p[0]).cross(p[k + 1] - p[0]).norm();
    centroid = wsum > 0 ? Vec3(weighted / wsum) : p[0];
}

// Midpoint subdivision into four cells of the same kind.
std::array<Cell, 4> split(const Cell& c) {
    std::array<Cell, 4> out;
    if (c.count == 3) {
        const Vec3 m01 = 0.5 * (c.v[0] + c.v[1]), m12 = 0.5 * (c.v[1] + c.v[2]), m20 = 0.5 * (c.v[2] + c.v[0]);
        out[0] = {{c.v[0], m01, m20, Vec3::Zero()}, 3};
        out[1] = {{m01, c.v[1], m12, Vec3::Zero()}, 3};
        out[2] = {{m20, m12, c.v[2], Vec3::Zero()}, 3};
        out[3] = {{m01, m12, m20, Vec3::Zero()}, 3};
    } else {
        const Vec3 m01 = 0.5 * (c.v[0] + c.v[1]), m12 = 0.5 * (c.v[1] + c.v[2]);
        const Vec3 m23 = 0.5 * (c.v[2] + c.v[3]), m30 = 0.5 * (c.v[3] + c.v[0]);
        const Vec3 mid = 0.25 * (c.v[0] + c.v[1] + c.v[2] + c.v[3]);
        out[0] = {{c.v[0], m01, mid, m30}, 4};
        out[1] = {{m01, c.v[1], m12, mid}, 4};
        out[2] = {{mid, m12, c.v[2], m23}, 4};
        out[3] = {{m30, mid, m23, c.v[3]}, 4};
    }
    return out;
}

// A cell's rule: the centroid for a quad; for a triangle the three-point rule of degree 2 (points at
// 2/3 of the way from the opposite edge's midpoint to each corner), exact for quadratic integrands.
// On the near pairs of a scanned statue (triangles, 3,000 pairs against a converged reference) the
// three-point rule stopped at depth 3 was more accurate than the centroid rule at depth 5, for fewer
// evaluations; on quads (the Cornell box's near pairs) the centroid rule was the cheaper of the two.
struct Rule {
    double richardson;  // the step toward the limit: the error falls 4x (centroid) or 16x per split
    int depth_offset;   // levels the rule stops before max_depth
};
constexpr Rule kQuadRule{1.0 / 3.0, 0};
constexpr Rule kTriangleRule{1.0 / 15.0, 2};
const Rule& rule_of(const Cell& c) { return c.count == 3 ? kTriangleRule : kQuadRule; }

struct Integrand {
    const Vec3* b;
    std::size_t b_count;
    Vec3 b_normal;
    Vec3 a_normal;

    // The cell's share of the integral: its area times the rule's mean of the point form factor.
    double operator()(const Cell& c) const {
        double area = 0.0;
        Vec3 centroid;
        area_centroid(c.v.data(), c.count, area, centroid);
        if (c.count == 4) return area * point_polygon_form_factor(centroid, a_normal, b, b_count, b_normal);
        double sum = 0.0;
        for (int k = 0; k < 3; ++k) {
            const Vec3 x = (2.0 / 3.0) * c.v[k] + (1.0 / 6.0) * (c.v[(k + 1) % 3] + c.v[(k + 2) % 3]);
            sum += point_polygon_form_factor(x, a_normal, b, b_count, b_normal);
        }
        return area * sum / 3.0;
    }
};

// When a cell stops being refined: its estimate stable to tolerance_per_area times its area, or max_depth
// levels down.
struct Refinement {
    double tolerance_per_area;
    int max_depth;
};

double refine(const Integrand& f, const Cell& cell, double estimate, double cell_area, int depth, const Refinement& stop) {
    const double tolerance_per_area = stop.tolerance_per_area;
    const int max_depth = stop.max_depth;
    const std::array<Cell, 4> children = split(cell);
    std::array<double, 4> parts{};
    double sum = 0.0;
    for (int k = 0; k < 4; ++k) sum += parts[k] = f(children[k]);
    // The rule's error falls as a power of the cell's size: the four children's sum is that much
    // nearer the integral than the parent's estimate, and Richardson's step removes that term.
    // For edge-adjacent triangles it cut the error about tenfold at the same cost (docs/method.md).
    const Rule& rule = rule_of(cell);
    if (depth >= max_depth - rule.depth_offset || std::abs(sum - estimate) <= tolerance_per_area * cell_area)
        return sum + (sum - estimate) * rule.richardson;
    double refined = 0.0;
    for (int k = 0; k < 4; ++k)
        refined += refine(f, children[k], parts[k], 0.25 * cell_area, depth + 1, stop);
    return refined;
}

// The part of polygon p (count corners) on the front side of the plane through `origin` with normal
// `normal`, by Sutherland-Hodgman; `relative`: its corners less `origin`. Corners within 1e-12 of the
// farthest corner's distance from `origin` of the plane are kept (a shared edge of perpendicular
// patches lies in it).
Clipped clip_to_front(const Vec3* p, std::size_t count, const Vec3& origin, const Vec3& normal, bool relative = false) {
    std::array<Vec3, 8> d;
    TPRF_DCHECK_LT(count, d.size() + 1);
    double scale2 = 0.0;
    for (std::size_t k = 0; k < count; ++k) {
        d[k] = p[k] - origin;
        scale2 = std::max(scale2, d[k].squaredNorm());
    }
    const double tolerance = 1e-12 * std::sqrt(scale2);
    const Vec3* corners = relative ? d.data() : p;
    Clipped out;
    for (std::size_t k = 0; k < count; ++k) {
        const std::size_t next = k + 1 < count ? k + 1 : 0;
        const double hx = normal.dot(d[k]), hy = normal.dot(d[next]);
        const bool in_x = hx >= -tolerance, in_y = hy >= -tolerance;
        const Vec3& x = corners[k];
        if (in_x) out.v[out.count++] = x;
        if (in_x != in_y) out.v[out.count++] = x + (hx / (hx - hy)) * (corners[next] - x);
    }
    return out;
}

// Doubles in one register (GCC's and Clang's vector extension): four under AVX (-march=x86-64-v3),
// two with SSE2 only, where a 32-byte vector would change how functions pass it.
#ifdef __AVX__
constexpr std::size_t kLanes = 4;
typedef double Lanes __attribute__((vector_size(32)));
#else
constexpr std::size_t kLanes = 2;
typedef double Lanes __attribute__((vector_size(16)));
#endif

// Lambert's contour sum, sum_k theta_k n . (b_k x a_k) / |b_k x a_k| over the edges (a_k, b_k) =
// (d[k], d[k + 1]) of a closed polygon given relative to the point, kLanes edges at a time. An edge
// whose line passes through the point (|b x a| <= 1e-300) subtends no angle and adds nothing.
double contour_sum(const Vec3* d, std::size_t count, const Vec3& n) {
    const Lanes zero{}, one = zero + 1.0;
    Lanes sum = zero;
    for (std::size_t k0 = 0; k0 < count; k0 += kLanes) {
        Lanes ax = zero, ay = zero, az = zero, bx = zero, by = zero, bz = zero;
        for (std::size_t l = 0; l < kLanes && k0 + l < count; ++l) {
            const Vec3& a = d[k0 + l];
            const Vec3& b = d[k0 + l + 1 < count ? k0 + l + 1 : 0];
            ax[l] = a.x(), ay[l] = a.y(), az[l] = a.z();
            bx[l] = b.x(), by[l] = b.y(), bz[l] = b.z();
        }
        const Lanes cx = by * az - bz * ay, cy = bz * ax - bx * az, cz = bx * ay - by * ax;
        const Lanes s2 = cx * cx + cy * cy + cz * cz;
#ifdef __AVX__
        const Lanes s = _mm256_sqrt_pd(s2);  // one instruction, where std::sqrt per lane is four and errno's check
#else
        Lanes s;
        for (std::size_t l = 0; l < kLanes; ++l) s[l] = std::sqrt(s2[l]);
#endif
        const auto lit = s > 1e-300;
        const Lanes theta = angle_between(s, ax * bx + ay * by + az * bz);
        const Lanes term = theta * (n.x() * cx + n.y() * cy + n.z() * cz) / (lit ? s : one);
        sum += lit ? term : zero;
    }
    double total = 0.0;
    for (std::size_t l = 0; l < kLanes; l += 2) total += sum[l] + sum[l + 1];
    return total;
}

}  // namespace

double polygon_area(const Vec3* poly, std::size_t count) {
    double area = 0.0;
    Vec3 centroid;
    area_centroid(poly, count, area, centroid);
    return area;
}

double point_polygon_form_factor(const Vec3& x, const Vec3& n, const Vec3* poly, std::size_t count,
                                 const Vec3& poly_normal) {
    TPRF_DCHECK_LT(count, std::size_t{9});
    // One-sided: from behind, the polygon's back is all one sees, and it sends nothing.
    if (poly_normal.dot(x - poly[0]) <= 0.0) return 0.0;

    // Clip to x's upper hemisphere (the plane n . (y - x) = 0). Corners that lie in that plane (a
    // shared edge of perpendicular patches) are kept: they add nothing.
    const Clipped d = clip_to_front(poly, count, x, n, true);  // corners relative to x
    if (d.count < 3) return 0.0;

    // Lambert's contour integral. With the polygon counter-clockwise about a normal that faces x,
    // b x a points toward the polygon's side of x, so every term of a front-facing polygon is >= 0.
    return std::max(0.0, contour_sum(d.v.data(), d.count, n) / (2.0 * M_PI));
}

double polygon_form_factor_gauss(const PolygonView& pa, const PolygonView& pb) {
    const Vec3* a = pa.corners;
    const std::size_t a_count = pa.count;
    const Vec3& a_normal = pa.normal;
    const Vec3* b = pb.corners;
    const std::size_t b_count = pb.count;
    const Vec3& b_normal = pb.normal;
    double sum = 0.0;
    if (a_count == 4) {
        // Bilinear map of the unit square; the Jacobian |x_u x x_v| weights each Gauss point.
        const double g = 0.5 / std::sqrt(3.0);
        double weight = 0.0;
        for (double u : {0.5 - g, 0.5 + g})
            for (double v : {0.5 - g, 0.5 + g}) {
                const Vec3 x = (1 - u) * (1 - v) * a[0] + u * (1 - v) * a[1] + u * v * a[2] + (1 - u) * v * a[3];
                const Vec3 xu = (1 - v) * (a[1] - a[0]) + v * (a[2] - a[3]);
                const Vec3 xv = (1 - u) * (a[3] - a[0]) + u * (a[2] - a[1]);
                const double jacobian = xu.cross(xv).norm();
                weight += jacobian;
                sum += jacobian * point_polygon_form_factor(x, a_normal, b, b_count, b_normal);
            }
        return weight > 0 ? sum / weight : 0.0;
    }
    TPRF_CHECK_EQ(a_count, std::size_t{3});
    for (int k = 0; k < 3; ++k) {
        const Vec3 x = (2.0 / 3.0) * a[k] + (1.0 / 6.0) * (a[(k + 1) % 3] + a[(k + 2) % 3]);
        sum += point_polygon_form_factor(x, a_normal, b, b_count, b_normal);
    }
    return sum / 3.0;
}

double polygon_form_factor(const PolygonView& pa, const PolygonView& pb, const FormFactorQuadrature& quadrature) {
    const Vec3* a = pa.corners;
    const std::size_t a_count = pa.count;
    const Vec3& a_normal = pa.normal;
    const Vec3* b = pb.corners;
    const std::size_t b_count = pb.count;
    const Vec3& b_normal = pb.normal;
    TPRF_CHECK(a_count == 3 || a_count == 4);
    double area = 0.0;
    Vec3 centroid;
    area_centroid(a, a_count, area, centroid);
    if (area <= 0.0) return 0.0;
    // Points of a behind b's plane see b's back, which sends nothing: the integrand steps to zero
    // where a crosses that plane. Integrated over the part in front only, so that no cell straddles
    // the step (on a mesh's near pairs, cells that did were estimated as wholly dark or wholly lit:
    // 1% of them were 100% off).
    const Clipped front = clip_to_front(a, a_count, b[0], b_normal);
    if (front.count < 3) return 0.0;
    // The cells to refine: a itself when nothing was cut, else a fan of triangles over the front part.
    std::array<Cell, 7> roots;
    std::size_t root_count = 0;
    bool cut = front.count != a_count;
    for (std::size_t k = 0; k < front.count && !cut; ++k) cut = front.v[k] != a[k];
    if (!cut) {
        roots[root_count].count = a_count;
        std::copy(a, a + a_count, roots[root_count++].v.begin());
    } else {
        for (std::size_t k = 1; k + 1 < front.count; ++k)
            roots[root_count++] = {{front.v[0], front.v[k], front.v[k + 1], Vec3::Zero()}, 3};
    }
    const Integrand f{b, b_count, b_normal, a_normal};
    // The tolerance follows the first refinement's average over the front part, so that pairs that
    // see each other weakly are refined as finely, relative to their own value, as strong ones.
    std::array<std::array<Cell, 4>, 7> children;
    std::array<std::array<double, 4>, 7> parts{};
    std::array<double, 7> root_area{};
    double first = 0.0, front_area = 0.0;
    for (std::size_t r = 0; r < root_count; ++r) {
        Vec3 c;
        area_centroid(roots[r].v.data(), roots[r].count, root_area[r], c);
        front_area += root_area[r];
        children[r] = split(roots[r]);
        for (int k = 0; k < 4; ++k) first += parts[r][k] = f(children[r][k]);
    }
    if (!(front_area > 0.0)) return 0.0;
    const double tolerance_per_area = quadrature.relative_tolerance * std::max(first / front_area, 1e-12);
    double total = 0.0;
    for (std::size_t r = 0; r < root_count; ++r)
        for (int k = 0; k < 4; ++k)
            total += refine(f, children[r][k], parts[r][k], 0.25 * root_area[r], 1,
                            {tolerance_per_area, quadrature.max_depth});
    return total / area;
}

}  // namespace tprf
