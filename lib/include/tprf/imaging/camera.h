#pragma once
/// The pinhole camera as a producer of sensing points: every pixel sample's first visible front-facing
/// surface point, with the exact camera leg.

#include "tprf/imaging/gather.h"
#include "tprf/imaging/sensing_points.h"
#include "tprf/scene/scene.h"

namespace tprf {

struct PatchSet;
struct LightSources;
class Visibility;

/// The unit ray direction through the image position (column, row) in pixels, (0, 0) the image's
/// top-left corner (pixel (c, r)'s centre at (c + 0.5, r + 0.5)), through the camera's intrinsics and
/// distortion; zero where the distortion has no undistorted direction for it.
Vec3 camera_ray(const Camera& camera, double column, double row);

/// Traces the camera's samples (a g x g grid per pixel when spp is a square, spp = 1 the centre, else
/// the R2 sequence). Samples that see nothing, or the back of a one-sided surface, give no point. Each
/// point carries its share of the pixel as a cell on the surface (SensingPoint::du, dv): the square of
/// side 1 / sqrt(spp) pixels around it, by ray differentials through mirrors and onto the patch's plane.
SensingPoints pinhole_points(const Camera& camera, const PatchSet& patches, const Visibility& visibility,
                             int threads = 0);

/// pinhole_points, then gather_points: everything the film needs for this camera.
Gather prepare_camera(const Camera& camera, const PatchSet& patches, const LightSources& sources,
                      const Visibility& visibility, const GatherOptions& options = {});

}  // namespace tprf
