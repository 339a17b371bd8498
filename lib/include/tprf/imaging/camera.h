#pragma once
/// The pinhole camera: which patches each pixel sees, how late, and the direct light it sees exactly.
///
/// Each pixel sample finds its visible point x (Embree). Light of later bounces comes from the patch
/// profiles, interpolated at x between the neighbouring patches of the same surface (a smooth compact
/// kernel over the centroids FLANN finds near x), and shifted by the exact camera leg |x - camera|.
/// Direct light from point lights and the laser point is evaluated exactly at x, with shadow rays
/// and its exact path, so first arrivals are sharp; the matching patch-level pulses are taken out
/// of the profiles (Pulse::exact_at_camera) so that nothing is counted twice.

#include "tprf/core/types.h"
#include "tprf/core/progress.h"
#include "tprf/scene/scene.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;
class Visibility;

/// One patch's share of one pixel: radiance = weight * B_patch (t - leg), weight including 1/pi,
/// the interpolation weight and 1/spp.
struct PixelTap {
    std::uint32_t patch = 0;
    float weight = 0.0f;
    float leg = 0.0f;   ///< metres of optical path added (0 with camera.unwarp)
    /// Earliest path at which any light can reach the camera through this sample (the straight
    /// line from the nearest emitter to the visible point, plus the leg), metres. A patch profile
    /// is an average over its patch, so its leading edge can run a few patch sizes ahead of what
    /// reaches this very point; the film moves such light to this bound instead of showing light
    /// before it could have arrived.
    float earliest = 0.0f;
};

/// An exact direct-light arrival at one pixel: radiance times one second, at an exact path.
struct DirectArrival {
    std::uint32_t pixel = 0;    ///< row * width + column
    double path = 0.0;          ///< whole optical path, metres (camera leg left out with unwarp)
    Rgb radiance = Rgb::Zero(); ///< W s / (m^2 sr), already divided by spp
    std::uint8_t order = 1;     ///< bounce order (1: point light; 2: lit by the laser point)
};

/// Everything the camera needs to turn patch profiles into pixels.
struct CameraGather {
    int width = 0;
    int height = 0;
    std::vector<std::uint64_t> row;        ///< width * height + 1 offsets into `taps`
    std::vector<PixelTap> taps;
    std::vector<DirectArrival> direct;     ///< sorted by pixel
};

/// Options of the camera stage.
struct CameraOptions {
    int threads = 0;        ///< 0: all cores
    ProgressFn progress;    ///< phase "camera"
};

/// Traces the camera's samples and prepares the gather. Pixels that see nothing (or the back of a
/// one-sided surface) get no taps and stay zero.
CameraGather prepare_camera(const Camera& camera, const Scene& scene, const PatchSet& patches,
                            const Visibility& visibility, const CameraOptions& options = {});

/// The pixel's ray direction for the sub-pixel position (sx, sy) in [0,1)^2; row 0 is the top.
Vec3 camera_ray(const Camera& camera, double column, double row);

}  // namespace tprf
