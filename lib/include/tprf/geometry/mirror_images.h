#pragma once
/// Specular planes (mirrors and thin glass) and the mirror images they make.
///
/// A planar mirror adds to the scene a mirror image of everything in front of it, seen through the
/// mirror's polygon: light from y that reflects at p on the mirror towards x travels as far as the
/// straight line from x to y's image y', and arrives from the direction of y'. A sequence of such
/// reflections (a MirrorChain) unfolds the same way: the image of y through planes S1, ..., Sk (in the
/// order light meets them going from x towards y) is R1 R2 ... Rk y, Rj the reflection across Sj, and
/// the straight segment from x to it crosses S1, R1(S2), R1 R2(S3), ... in turn, each within the image
/// of that plane's polygon, wherever the real path exists. Transfer, lights, lasers and the camera all
/// use this unfolding (geometry/visibility.h checks it on a given segment; docs/materials.md).

#include "tprf/core/types.h"

#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <vector>

namespace tprf {

struct Scene;
struct PatchSet;

/// A mirror or a glass object: one plane and the convex polygons that cover it.
struct SpecularPlane {
    std::uint32_t object = 0;        ///< index into Scene::objects
    Vec3 point = Vec3::Zero();       ///< a point of the plane, metres
    Vec3 normal = Vec3::UnitZ();     ///< unit front normal
    double reflectance = 0.0;        ///< specular reflectance: the mean over the channels
    Rgb tint = Rgb::Ones();          ///< each channel's reflectance over `reflectance` (ones when grey)
    double transmittance = 0.0;      ///< glass: straight-through transmittance (grey); 0 for a mirror
    bool both_sides = false;         ///< glass reflects on both sides, a mirror on its front only
    /// Polygon k is corners[first[k] .. first[k + 1]), convex, counter-clockwise about `normal`.
    std::vector<Vec3> corners;
    std::vector<std::uint32_t> first{0};
    Eigen::AlignedBox3d box;         ///< of every corner

    std::size_t polygons() const { return first.size() - 1; }
    /// Whether the point p of the plane lies in one of its polygons (borders included, to a relative
    /// tolerance).
    bool contains(const Vec3& p) const;
    /// Whether it reflects light arriving from the side `side` (+1 front, -1 back).
    bool reflects_from(int side) const { return reflectance > 0.0 && (side > 0 || both_sides); }
};

/// Reflection across a plane as an affine map p -> linear p + offset.
struct Unfolding {
    Eigen::Matrix3d linear = Eigen::Matrix3d::Identity();  ///< orthogonal
    Vec3 offset = Vec3::Zero();

    Vec3 operator()(const Vec3& p) const { return linear * p + offset; }
    /// The inverse map (linear is orthogonal).
    Vec3 inverse(const Vec3& p) const { return linear.transpose() * (p - offset); }
    /// The map p -> this(inner(p)).
    Unfolding after(const Unfolding& inner) const { return {linear * inner.linear, linear * inner.offset + offset}; }
    /// The reflection across the plane through `point` with unit normal `normal`.
    static Unfolding reflection(const Vec3& point, const Vec3& normal);
};

/// Most reflections a chain holds.
inline constexpr int kMaxChain = 16;

/// Specular reflections in the order light meets them going from the receiving end x towards the
/// sending end y: planes[0] first. image(y) is where y appears from x.
struct MirrorChain {
    int length = 0;
    std::array<std::uint16_t, kMaxChain> plane{};  ///< indices into the planes
    std::array<std::int8_t, kMaxChain> side{};     ///< +1: reflects on the plane's front, -1: its back
    double reflectance = 1.0;                      ///< product of the planes' (mean) reflectances
    Rgb tint = Rgb::Ones();                        ///< product of the planes' tints: channel c carries
                                                   ///< reflectance * tint[c]
    Unfolding unfold;                              ///< R1 R2 ... Rk

    Vec3 image(const Vec3& y) const { return unfold(y); }
};

/// The specular planes of a scene, one per mirror or glass object, from its patches. Throws Error (the
/// object's JSON path) when a specular object is not planar within 1e-6 of its size.
std::vector<SpecularPlane> specular_planes(const Scene& scene, const PatchSet& patches);

/// Every chain of 1 .. max_length reflections between planes that can see each other (consecutive
/// planes differ; each lies partly on the reflecting side of the one before). At most `limit` chains:
/// more throws Error naming `solver.max_specular`.
std::vector<MirrorChain> mirror_chains(const std::vector<SpecularPlane>& planes, int max_length,
                                       std::size_t limit = 4096);

/// The chain read the other way (light from x to y instead of y to x): image of x seen from y.
MirrorChain reversed(const MirrorChain& chain, const std::vector<SpecularPlane>& planes);

/// Clips the convex polygon `poly` (its corners in order) to the cone of rays from `apex` through the
/// convex polygon `window` (corners counter-clockwise about `window_normal`, apex on its front side when
/// front_apex, else on its back side). Returns the corners left (possibly none).
std::vector<Vec3> clip_to_window(const std::vector<Vec3>& poly, const Vec3& apex, const Vec3* window,
                                 std::size_t window_count, bool front_apex);

}  // namespace tprf
