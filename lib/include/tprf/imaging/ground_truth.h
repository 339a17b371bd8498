#pragma once
/// Ground truth per pixel (docs/outputs.md, "Ground truth maps"): what the ray through each pixel's
/// centre meets first, as maps a time-of-flight engineer compares a camera's estimates with: the
/// distance along the ray, the surface's normal, the point, the object and its diffuse albedo.

#include "tprf/core/types.h"

#include <cstdint>
#include <string_view>
#include <vector>

namespace tprf {

struct Camera;
struct PatchSet;
class Visibility;

/// The maps that `--aov` names, as bits.
enum AovMap : unsigned {
    kAovDepth = 1u << 0,     ///< aov_depth (H, W): metres along the ray, inf where it meets nothing
    kAovNormal = 1u << 1,    ///< aov_normal (H, W, 3): the unit normal of the side met (towards the camera), 0 where nothing
    kAovPosition = 1u << 2,  ///< aov_position (H, W, 3): metres, NaN where nothing
    kAovObject = 1u << 3,    ///< aov_object (H, W) int32: the index in `objects`, -1 where nothing
    kAovAlbedo = 1u << 4,    ///< aov_albedo (H, W, 3): the diffuse albedo of the side met (0: a one-sided back)
};

/// The maps of a comma-separated list ("depth,normal"); "all" names every one. Throws Error naming
/// `what` (the flag or key it came from) for an empty list or an unknown name.
unsigned parse_aov_list(std::string_view list, std::string_view what);

/// The maps of `maps` for `camera`, each pixel's centre ray through the camera's intrinsics and
/// distortion to the first surface it meets (mirrors and glass are surfaces here, like any other).
struct GroundTruth {
    int width = 0, height = 0;
    std::vector<float> depth;           ///< H x W
    std::vector<float> normal;          ///< H x W x 3
    std::vector<float> position;        ///< H x W x 3
    std::vector<std::int32_t> object;   ///< H x W
    std::vector<float> albedo;          ///< H x W x 3
};
GroundTruth ground_truth(const Camera& camera, const PatchSet& patches, const Visibility& visibility, unsigned maps,
                         int threads = 0);

}  // namespace tprf
