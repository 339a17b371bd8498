#pragma once
/// The sensing points of an NLOS capture (docs/capture.md): the grid points on
/// the relay wall as their devices see them, as a camera's pinhole samples are its pixels' points.
///
/// A wall point is both a laser spot (a Lambertian point that sends on what the laser deposits) and a
/// sensor point (it measures the radiance leaving it toward the sensor). What it sees of the patches,
/// in both directions, is one PatchView per patch (transport/patch_views.h).

#include "tprf/core/types.h"
#include "tprf/transport/light_sources.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct Scene;
struct PatchSet;
class Visibility;
struct CaptureGrid;

/// A grid point on the relay wall.
struct WallPoint {
    Vec3 point = Vec3::Zero();     ///< on the surface, metres
    Vec3 normal = Vec3::UnitZ();   ///< unit front normal of the surface there (toward its device)
    std::uint32_t patch = 0;       ///< the patch it lies on
    double device_leg = 0.0;       ///< metres from the device (laser or sensor) to the point
};

/// Both grids of a capture, each point (a, b) at index a * nv + b.
struct CapturePoints {
    std::vector<WallPoint> laser;   ///< the laser grid
    std::vector<WallPoint> sensor;  ///< the sensor grid (a confocal capture: the laser grid)
};

/// Finds every grid point of scene.capture on the front of the surface that its device sees. Throws
/// Error naming the scene file, the grid's JSON path and the point when a point lies on no surface,
/// is hidden from its device, or is seen from behind; or naming the device's position when the
/// device is inside or behind an object.
CapturePoints locate_capture_points(const Scene& scene, const PatchSet& patches, const Visibility& visibility);

/// The laser spot that wall point w is when a laser of `power` (W per channel) lights it, its light
/// leaving at `path` (spot_source() turns it into the Lambertian point source of the v1 laser model).
inline LaserSpot wall_spot(const WallPoint& w, const Rgb& power, double path) {
    return {true, w.patch, w.point, path, power};
}

/// The sensor cell of `grid` (index a * nv + b) that holds x, or -1 when x is off the grid's plane (by
/// more than `tolerance` metres) or outside it.
std::int64_t grid_cell(const CaptureGrid& grid, const Vec3& x, double tolerance);

}  // namespace tprf
