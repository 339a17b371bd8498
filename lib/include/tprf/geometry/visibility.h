#pragma once
/// Ray visibility over the patch geometry (Embree 3).

#include "tprf/core/types.h"

#include <cstdint>
#include <memory>

namespace tprf {

struct PatchSet;

/// The closest surface a ray hits.
struct RayHit {
    bool hit = false;
    double distance = 0.0;      ///< metres along the (unit) ray direction
    std::uint32_t patch = 0;    ///< the patch hit (for two-sided objects: the side facing the ray)
    bool front = false;         ///< the ray hit the patch's front (lit) side
    Vec3 point = Vec3::Zero();  ///< metres
};

/// A bounding-volume hierarchy over every patch polygon. Thread-safe for queries once built.
class Visibility {
public:
    /// Builds the hierarchy. Every patch is opaque from both sides, whatever its own sidedness.
    explicit Visibility(const PatchSet& patches);
    ~Visibility();
    Visibility(const Visibility&) = delete;
    Visibility& operator=(const Visibility&) = delete;

    /// True when something lies strictly between a and b (the end points' own surfaces excluded
    /// by a relative epsilon).
    bool occluded(const Vec3& a, const Vec3& b) const;

    /// The first surface along origin + s * direction (unit), s in (0, max_distance).
    RayHit intersect(const Vec3& origin, const Vec3& direction, double max_distance) const;

    /// Offset used to lift ray end points off their surfaces, metres (scales with the scene size).
    double epsilon() const { return m_epsilon; }

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
    double m_epsilon = 0.0;
};

}  // namespace tprf
