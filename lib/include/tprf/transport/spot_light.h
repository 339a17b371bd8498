#pragma once
/// A capture's laser spot as a light source (docs/capture.md): the wall point that a laser lights is a
/// Lambertian point that sends on what the laser deposits (spot_source(), transport/light_sources.h).
/// Its light that needs no march is exact: at a wall point straight or through mirrors (the second
/// reflection, counting the spot as the first) and by way of one patch (the third), as boxes of light
/// over paths that the capture's film bins (imaging/capture_film.h), as the camera's film bins its exact
/// direct arrivals. What it sends into the patches is one pulse per patch, for the march of the later
/// reflections.

#include "tprf/core/types.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/patch_views.h"

#include <vector>

namespace tprf {

struct GlossyRows;

struct PatchSet;
struct TimeAxis;
class Visibility;

/// A capture's measure of light: the mean of the three channels.
inline double channel_mean(const Rgb& c) { return (c[0] + c[1] + c[2]) / 3.0; }

/// Light reaching a point by its path: `value` (radiance times one second, the channels' mean) spread
/// evenly over the paths [lo, hi], metres; a box of no width, or one within a bin, is a delta at lo.
struct PathBox {
    double lo = 0.0;
    double hi = 0.0;
    double value = 0.0;
};

/// The spot and its mirror images through the scene's mirrors and glass (point_images), as point
/// sources.
std::vector<PointSource> spot_sources(const LaserSpot& spot, const PatchSet& patches, const Visibility& visibility);

/// A surface point that a capture's exact light reaches: where it is, its unit front normal, its albedo,
/// and the metres that every path to it adds (its device leg, or 0).
struct Receiver {
    Vec3 point = Vec3::Zero();
    Vec3 normal = Vec3::UnitZ();
    Rgb albedo = Rgb::Zero();
    double leg = 0.0;
};

/// The second reflection: the light of each of `spots` (spot_sources) that reaches the receiver straight
/// (on a relay surface that is not planar) or through mirrors, radiance albedo I cos / (pi r^2) at the
/// exact path (arrive()) plus the receiver's leg, appended to `out`.
void spot_arrivals(const std::vector<PointSource>& spots, const Receiver& at, const Visibility& visibility,
                   std::vector<PathBox>& out);

/// The ends of a third reflection, spot -> patch j -> sensor point: what each sees of the patches (in
/// patch order, PatchViewer::view), the factor of both ends, albedo_l P albedo_s / (pi^3 kViewSamples),
/// and the metres added to every path (the device legs).
struct ThirdBounce {
    const std::vector<PatchView>& from_laser;
    const std::vector<PatchView>& from_sensor;
    Rgb ends = Rgb::Zero();
    double legs = 0.0;
    /// The views' samples (PatchViewer::cells): at a glossy patch, the BRDF between the directions to
    /// the two ends replaces albedo / pi at each sample.
    const ViewCells* cells = nullptr;
};

/// The third reflection, over the samples of every patch that both ends see (each view of one end with
/// each of the other's, straight and through mirrors), appended to `out`. Each sample's light is spread
/// over the paths of its cell: its exact path +- the first-order change across the cell, the start
/// clamped at the shortest path by way of the patch's plane. The path is convex in the point of the
/// patch, so the tangent's minimum over the cell is never later than the cell's true first light:
/// onsets are never late, and early only by the path's curvature across a cell (docs/capture.md).
void third_bounce(const PatchSet& patches, const ThirdBounce& ends, std::vector<PathBox>& out);

/// The pulses that `spot` sends into the patch system for a march on `time` (CSR by patch): each patch's
/// first-bounce exitance (the spot's albedo P / pi, over the samples) at its mean path (mean_view of
/// `views`, what the spot sees) plus the spot's path, split between the two bins of the march about it
/// as a tap splits its leg, each piece in the middle of its bin. The pulses are order 2 and belong to
/// point source 0 (the spot): a film takes them out of the profiles again (their light is
/// third_bounce's, exact per sample); they only feed the later reflections. With `glossy` rows (not
/// empty), a glossy patch's pulse also goes to its out-cells through the lobe from the spot's direction
/// (the rows after the patches: the CSR has a row for each).
Illumination spot_pulses(const PatchSet& patches, const LaserSpot& spot, const std::vector<PatchView>& views,
                         const TimeAxis& time, const GlossyRows* glossy = nullptr);

}  // namespace tprf
