#pragma once
/// The film of an NLOS capture (docs/capture.md): what each sensor point measures, made as the camera's
/// film makes a pixel (imaging/film.h). The light that needs no march (orders 1 to 3, the laser spot
/// counted as the first reflection) arrives at exact paths and is binned there, as the camera's exact
/// direct arrivals are; the later orders are read from the solved patch profiles, less the pulses the
/// spot sent into them, through the sensor point's taps, as a pixel reads them through its taps. Every
/// value is the mean of the three channels (the capture's measure), radiance times seconds per bin.

#include "tprf/core/types.h"
#include "tprf/imaging/capture_points.h"
#include "tprf/imaging/film.h"
#include "tprf/scene/scene.h"
#include "tprf/transport/patch_views.h"
#include "tprf/transport/spot_light.h"

#include <cmath>
#include <cstdint>
#include <vector>

namespace tprf {

struct GlossyRows;

struct PatchSet;
struct Illumination;
class Visibility;

/// How a capture bins light: H's bins (the scene's time axis) and the march's (march_time(): bins
/// march_factor times wider, from the same start), and how a leg between two bins is placed.
struct CaptureBins {
    int bins = 0;                 ///< T: H's bins per (laser point, sensor point) pair
    BinMap scene;                 ///< H's bins (the scene's time axis)
    BinMap march;                 ///< the march's bins: the same start, march_factor times wider
    int march_factor = 1;         ///< Capture::march_bin_factor
    DelayMode delay = DelayMode::Linear;

    /// H's bin of a path, metres.
    std::int64_t bin(double path) const { return scene.bin(path); }
    /// The march's bin of a path, metres.
    std::int64_t march_bin(double path) const { return march.bin(path); }
};

/// Adds light at exact paths to a row of H (bins.bins bins), in order: a box's value spread evenly over
/// its paths, each bin taking its share of the interval; a box of no width, or within one bin, whole in
/// the bin of its lower end. Light outside the window is dropped.
void add_path_boxes(const CaptureBins& bins, const std::vector<PathBox>& boxes, float* row);

/// What a capture's exact light crosses: the capture (its sensor grid, laser power and max_bounces),
/// the patches and the visibility.
struct CaptureScene {
    const Capture& capture;
    const PatchSet& patches;
    const Visibility& visibility;
    const ViewCells& cells;  ///< the patches' view samples (PatchViewer::cells), where glossy patches reflect
};

/// A laser point and a sensor point of a capture, as their exact light needs them.
struct WallPair {
    const WallPoint& laser;
    const WallPoint& sensor;
    std::int64_t sensor_cell = 0;   ///< the sensor point's index in the sensor grid
    double laser_leg = 0.0;         ///< metres added to every path: the device legs when the capture
    double sensor_leg = 0.0;        ///< accounts them (account_first_and_last_bounces), else 0
    const std::vector<PointSource>& spots;       ///< the laser point's spot and its images (spot_sources)
    const std::vector<PatchView>& laser_views;   ///< what each point sees of the patches
    const std::vector<PatchView>& sensor_views;
};

/// The light of the pair's laser point that reaches its sensor point without a march, the orders that
/// capture.max_bounces keeps, appended to `out`: 1. the spot itself, where the sensor point's grid cell
/// holds it (its exitance albedo P spread over the cell, radiance albedo P / (pi A_cell)); 2. the
/// spot's light reaching the sensor point straight or through mirrors (spot_arrivals); 3. spot ->
/// patch -> sensor point over the samples both see (third_bounce).
void exact_light(const CaptureScene& scene, const WallPair& pair, std::vector<PathBox>& out);

/// One sensor point's share of a patch's profile: radiance = weight . B_patch(t - leg), per colour.
struct SensorTap {
    std::uint32_t patch = 0;   ///< the row it reads: a patch's, or a glossy patch's out-cell
    Rgb weight = Rgb::Zero();  ///< albedo_s A_j / (pi^2 S) sum g, per colour (sr^-1)
    double leg = 0.0;          ///< the g-weighted mean path from the patch to the point, metres
    std::uint32_t surface = 0; ///< the patch it lies on (`patch`, or the out-cell's patch)
};

/// A sensor point's taps on the patches it sees (`views`, PatchViewer::view), one per view with any
/// light, in the views' order (patch order): `leg` (its device leg, or 0) joins every tap's.
/// With `glossy` rows (not empty), a glossy patch's tap is joined by taps on its out-cells about the
/// direction to the sensor point (GlossyRows::cells_about), the same weight shared among them.
std::vector<SensorTap> sensor_taps(const PatchSet& patches, const WallPoint& sensor, double leg,
                                   const std::vector<PatchView>& views, const GlossyRows* glossy = nullptr);

/// Films a batch of laser points marched together (lane k of every block is laser point k's
/// illumination) at their sensor points, into their rows of H. Each lane's profiles, less the pulses
/// its spot sent (their light is exact_light's), are read by each tap at its leg, split between two
/// bins (or rounded, with solver.delay nearest). A march on bins F times wider (march_bin_factor) is
/// spread back over the scene's bins: march bin k stands for the path k F scene bins after the start
/// (as a delta there is split between the two march bins about it), and its light goes to the scene's
/// bins about that path by linear interpolation, a hat F bins wide on either side. Each bin's light is
/// kept, and so is its mean path.
class CaptureFilm : public Film {
public:
    /// One laser point of the batch.
    struct Lane {
        float* rows = nullptr;                ///< its row of H for its first sensor point; the others follow, T bins each
        const Illumination* pulses = nullptr; ///< what its spot sent into the patches (spot_pulses)
        /// Its sensor points' taps, in the order of its rows.
        const std::vector<std::vector<SensorTap>>* taps = nullptr;
        double* received = nullptr;           ///< or null: the light each of the first sensor point's taps gave it, added up
    };

    CaptureFilm(const CaptureBins& bins, std::vector<Lane> lanes, int threads);

    /// Films every lane's profiles of the block (lanes in parallel).
    void add_block(const SolveBlock& block) override;
    /// Nothing is kept between blocks.
    void finish() override {}

private:
    void add_lane(const SolveBlock& block, std::size_t lane, std::vector<float>& indirect) const;
    double add_tap(const SensorTap& tap, float* out, const SolveBlock& block, const std::vector<float>& indirect) const;

    CaptureBins m_bins;
    std::vector<Lane> m_lanes;
    int m_threads;
};

}  // namespace tprf
