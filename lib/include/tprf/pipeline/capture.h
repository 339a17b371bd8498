#pragma once
/// The NLOS capture (docs/capture.md): H[t, laser point, sensor point] of a
/// relay-wall scan, every illumination a laser spot on the wall, solved in batches that share one
/// read of the links per block.
///
/// What reaches sensor point s from laser point l, by the number of surface reflections:
/// 1. the spot itself, when it lies in s's grid cell: albedo P / (pi A_cell), the spot's exitance
///    spread over the cell that the sensor point stands for;
/// 2. the spot's light reaching s directly (zero on a planar wall);
/// 3. spot -> patch j -> s, summed over stratified samples y of every patch that both see, each at its
///    exact path |l - y| + |y - s| (transport/patch_views.h): the onsets are exact to the bin;
/// 4+. the solved patch profiles (all later bounces, the links' time march) less their first pulses,
///    gathered at s with each patch's mean last leg.
/// The device legs join every path when account_first_and_last_bounces is set.
/// Where each is made: 1 in exact_light (imaging/capture_film.h), 2 and 3 by the spot as a source
/// (transport/spot_light.h), 4+ by the march (transport/solver.h) filmed by CaptureFilm
/// (imaging/capture_film.h), moved between grid points with march_grid_step (imaging/lattice_move.h).
/// This stage orders them: views, batches, ranks and H's rows.

#include "tprf/core/progress.h"
#include "tprf/imaging/capture_points.h"
#include "tprf/io/json_records.h"

#include <cstddef>
#include <vector>

namespace tprf {

struct Scene;
struct PatchSet;
struct LinkSet;
class Visibility;
class RankGroup;

/// Options of the capture.
struct CaptureOptions {
    int threads = 0;           ///< 0: all cores
    /// Illuminations solved together (1..kMaxBatch, transport/solver.h); 0: chosen from memory_bytes.
    int batch = 0;
    std::size_t memory_bytes = 0;  ///< the memory the batch may use (0: no limit but kMaxBatch)
    ProgressFn progress;       ///< phase "capture" (with march_grid_step > 1, phase "march" first)
    /// The ranks that share the laser points (pipeline/ranks.h; null: this process alone). Every rank
    /// calls compute_capture with the same scene; each computes whole batches of laser points (the
    /// batch is rank 0's choice), rank 0 collects H. An exception on one rank leaves the others waiting
    /// in a collective: the caller ends the group then (render_file does).
    const RankGroup* ranks = nullptr;
};

/// A capture's H and what it measured.
struct CaptureResult {
    CapturePoints points;
    /// pairs x T, float: radiance (the mean of RGB) times seconds per bin, W s / (m^2 sr). Pair index:
    /// the sensor point s for a confocal capture, l * sensor points + s for an exhaustive one. Empty on
    /// the ranks other than 0 of a split capture (their rows went to rank 0).
    std::vector<float> H;
    std::size_t pairs = 0;
    int bins = 0;
    bool solved = false;             ///< later bounces marched (max_bounces null or >= 4)
    int batch = 0;                   ///< illuminations per march
    /// Marches run, (sensor point, patch) pairs seen (summed over sensor points) and links x bins x
    /// layers (summed over marches): on rank 0 of a split capture, summed over the ranks.
    int marches = 0;
    std::size_t view_pairs = 0;
    std::uint64_t link_bin_updates = 0;
    double seconds_views = 0.0;      ///< locating points and viewing the patches from them (this rank)
    double seconds_solve = 0.0;      ///< the marches (this rank)
    double seconds_gather = 0.0;     ///< exact first bounces and the marched profiles gathered into H (this rank)
    double seconds_exchange = 0.0;   ///< waiting for the other ranks and collecting their rows (0: one rank)
    /// Rank 0: every rank's laser points and seconds, in rank order; elsewhere: this rank's alone.
    std::vector<CaptureShare> shares;
};

/// Computes scene.capture over the built patches (and, when later bounces are asked for, `links`, which
/// may otherwise be null). Throws Error for grid points that lie on no surface their device sees.
CaptureResult compute_capture(const Scene& scene, const PatchSet& patches, const Visibility& visibility,
                              const LinkSet* links, const CaptureOptions& options = {});

/// Whether scene.capture needs the links (its bounces go beyond laser spot -> patch -> sensor point).
bool capture_needs_links(const Scene& scene);

/// Whether a render of `scene` builds links: for a camera's solve, or a capture that marches.
bool render_needs_links(const Scene& scene);

/// The time axis the links are built for and marched on: the scene's, or for a capture with
/// march_bin_factor F > 1 (no camera), bins F times wider from the same start, enough of them that the
/// light of the last spreads back to the end of the scene's window (ceil(T / F) + 1).
TimeAxis march_time(const Scene& scene);

/// The laser points whose later bounces are marched: every one, or with march_grid_step S > 1 the
/// lattice of every S-th grid point along each side and the last (the others take their light, moved).
std::size_t marched_laser_points(const Capture& capture);

/// The orders a capture's march solves (SolverOptions::max_bounces): the patch orders, one less than
/// the sensor's (the last leg to the sensor point is one of capture.max_bounces), or all.
inline int capture_march_bounces(const Capture& capture) {
    return capture.max_bounces < 0 ? -1 : capture.max_bounces - 1;
}

}  // namespace tprf
