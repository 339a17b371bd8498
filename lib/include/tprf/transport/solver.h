#pragma once
/// The transient solver: B_i[t] = E_i[t] + albedo_i * sum_j F_ij B_j[t - d_ij], every bounce in one
/// pass of a time march.
///
/// Each patch keeps a ring buffer of its recent radiosity, as long as the largest delay plus one
/// block; the working memory is O(patches x max delay + links) whatever the number of bins. The time
/// axis is cut into blocks: a link whose delay is at least the block length reads only history that
/// is already final, so the block is one contiguous multiply-add over bins per link; shorter links are
/// applied bin by bin, and zero-delay links (both patches within one bin) by a Jacobi iteration
/// inside the bin, which neither loses nor invents energy. Tinted links (Links::tint: through tinted
/// mirrors, a weight per colour) are few and kept in lists of their own, so that the grey links' one
/// weight serves every lane; the long ones are applied a block at a time.
///
/// A batch of illuminations of the same patches (one per laser point of a capture, say) is marched
/// together: every link read then serves all of them. The march holds one value per lane per patch
/// and bin, a lane being one colour of one illumination (one lane per illumination when the scene is
/// grey), so its working memory grows with the batch; solve_working_bytes() tells how much.

#include "tprf/core/progress.h"
#include "tprf/scene/scene.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace tprf {

struct PatchSet;
struct LinkSet;
struct Illumination;
struct Links;
struct GlossyRows;

/// Most illuminations one march takes.
inline constexpr int kMaxBatch = 16;

/// Options of the transient solve.
struct SolverOptions {
    DelayMode delay = DelayMode::Linear;  ///< how a delay between two bins is placed
    int max_bounces = -1;                 ///< -1: all; else only orders 0..max_bounces
    int bounce_terms = 0;                 ///< > 0: also report per-order terms (see SolveBlock)
    int block_bins = 32;                  ///< time-block length, bins
    int threads = 0;                      ///< 0: all cores
    /// Run the long-link kernels with 512-bit vectors where the CPU has AVX-512 (and the compiler
    /// built them: GCC on x86-64 with FMA in the base instruction set, as the default x86-64-v3; the
    /// environment variable TPRF_NO_AVX512=1 refuses them). The results are bit-identical either way.
    bool wide_vectors = true;
    ProgressFn progress;                  ///< phase "solve"
    /// The first bin handed to the sink, <= 0: bins before the window (negative SolveBlock::first_bin),
    /// for a camera whose leg brings the light that left the patches then into the window.
    int first_bin = 0;
};

/// A block of final bins, handed to the caller as soon as it is complete.
struct SolveBlock {
    int first_bin = 0;              ///< index of the block's first bin on the scene's time axis (< 0: before it)
    int bins = 0;                   ///< bins in this block
    std::size_t patches = 0;        ///< N
    int illuminations = 1;          ///< K: the illuminations of the batch, in the order they were given
    /// N x bins x K x 3 (patch-major, then bin, then illumination, then RGB): radiosity B_i (W s / m^2
    /// per bin) of every illumination, all orders that were solved. For one illumination, N x bins x 3.
    const float* radiosity = nullptr;
    /// Number of per-order terms (0 unless asked): term k holds bounce order k; the last term holds
    /// every order >= its index when max_bounces is unlimited.
    int terms = 0;
    /// terms x N x bins x K x 3, same layout as `radiosity` per term.
    const float* per_order = nullptr;
    /// Rows [unread_first, unread_last) are left zero: the glossy patches' in-cells, which only their
    /// out-cells read (transport/glossy_rows.h); a sink need not copy them.
    std::size_t unread_first = 0, unread_last = 0;
    bool unread(std::size_t row) const { return row >= unread_first && row < unread_last; }
};

/// The march's own blocks, when shorter, reach the sink together: up to kSinkBins bins in one SolveBlock,
/// fewer when that output (N x bins x K x 3 floats, and as much per term) would pass kSinkBytes. Until
/// then they are kept a second time (by patch position, as the march reads them).
inline constexpr int kSinkBins = 32;
inline constexpr std::size_t kSinkBytes = std::size_t(16) << 20;

/// Called once per block of final bins, in time order, from one thread; the blocks follow one another
/// without gaps from SolverOptions::first_bin to the last bin (SolveStats::block_bins is the march's
/// block; a SolveBlock may hold several, see kSinkBins).
using BlockSink = std::function<void(const SolveBlock&)>;

/// What the solve measured.
struct SolveStats {
    int block_bins = 0;                 ///< block length used
    int ring_bins = 0;                  ///< history kept per patch, bins
    int channels = 0;                   ///< 1 when the scene is grey (albedos, pulses, link tints), else 3
    int illuminations = 0;              ///< K, illuminations marched together
    int lanes = 0;                      ///< values marched per patch and bin: channels x illuminations
    std::uint64_t link_bin_updates = 0; ///< links x bins x fed layers
    /// Ring buffers, block buffers and short-link lists (all but the link lists grow with the lanes)
    std::size_t working_bytes = 0;
    int max_jacobi_iterations = 0;      ///< worst zero-delay iteration count in one bin
    std::uint64_t jacobi_sweeps = 0;    ///< zero-delay sweeps over all bins
    std::uint64_t short_links = 0;      ///< links shorter than a block (applied bin by bin), tinted ones included
    double seconds_long = 0.0;          ///< wall time in the blocked long-link pass
    double seconds_short = 0.0;         ///< wall time in the bin-by-bin pass (short and same-bin links)
    double seconds_sink = 0.0;          ///< wall time in output assembly and the sink
    bool wide_kernels = false;          ///< the long-link kernels ran with AVX-512 (SolverOptions::wide_vectors)
    std::uint64_t packed_links = 0;     ///< links the plan packed for the dense-row kernels (flat sets; those of at least a block), or 0
};

/// Marches over the scene's time axis and hands every block of final bins to `sink`.
/// The link set may hold clusters (LinkSet): their gathered light is pushed to their patches and their
/// radiosity pulled from them at every bin.
SolveStats solve_transient(const PatchSet& patches, const LinkSet& links, const Illumination& illumination,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink);

/// Solves `batch` (1..kMaxBatch illuminations of the same patches, each N + 1 rows) in one march: every
/// block of every illumination goes to `sink` in one SolveBlock (K = batch.size()), and each
/// illumination's profiles are those that solving it alone gives (up to float summation order and the
/// same-bin iteration's stopping point, about 1e-7 of a profile's peak). The scene is marched on K lanes
/// when every albedo, every pulse of every illumination and every link tint (Links::tint) is grey, else on 3 K.
SolveStats solve_transient(const PatchSet& patches, const LinkSet& links, std::span<const Illumination* const> batch,
                           const TimeAxis& time, const SolverOptions& options, const BlockSink& sink);

/// The layers of a march on `options` (max_bounces, bounce_terms): rings kept apart per bounce order.
struct MarchLayers {
    int layers = 1;  ///< rings per node (orders kept apart, and the total of the later ones)
    int terms = 0;   ///< per-order terms handed to the sink (SolveBlock::terms)
    int fed = 1;     ///< layers that gather from links (the first order's only takes the pulses)
};
MarchLayers march_layers(const SolverOptions& options);

/// The channels a march keeps per illumination (SolveStats::channels): 1 when its light stays grey
/// (every albedo, every link tint and every source's colour grey), else 3.
constexpr int march_channels(bool grey) { return grey ? 1 : 3; }

/// Whether the patches and links keep grey light grey: every albedo and the tint of every link
/// (Links::tint) is grey. With grey sources, a march of them keeps one channel (march_channels).
bool keeps_grey(const PatchSet& patches, const Links& links);
/// Whether the glossy rows keep grey light grey: the lobe colour of every glossy patch grey.
bool keeps_grey(const GlossyRows& rows);

/// Whether a march of the scene as written stays grey (march_channels), before anything is built: every
/// object's albedo, emission and mirror or glass reflectance, every light's colour and a capture's
/// laser power grey. What keeps_grey and the pulses find once the scene is built.
bool scene_keeps_grey(const Scene& scene);

/// Working bytes (SolveStats::working_bytes) of a march of `illuminations` (1..kMaxBatch) illuminations
/// of `channels` channels each (1 for a grey scene, else 3) over these patches, links and time axis:
/// the plan is built (the link lists sorted), nothing is marched. For choosing a batch from a memory
/// budget; the links themselves are not counted.
std::size_t solve_working_bytes(const PatchSet& patches, const LinkSet& links, const TimeAxis& time,
                                const SolverOptions& options, int illuminations, int channels);

/// The most illuminations, up to kMaxBatch, whose march fits in `memory_bytes`, on the straight line
/// through the working bytes of a march of one illumination (`one_bytes`) and of kMaxBatch
/// (`full_bytes`); 1 when not even one fits.
int batch_that_fits(double one_bytes, double full_bytes, double memory_bytes);

/// The illuminations a capture marches at once within `budget_bytes`, given the working bytes of a
/// march of B illuminations (`working_bytes(B)`, B in 1..kMaxBatch): batch_that_fits on the line through
/// B = 1 and B = kMaxBatch, then one fewer while the march of that many still exceeds the budget (the
/// lane count also picks the march's kernels, so the line is checked where it lands); 1 when not even
/// one fits. The one rule of the capture's batch: pipeline/capture.cpp calls it with the plan's sizes
/// (solve_working_bytes), the resource estimate (tprf info) with its model of the same march.
int capture_batch(const std::function<double(int)>& working_bytes, double budget_bytes);

// ---- Sizing a march without building it ----
//
// A march's working memory follows from its shape, which the plan decides from the sizes of its inputs
// alone (march_shape), and from the lengths of the lists it makes, which its links' delays decide. The
// plan counts its own (solve_sizing); an estimate that builds nothing (tprf info) models the inputs and
// the lengths, takes the shape from march_shape, and both add them up by one rule (march_working_bytes).

/// The sizes a plan decides its march's shape from.
struct MarchInputs {
    std::size_t patches = 0;     ///< N
    std::size_t nodes = 0;       ///< N and the clusters (LinkSet::nodes)
    std::size_t links = 0;       ///< the set's links
    bool clusters = false;       ///< the set has clusters (push and pull run)
    int cluster_block_bins = 0;  ///< LinkSet::block_bins: the shortest cluster link, bins (0: none)
    int longest_lag = 0;         ///< the longest link's delay, whole bins (delay_taps_f's lag)
    int illuminations = 1;       ///< K, 1..kMaxBatch
    int channels = 3;            ///< per illumination (march_channels)
};

/// What a plan decides from MarchInputs and the options: the march's shape.
struct MarchShape {
    std::size_t patches = 0;          ///< N
    std::size_t nodes = 0;            ///< N and the clusters
    int threads = 1;                  ///< worker threads
    int illuminations = 1;            ///< K
    int channels = 3;                 ///< per illumination
    int lanes = 3;                    ///< values per node and bin: K x channels
    MarchLayers layers;               ///< rings per node, terms handed out, layers fed by links
    int block_bins = 0;               ///< the march's block, bins (a power of two)
    int emit_blocks = 1;              ///< blocks per hand-over to the sink (a power of two)
    std::size_t source_tile = 0;      ///< sources per tile of the long pass (all of them: not tiled)
    int lag_bits = 0;                 ///< > 0: dense rows' links packed, the lag in this many bits of a key
    int windows = 1;                  ///< windows of the long pass
    int window_bins = 0;              ///< the longest window, bins: the accumulators' length
    int recent_bins = 0;              ///< bins of every node's recent radiosity
    bool near_list = false;           ///< the shortest window's links in a list of their own (read from the recent bins)
    std::size_t tile_sum_floats = 0;  ///< a thread's receiver-tile sums in the long pass
};
MarchShape march_shape(const MarchInputs& inputs, const SolverOptions& options);
/// The march's block (MarchShape::block_bins): options.block_bins as a power of two, no longer than the
/// shortest cluster link (`cluster_block_bins`, LinkSet::block_bins; 0: no limit).
int march_block_bins(const SolverOptions& options, int cluster_block_bins);

/// The lengths of a march's lists and rings, which its links' delays decide.
struct MarchLists {
    std::size_t ring_bins = 0;       ///< every node's ring and its mirror, bins, summed over the nodes
    std::size_t short_links = 0;     ///< grey links applied bin by bin (a cluster link as its patches' links)
    std::size_t same_bin_links = 0;  ///< grey links within one bin (the same-bin system)
    std::size_t sweep_rows = 0;      ///< the same-bin system's rows: patches that send or receive such a link
    bool chebyshev = false;          ///< the same-bin sweeps keep a third iterate (Chebyshev acceleration)
    bool sorted = false;             ///< the long pass reads a copy of the grey links (by window; tinted ones left out)
    std::size_t sorted_links = 0;    ///< ... of this many links
    std::size_t near_links = 0;      ///< the shortest window's links (MarchShape::near_list)
    std::size_t packed_links = 0;    ///< dense rows' links packed (MarchShape::lag_bits)
    bool tinted = false;             ///< some link is tinted: the tinted lists exist
    std::size_t tinted_long = 0;     ///< tinted links of at least a block
    std::size_t tinted_short = 0;    ///< tinted links shorter than a block
    std::size_t tinted_same = 0;     ///< tinted links within one bin
};

/// Working bytes of a march of this shape and these lists (SolveStats::working_bytes).
std::size_t march_working_bytes(const MarchShape& shape, const MarchLists& lists);

/// A plan's own inputs, shape and lists, as solve_working_bytes plans the march (nothing marched):
/// what an estimate of the march is checked against.
struct MarchSizing {
    MarchInputs inputs;
    MarchShape shape;
    MarchLists lists;
    std::size_t working_bytes = 0;  ///< march_working_bytes(shape, lists)
};
MarchSizing solve_sizing(const PatchSet& patches, const LinkSet& links, const TimeAxis& time,
                         const SolverOptions& options, int illuminations, int channels);

/// Bins of a node's ring whose longest outgoing link is `lag` bins, in a march of blocks of
/// `block_bins` (a power of two: the window [t - lag - 1, t] and one block).
int ring_bins(int lag, int block_bins);
/// Bins mirrored after a ring whose longest long link is read in windows of `window_bins` (0: none).
int ring_mirror_bins(int window_bins);

}  // namespace tprf
