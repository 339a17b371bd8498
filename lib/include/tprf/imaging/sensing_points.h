#pragma once
/// Sensing points: where a sensor looks at the scene. A pinhole camera's pixel samples are one
/// producer (imaging/camera.h), the sensor points of a relay wall the next; the gather
/// (imaging/gather.h) turns any set of them into time profiles the same way.

#include "tprf/core/types.h"

#include <cstdint>
#include <vector>

namespace tprf {

/// A surface point that a sensor measures: the radiance leaving it towards the sensor, delayed by
/// the last leg to the sensor.
struct SensingPoint {
    std::uint32_t output = 0;   ///< the measurement it adds to (a pixel: row * width + column)
    std::uint32_t patch = 0;    ///< the patch it lies on (its front side faces the sensor)
    Vec3 point = Vec3::Zero();  ///< metres
    float leg = 0.0f;           ///< metres of optical path from the point to the sensor (0: unwarped)
    /// The share of the point's light that reaches the sensor: the product of the reflectances and
    /// transmittances of the mirrors and glass on its way (1 on a straight line of sight).
    float throughput = 1.0f;
    /// Where tinted mirrors colour the way: an index into SensingPoints::tints (0: grey).
    std::uint16_t tint = 0;
    /// The leg's change across the point's cell, metres (0 when unwarped): leg + leg_du * s + leg_dv * t
    /// at point + du * s + dv * t, s and t in [-1, 1].
    float leg_du = 0.0f, leg_dv = 0.0f;
    /// The point's cell on the surface: what the point stands for, when it is one sample of a pixel
    /// (a pinhole camera's sample: its share of the pixel square, traced onto the surface to first
    /// order), as two half-axes, metres. Zero for a point that is itself the measurement (a capture's
    /// sensor point). The gather spreads the point's direct light over the paths of its cell, so that a
    /// pixel's light is spread over the times its footprint spans rather than over spp instants.
    Eigen::Vector3f du = Eigen::Vector3f::Zero(), dv = Eigen::Vector3f::Zero();
    /// The unit direction from the point towards the sensor along the last straight leg (after the
    /// mirrors); where the point is glossy, what its BRDF reflects towards. Zero when not known.
    Eigen::Vector3f view = Eigen::Vector3f::Zero();
};

/// A set of sensing points, in output order (non-decreasing `output`).
struct SensingPoints {
    std::size_t outputs = 0;            ///< number of measurements (pixels)
    double weight = 1.0;                ///< each point's share of its output (a pixel sample: 1 / spp)
    std::vector<SensingPoint> points;
    /// Per-channel factors of the points' throughput: tints[0] = ones; empty when every point is grey.
    std::vector<Rgb> tints;

    /// The index of `tint` in `tints`, added when new (0 for grey).
    std::uint16_t tint_index(const Rgb& tint);
    /// Point p's per-channel factor.
    Rgb tint_of(const SensingPoint& p) const { return tints.empty() ? Rgb::Ones() : tints[p.tint]; }
};

}  // namespace tprf
