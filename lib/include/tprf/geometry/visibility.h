#pragma once
/// Ray visibility over the patch geometry (Embree 3).

#include "tprf/core/types.h"
#include "tprf/geometry/mirror_images.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace tprf {

struct PatchSet;
struct Scene;

/// The closest surface a ray hits.
struct RayHit {
    bool hit = false;
    double distance = 0.0;      ///< metres along the (unit) ray direction
    std::uint32_t patch = 0;    ///< the patch hit (for two-sided objects: the side facing the ray)
    bool front = false;         ///< the ray hit the patch's front (lit) side
    Vec3 point = Vec3::Zero();  ///< metres
};

/// A surface that a ray traced through mirrors and glass reaches (Visibility::trace).
struct TracedHit {
    RayHit hit;                 ///< the surface; hit.distance is the last straight piece only
    double path = 0.0;          ///< metres from the ray's origin, every specular leg included
    double weight = 1.0;        ///< product of the (mean) reflectances and transmittances on the way
    Rgb tint = Rgb::Ones();     ///< product of the reflections' tints (SpecularPlane::tint)
    /// The reflections' linear part: the last piece's direction is turn * (the ray's direction), and so
    /// are the changes of direction of neighbouring rays (ray differentials through mirrors).
    Eigen::Matrix3d turn = Eigen::Matrix3d::Identity();
};

/// A bounding-volume hierarchy over every patch polygon, and the specular planes of the scene (mirrors
/// and glass, geometry/mirror_images.h). Thread-safe for queries once built.
class Visibility {
public:
    /// Builds the hierarchy. Every patch is opaque from both sides, whatever its own sidedness, except
    /// the patches of glass planes, which pass their transmittance. Chains of up to `max_specular`
    /// reflections between the planes are enumerated (mirror_chains).
    explicit Visibility(const PatchSet& patches, std::vector<SpecularPlane> planes = {}, int max_specular = 0);
    ~Visibility();
    Visibility(const Visibility&) = delete;
    Visibility& operator=(const Visibility&) = delete;

    /// True when something opaque lies strictly between a and b (the end points' own surfaces excluded
    /// by a relative epsilon). Glass does not occlude: see transmittance().
    bool occluded(const Vec3& a, const Vec3& b) const;

    /// The share of light that passes straight from a to b: 0 when occluded, else the product of the
    /// transmittances of the glass crossed (1 without glass).
    double transmittance(const Vec3& a, const Vec3& b) const;

    /// Most segments transmittances() takes at once.
    static constexpr int kBatch = 8;
    /// transmittance() of `count` (at most kBatch) segments a[k] to b[k] at once, into passed[k]: the
    /// same answers, the occlusion tests as one packet of rays (rays between two nearby patches or
    /// clusters share most of their way through the hierarchy).
    void transmittances(const Vec3* a, const Vec3* b, int count, double* passed) const;

    /// Light from the point y whose image through `chain` is `image`, seen from x: the chain's
    /// reflectance times the transmittance of every real leg, when the straight segment from x to
    /// `image` crosses each unfolded plane of the chain in turn, from its reflecting side and within
    /// its polygons; else 0 (and `through`, when given, is set false: the path does not exist, as
    /// opposed to being shadowed).
    double unfolded(const MirrorChain& chain, const Vec3& x, const Vec3& image, bool* through = nullptr) const;

    /// The share of light that passes from y to x straight (chain -1: transmittance(x, y)) or along
    /// chains()[chain], y being then the image of the sending point (unfolded).
    double passes(int chain, const Vec3& x, const Vec3& y) const {
        return chain < 0 ? transmittance(x, y) : unfolded(m_chains[std::size_t(chain)], x, y);
    }

    /// The surfaces along origin + s * direction (unit): the first one, and where it is a mirror or
    /// glass, what its reflection (and glass' transmission) reaches in turn, up to max_specular
    /// reflections. Appends to `out`, which holds the first surface first.
    void trace(const Vec3& origin, const Vec3& direction, std::vector<TracedHit>& out) const;

    /// The first surface along origin + s * direction (unit), s in (0, max_distance), glass included.
    RayHit intersect(const Vec3& origin, const Vec3& direction, double max_distance) const;
    /// intersect() of `count` (at most kBatch) rays from one origin along directions[k], into out[k],
    /// traced as one packet: for rays that start together and point nearly the same way (a pixel's
    /// camera samples), which share most of their way through the hierarchy.
    void intersect_from(const Vec3& origin, const Vec3* directions, int count, double max_distance, RayHit* out) const;

    /// The specular planes and their chains.
    const std::vector<SpecularPlane>& planes() const { return m_planes; }
    const std::vector<MirrorChain>& chains() const { return m_chains; }
    /// The specular plane of patch i, or -1.
    int plane_of(std::uint32_t patch) const;
    bool has_glass() const { return m_glass; }

    /// Offset used to lift ray end points off their surfaces, metres (scales with the scene size).
    double epsilon() const { return m_epsilon; }

private:
    RayHit first_hit(const Vec3& origin, const Vec3& direction, double max_distance, std::int64_t prim, double t) const;

    struct Impl;
    std::unique_ptr<Impl> m_impl;
    double m_epsilon = 0.0;
    std::vector<SpecularPlane> m_planes;
    std::vector<MirrorChain> m_chains;
    std::vector<int> m_object_plane;   // per object index: its plane, or -1
    int m_max_specular = 0;
    bool m_glass = false;
};

/// The visibility of a scene's patches with its mirrors and glass (specular_planes, and chains of up
/// to solver.max_specular reflections).
std::unique_ptr<Visibility> scene_visibility(const Scene& scene, const PatchSet& patches);

}  // namespace tprf
