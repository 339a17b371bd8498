#pragma once
/// What a point on a surface sees of the patches (docs/capture.md): at stratified samples of every
/// patch, the kernel g = V cos cos / r^2 and the exact path, from arrive() (transport/light_sources.h),
/// the function that times every other point source's light.
///
/// A capture describes the light between a relay-wall point and a patch this one way in both
/// directions: from a laser spot (the pulses it sends into the patches and its exact third bounce,
/// transport/spot_light.h) and toward a sensor point (its taps on the patches' profiles,
/// imaging/capture_film.h). So the light that leaves laser point l, is reflected by patch j and reaches
/// sensor point s is summed over the same samples from both ends, which makes exhaustive captures
/// reciprocal, and every sample's path is exact, which makes the onsets exact to the bin.

#include "tprf/core/types.h"

#include <array>
#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;
struct PointSource;
class Visibility;

/// Stratified samples per patch side that a PatchView takes (2 x 2 samples).
inline constexpr int kViewSide = 2;
inline constexpr int kViewSamples = kViewSide * kViewSide;

/// What a surface point x sees of one patch: at each stratified sample y of the patch, the kernel
/// g = V cos(at x) cos(at y) / |y - x|^2 (m^-2, 0 where hidden or behind) and the path |y - x|;
/// and how the path changes across the sample's cell (the quarter of the patch it stands for): along
/// the cell's half-axes h_u, h_v, the path's gradient (y - x) / |y - x| dotted with them. A cell's paths
/// from x then lie within path +- (|du| + |dv|) to first order, which times the cell's light as a box in
/// path length instead of one point (docs/capture.md, "Onsets").
/// Through mirrors and glass (Visibility::chains()), x's image through a chain sees the patch as well:
/// one more view of the same patch, its paths unfolded and its kernel times the chain's weight.
struct PatchView {
    std::uint32_t patch = 0;
    std::int32_t chain = -1;                 ///< -1: the straight view; else the chain it is seen through
    Vec3 from = Vec3::Zero();                ///< x, or its image through the chain, metres
    Rgb tint = Rgb::Ones();                  ///< the chain's tint (MirrorChain::tint): channel c's g is g * tint[c]
    std::array<float, kViewSamples> path{};  ///< metres
    std::array<float, kViewSamples> g{};     ///< m^-2
    std::array<float, kViewSamples> du{};    ///< metres: (y - x) / |y - x| . h_u
    std::array<float, kViewSamples> dv{};    ///< metres: (y - x) / |y - x| . h_v
};

/// The stratified samples of every patch and their cells' half-axes, the same for every surface point:
/// patch j's sample k at index j * kViewSamples + k.
struct ViewCells {
    std::vector<Vec3> point;  ///< the sample y, metres
    std::vector<Vec3> hu;     ///< the cell's half-axis along the patch's u, metres
    std::vector<Vec3> hv;     ///< ... and along its v
};

/// Views the patches from surface points: the patches' samples and cells are laid out once, for every
/// point.
class PatchViewer {
public:
    PatchViewer(const PatchSet& patches, const Visibility& visibility);

    /// Every patch that the point x (unit front normal n, on patch `own`, which it does not see) sees
    /// (some sample with g > 0), straight or through a chain of mirrors and glass, in increasing patch
    /// order (then chain order, the straight view first).
    std::vector<PatchView> view(const Vec3& x, const Vec3& n, std::uint32_t own) const;
    /// The patches' samples and cells that every view takes.
    const ViewCells& cells() const { return m_cells; }

private:
    bool view_patch(const PointSource& probe, const Vec3& wall_normal, std::size_t j, PatchView& v) const;

    const PatchSet& m_patches;
    const Visibility& m_visibility;
    ViewCells m_cells;
};

/// The g-weighted mean path from the point to a view's patch, and the sum of g: what both ends of a
/// capture's marched light use (the spot's pulse into the patch, the sensor point's tap on it), so that
/// exchanging laser and sensor points exchanges identical pieces.
struct MeanView {
    double sum = 0.0;
    double path = 0.0;
};

inline MeanView mean_view(const PatchView& v) {
    MeanView m;
    double moment = 0.0;
    for (int k = 0; k < kViewSamples; ++k) {
        m.sum += double(v.g[std::size_t(k)]);
        moment += double(v.g[std::size_t(k)]) * double(v.path[std::size_t(k)]);
    }
    if (m.sum > 0.0) m.path = moment / m.sum;
    return m;
}

}  // namespace tprf
