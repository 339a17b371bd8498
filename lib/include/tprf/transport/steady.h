#pragma once
/// The steady state: continuous emission, infinite speed of light.

#include "tprf/core/types.h"

#include <vector>

namespace tprf {

struct PatchSet;
struct LinkSet;
struct Illumination;

/// Solves (I - diag(albedo) F) B = E for every channel (F's tinted links times their tint in that
/// channel, Links::tint) with BiCGSTAB (Eigen) to a relative residual below 1e-8, where E is each patch's time-integrated propagating emission; pulses that do not
/// propagate (the laser spot) are added afterwards. With max_bounces >= 0, sums the Neumann series
/// up to that order instead. Returns the radiosity of every row of `links` (the N patches, then any
/// glossy rows: LinkSet::glossy), W/m^2: by linearity, the sum over time of the
/// transient radiosity when the window holds all the light.
std::vector<Rgb> solve_steady(const PatchSet& patches, const LinkSet& links, const Illumination& emission,
                              int max_bounces = -1);

}  // namespace tprf
