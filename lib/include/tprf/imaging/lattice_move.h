#pragma once
/// A confocal scan's later light moved from a marched lattice of its points to the points between
/// (Capture::march_grid_step; docs/capture.md, "A marched lattice"). A later path leaves the point for a
/// patch i and comes back from a patch j; only those two legs depend on the point. So a lattice point
/// q's later light moves to a point l by the change of its last legs, weighted as q received its later
/// light from each patch, and the first legs change likewise (the scan is confocal: the first legs'
/// light is the last legs' by reciprocity): its paths lengthen by twice the change of the mean last
/// leg (less the sensor's device leg, plus the laser's), and its light scales by the square of the
/// change of the last legs' factors. With the patches' light at q fixed this is exact to first order in
/// the step from q to l. Patches that l sees and q's later light did not come back from add nothing.

#include "tprf/imaging/capture_film.h"

#include <cstdint>
#include <vector>

namespace tprf {

/// A confocal point's last legs by patch: a patch's taps added up (straight and through mirrors, and a
/// glossy patch's out-cells with its own patch row: the lobe's change between points is left out),
/// `factor` the colour mean of their weights and `leg` their factor-weighted mean leg, metres; at a
/// marched point, `light` is the later light the point received by way of the patch (summed over the
/// bins).
struct PatchLeg {
    std::uint32_t patch = 0;
    float factor = 0.0f;
    float leg = 0.0f;
    float light = 0.0f;
};

/// `taps` (sensor_taps: in patch order) by the patch they lie on (SensorTap::surface); `received`, if
/// not null, each tap's light (only patches that received some are kept then).
std::vector<PatchLeg> patch_legs(const std::vector<SensorTap>& taps, const double* received);

/// The marched coordinates along a grid side of `count` points: every step-th from 0, and the last.
std::vector<int> lattice(int count, int step);

/// A confocal scan's later bounces marched at a lattice of its points: the marched coordinates along
/// each side, and in lattice order (a major) each lattice point's laser point, its device legs as the
/// paths count them, its later light (T bins each) and its last legs, lattice point k's
/// legs[start[k], start[k + 1]), with their light's sum and light-weighted mean leg.
struct LatticeLight {
    std::vector<int> as, bs;
    std::vector<std::size_t> points;
    std::vector<double> laser_leg, sensor_leg;
    std::vector<float> later;
    std::vector<std::uint64_t> start;
    std::vector<PatchLeg> legs;
    std::vector<double> light, mean_leg;

    /// Fills start, light and mean_leg from `legs` and each lattice point's count of them.
    void index(const std::vector<std::uint64_t>& counts);
};

/// A point of the scan that takes moved light: its grid coordinates, its device legs as the paths count
/// them, and its last legs (patch_legs of its taps).
struct MovedPoint {
    int a = 0;
    int b = 0;
    double laser_leg = 0.0;
    double sensor_leg = 0.0;
    const std::vector<PatchLeg>& legs;
};

/// Adds to `out` (the point's row of H) the later light of the (up to) four lattice points around it,
/// each moved to it and the four blended bilinearly, each shift split between two bins as a tap splits
/// its leg (or rounded, with solver.delay nearest). A lattice point takes its own light (weight 1, moved
/// by nothing).
void add_moved(const LatticeLight& marched, const MovedPoint& to, const CaptureBins& bins, float* out);

}  // namespace tprf
