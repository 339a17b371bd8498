#pragma once
/// Illumination: the light that enters the patch system, as sparse pulses with exact arrival times.
///
/// Every emitter fires one delta pulse at t = 0 (docs/scene.md). What reaches patch i is a handful of pulses,
/// each at its own exact optical path (not the patch centroid's): a point source (transport/
/// light_sources.h: a point light, or a laser's spot, Lambertian or through its BRDF) reaches each
/// stratified sample point x of a patch at its path plus |source - x|; a laser spot's own patch
/// holds the reflected power at the spot's path; an emissive patch shows its own pulse at path 0,
/// and each area source (an emissive polygon, however many patches it is cut into) reaches each
/// patch in front of it with the energy of the exact patch-to-polygon form factor times the fraction
/// that shadow rays find unblocked, spread over the paths |y - x| between stratified points x of the
/// patch and y of the polygon in proportion to the point-to-point kernel cos cos / r^2. Its cost is
/// per patch and source, not per pair of patches.

#include "tprf/core/time_axis.h"
#include "tprf/core/types.h"
#include "tprf/transport/light_sources.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;
class Visibility;

/// One pulse of exitance at a patch.
struct Pulse {
    double path = 0.0;          ///< optical path length from the emitter to the patch, metres
    Rgb energy = Rgb::Zero();   ///< patch-averaged exitance times one second, W s / m^2 (J/m^2)
    std::uint8_t order = 0;     ///< surface reflections so far: 0 emissive surface, 1 lit directly
    bool propagates = true;     ///< false: seen by the camera, but its onward light is sent by an
                                ///< exact point source instead (the laser spot), so it is not
                                ///< propagated through the links a second time
    /// The point source (index into LightSources::points) whose direct light this is, or -1. Sensing
    /// points evaluate point sources exactly (imaging/gather.h), so the film leaves these pulses out
    /// of the patch profiles it interpolates.
    std::int32_t point_source = -1;
    /// The area source (index into LightSources::areas) whose first bounce this is, or -1. Sensing
    /// points evaluate area sources exactly too, and the film leaves these pulses out the same way.
    std::int32_t area_source = -1;

    /// Whether sensing points evaluate this pulse's light themselves (a point or area source's direct
    /// light), so that the film takes it out of the patch profiles it interpolates.
    bool exact_at_sensors() const { return point_source >= 0 || area_source >= 0; }
};

/// Pulses grouped by patch (CSR): patch i's pulses are pulses[row[i] .. row[i+1]).
struct Illumination {
    std::vector<std::uint64_t> row;
    std::vector<Pulse> pulses;
};

/// Options of the illumination stage.
struct IlluminationOptions {
    int samples = 16;           ///< stratified points per patch for point sources
    int area_samples = 4;       ///< stratified points per patch that area sources light
    /// Shadow rays from each of those points to an area source (to the centres of a grid of cells over
    /// it). The pulses' times come from a grid of cells whose paths span about half a bin of
    /// merge_bins (2 x 2 to 32 x 32 cells; 4 x 4 without merge_bins), each taking its shadow cell's ray.
    int emitter_rays = kAreaShadowRays;
    /// Where those rays disagree (a penumbra), the point's pairs take a grid of at least this many cells
    /// instead, with a shadow ray each.
    int penumbra_rays = kAreaPenumbraRays;
    int threads = 0;            ///< 0: all cores
    /// When set, a patch's pulses that fall in one bin of this axis with the same order, source and
    /// propagation are merged into one (at the first one's path): exact for every consumer, each of
    /// which places a pulse by the bin that holds its path, and a patch then keeps a few pulses per
    /// light instead of one per sample pair.
    const TimeAxis* merge_bins = nullptr;
};

/// Computes the pulses that every source (point sources, laser spots, area sources) sends into the
/// patch system. Shadow rays decide visibility.
Illumination illuminate(const LightSources& sources, const PatchSet& patches, const Visibility& visibility,
                        const IlluminationOptions& options = {});

}  // namespace tprf
