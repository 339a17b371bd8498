#pragma once
/// The gather: what each sensing point sees, as taps on the patch profiles and exact direct arrivals.
///
/// Light of later bounces comes from the patch profiles, interpolated at the point between the
/// neighbouring patches of the same surface (a smooth compact kernel over the centroids FLANN finds
/// near it), and shifted by the exact last leg. Direct light of point sources (point lights, laser
/// spots) is evaluated exactly at the point by the same arrive() that lights the patches
/// (transport/light_sources.h), with shadow rays and its exact path, so first arrivals are sharp; the
/// film leaves the matching patch pulses (Pulse::point_source) out of the profiles, so that nothing
/// is counted twice.

#include "tprf/core/progress.h"
#include "tprf/core/time_axis.h"
#include "tprf/core/types.h"
#include "tprf/imaging/sensing_points.h"
#include "tprf/transport/light_sources.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;
struct GlossyRows;
struct LightSources;
class Visibility;
class SecondBounceLight;

/// One patch's share of one output: radiance = weight * B_patch (t - leg), weight including 1/pi,
/// the interpolation weight and the point's weight.
struct PixelTap {
    std::uint32_t patch = 0;
    float weight = 0.0f;
    float leg = 0.0f;   ///< metres of optical path added (0 with camera.unwarp)
    /// Earliest path at which any light can reach the sensor through this point (the straight
    /// line from the nearest source to the point, plus the leg), metres. A patch profile is an
    /// average over its patch, so its leading edge can run a few patch sizes ahead of what reaches
    /// this very point; the film moves such light to this bound instead of showing light before it
    /// could have arrived.
    float earliest = 0.0f;
    std::uint16_t tint = 0;   ///< index into Gather::tints: the weight per channel is weight * tints[tint]
    /// Metres of path added to the light one link after its pulse (SecondBounceLight::shift at the
    /// point): the film reads that part of the profile at leg + shift, the rest at leg.
    float shift = 0.0f;
};

/// An exact direct-light arrival at one output: radiance times one second, at an exact path.
struct DirectArrival {
    std::uint32_t pixel = 0;    ///< the output (row * width + column for a camera)
    double path = 0.0;          ///< whole optical path, metres (the last leg left out when unwarped)
    Rgb radiance = Rgb::Zero(); ///< W s / (m^2 sr), already weighted by the point's share
    std::uint8_t order = 1;     ///< bounce order (1: point light; 2: lit by the laser point)
};

/// Everything the film needs to turn patch profiles into outputs.
struct Gather {
    int width = 0;                         ///< outputs = width * height (a camera's image size)
    int height = 0;
    std::vector<std::uint64_t> row;        ///< outputs + 1 offsets into `taps`
    std::vector<PixelTap> taps;
    std::vector<DirectArrival> direct;     ///< sorted by output
    std::vector<Rgb> tints;                ///< the taps' per-channel factors (SensingPoints::tints)
};

/// Options of the gather.
struct GatherOptions {
    int threads = 0;        ///< 0: all cores
    ProgressFn progress;    ///< phase "camera"
    /// The time axis: area sources' direct light is timed by cells whose paths span about half of its
    /// bin, and merged per bin of it (per sensing point). Without one, 4 x 4 cells and no merging.
    const TimeAxis* time = nullptr;
    int emitter_rays = kAreaShadowRays;     ///< shadow rays from a sensing point to an area source
    int penumbra_rays = kAreaPenumbraRays;  ///< where those disagree
    /// When given, each tap's shift is second_bounce->shift(patch, point) (camera.shift_second_bounce).
    const SecondBounceLight* second_bounce = nullptr;
    /// When given (and not empty), a point on a glossy patch takes a second tap beside its patch's: the
    /// out-cell row facing the sensor along the point's view (glossy_rows.h).
    const GlossyRows* glossy = nullptr;
};

/// One output's taps merged where a film on `time` cannot tell them apart: one patch and tint, legs in
/// the same half of one bin (and legs plus shifts in the same half bin). The merged tap has the sum of
/// the weights, the weighted mean leg and shift and the least earliest path. The film splits a leg
/// linearly between its bin and the next (or puts it in the nearer), so the two bins get the same
/// light as from the taps one by one (up to a float leg's precision, 5e-5 of a 5 mm bin at 2 m), and
/// its earliest bin is the least over a pixel's taps of a patch anyway. In the order of first
/// occurrence. gather_points does this for every output when it has a time axis: a pixel's samples at
/// spp 64 leave about 8x fewer taps.
void merge_taps(std::vector<PixelTap>& taps, const TimeAxis& time);

/// What a gather reads of the scene: the patches, the light sources and the visibility.
struct GatherScene {
    const PatchSet& patches;
    const LightSources& sources;
    const Visibility& visibility;
};

/// Prepares the gather of `points` (outputs laid out as width x height). Outputs without points
/// get no taps and stay zero.
Gather gather_points(const SensingPoints& points, int width, int height, const GatherScene& scene,
                     const GatherOptions& options = {});

}  // namespace tprf
