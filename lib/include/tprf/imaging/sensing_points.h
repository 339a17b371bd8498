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
};

/// A set of sensing points, in output order (non-decreasing `output`).
struct SensingPoints {
    std::size_t outputs = 0;            ///< number of measurements (pixels)
    double weight = 1.0;                ///< each point's share of its output (a pixel sample: 1 / spp)
    std::vector<SensingPoint> points;
};

}  // namespace tprf
