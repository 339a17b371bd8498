#pragma once
/// Illumination: the light that enters the patch system, as sparse pulses with exact arrival times.
///
/// Every emitter fires one delta pulse at t = 0 (SPEC). What reaches patch i is a handful of pulses,
/// each at its own exact optical path (not the patch centroid's): a point source (transport/
/// light_sources.h: a point light, or a laser's spot seen as a Lambertian point) reaches each
/// stratified sample point x of a patch at its path plus |source - x|; a laser spot's own patch
/// holds the reflected power at the spot's path; an emissive patch shows its own pulse at path 0,
/// and its direct light reaches each linked patch with the energy of the exact form factor, spread
/// over the paths |y - x| between stratified points y of the emitter and x of the receiver in
/// proportion to the point-to-point kernel cos cos / r^2 (visibility included).

#include "tprf/core/time_axis.h"
#include "tprf/core/types.h"
#include "tprf/transport/light_sources.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;
struct Links;
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
};

/// Pulses grouped by patch (CSR): patch i's pulses are pulses[row[i] .. row[i+1]).
struct Illumination {
    std::vector<std::uint64_t> row;
    std::vector<Pulse> pulses;
};

/// Options of the illumination stage.
struct IlluminationOptions {
    int samples = 16;           ///< stratified points per patch for point sources
    int area_samples = 4;       ///< stratified points per patch on each side of an emitter's link
    int threads = 0;            ///< 0: all cores
    /// When set, a patch's pulses that fall in one bin of this axis with the same order, source and
    /// propagation are merged into one (at the first one's path): exact for every consumer, each of
    /// which places a pulse by the bin that holds its path, and a patch then keeps a few pulses per
    /// light instead of one per sample pair.
    const TimeAxis* merge_bins = nullptr;
};

/// Computes the pulses that every source (point sources, laser spots, emissive patches) sends into
/// the patch system. Shadow rays decide visibility from point sources. `emitters`: patch-to-patch
/// links by receiver whose sources emit (LinkSet::emitters; links from other sources are skipped).
Illumination illuminate(const LightSources& sources, const PatchSet& patches, const Links& emitters,
                        const Visibility& visibility, const IlluminationOptions& options = {});

}  // namespace tprf
