#pragma once
/// The sensing points of an NLOS capture (SPEC.md v2, "Capture"; docs/capture.md): the grid points on
/// the relay wall as their devices see them, and what a wall point sees of every patch.
///
/// A wall point is both a laser spot (a Lambertian point that sends on what the laser deposits) and a
/// sensor point (it measures the radiance leaving it toward the sensor). Both directions use one
/// description of the light between the point and a patch, a PatchView: the kernel cos cos / r^2 and
/// the exact path at stratified samples of the patch, from arrive() (transport/light_sources.h), the
/// function that times every other point source's light. So the light that leaves laser point l, is
/// reflected by patch j and reaches sensor point s is summed over the same samples from both ends,
/// which makes exhaustive captures reciprocal, and every sample's path is exact, which makes the
/// onsets exact to the bin.

#include "tprf/core/types.h"
#include "tprf/transport/light_sources.h"

#include <array>
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

/// Stratified samples per patch side that a PatchView takes (2 x 2 samples).
inline constexpr int kViewSide = 2;
inline constexpr int kViewSamples = kViewSide * kViewSide;

/// What a wall point x sees of one patch: at each stratified sample y of the patch, the kernel
/// g = V cos(at the wall) cos(at y) / |y - x|^2 (m^-2, 0 where hidden or behind) and the path |y - x|;
/// and how the path changes across the sample's cell (the quarter of the patch it stands for): along
/// the cell's half-axes h_u, h_v, the path's gradient (y - x) / |y - x| dotted with them. A cell's paths
/// from x then lie within path +- (|du| + |dv|) to first order, which times the cell's light as a box in
/// path length instead of one point (docs/capture.md, "Onsets").
/// Through mirrors and glass (Visibility::chains()), x's image through a chain sees the patch as well:
/// one more view of the same patch, its paths unfolded and its kernel times the chain's weight.
struct PatchView {
    std::uint32_t patch = 0;
    std::int32_t chain = -1;                 ///< -1: the straight view; else the chain it is seen through
    Vec3 from = Vec3::Zero();                ///< x, or its image through the chain, metres
    Rgb tint = Rgb::Ones();                  ///< the chain's tint (MirrorChain::tint): channel c's g is g * tint[c]
    std::array<float, kViewSamples> path{};  ///< metres
    std::array<float, kViewSamples> g{};     ///< m^-2
    std::array<float, kViewSamples> du{};    ///< metres: (y - x) / |y - x| . h_u
    std::array<float, kViewSamples> dv{};    ///< metres: (y - x) / |y - x| . h_v
};

/// The laser spot that wall point w is when a laser of `power` (W per channel) lights it, its light
/// leaving at `path` (spot_source() turns it into the Lambertian point source of the v1 laser model).
inline LaserSpot wall_spot(const WallPoint& w, const Rgb& power, double path) {
    return {true, w.patch, w.point, path, power};
}

/// The stratified samples of every patch and their cells' half-axes, the same for every wall point:
/// patch j's sample k at index j * kViewSamples + k.
struct ViewCells {
    std::vector<Vec3> point;  ///< the sample y, metres
    std::vector<Vec3> hu;     ///< the cell's half-axis along the patch's u, metres
    std::vector<Vec3> hv;     ///< ... and along its v
};

/// The samples and cells of every patch (for view_patches).
ViewCells view_cells(const PatchSet& patches);

/// Every patch that wall point w sees (some sample with g > 0), straight or through a chain of mirrors
/// and glass, in increasing patch order (then chain order, the straight view first).
std::vector<PatchView> view_patches(const WallPoint& w, const PatchSet& patches, const Visibility& visibility,
                                    const ViewCells& cells);

/// The sensor cell of `grid` (index a * nv + b) that holds x, or -1 when x is off the grid's plane (by
/// more than `tolerance` metres) or outside it.
std::int64_t grid_cell(const CaptureGrid& grid, const Vec3& x, double tolerance);

}  // namespace tprf
