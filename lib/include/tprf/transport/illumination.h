#pragma once
/// Emitters: the light that enters the patch system, as sparse pulses with exact arrival times.
///
/// Every emitter fires one delta pulse at t = 0 (SPEC). What reaches patch i is a handful of pulses,
/// each at its own exact optical path (not the patch centroid's): a point light's pulse reaches each
/// stratified sample point x of a patch at |light - x|; a laser deposits its power at the point X it
/// hits, and X then lights the other patches as a Lambertian point source, with delays
/// |origin - X| + |X - x|; an emissive patch shows its own pulse at path 0, and its direct light
/// reaches each linked patch with the energy of the exact form factor, spread over the paths
/// |y - x| between stratified points y of the emitter and x of the receiver in proportion to the
/// point-to-point kernel cos cos / r^2 (visibility included).

#include "tprf/core/types.h"
#include "tprf/core/progress.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct Scene;
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
    bool exact_at_camera = false;  ///< the camera re-evaluates this light exactly at each visible
                                   ///< point (point-light and laser-point direct light)
};

/// Pulses grouped by patch (CSR): patch i's pulses are pulses[row[i] .. row[i+1]).
struct Emission {
    std::vector<std::uint64_t> row;
    std::vector<Pulse> pulses;
};

/// Options of the emitter stage.
struct EmitterOptions {
    int samples = 16;           ///< stratified points per patch for point lights and the laser point
    int area_samples = 4;       ///< stratified points per patch on each side of an emitter's link
    int threads = 0;            ///< 0: all cores
};

/// The hit point of a laser, if it hits a front side.
struct LaserSpot {
    bool hit = false;
    std::uint32_t patch = 0;
    Vec3 point = Vec3::Zero();  ///< metres
    double path = 0.0;          ///< |origin - point|, metres
    Rgb power = Rgb::Zero();    ///< the laser's power, W per channel
};

/// Where a laser's ray first meets the scene (a back side absorbs: hit stays false).
LaserSpot find_laser_spot(const Vec3& origin, const Vec3& direction, const PatchSet& patches,
                          const Visibility& visibility);

/// The spots of every laser of the scene, in the order of `scene.lights` (lasers only).
std::vector<LaserSpot> find_laser_spots(const Scene& scene, const PatchSet& patches, const Visibility& visibility);

/// Computes the pulses that every emitter of the scene (lights and emissive patches) sends into the
/// patch system. Shadow rays decide visibility from point lights and the laser point.
Emission compute_emission(const Scene& scene, const PatchSet& patches, const Links& links,
                          const Visibility& visibility, const EmitterOptions& options = {});

}  // namespace tprf
