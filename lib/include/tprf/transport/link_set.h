#pragma once
/// LinkSet: what the solver marches, whatever built it.
///
/// Nodes are the patches (0..N-1) and, for hierarchical links, the clusters of a ClusterTree
/// (N..M-1). A cluster's radiosity is the area-weighted mean of its children's ("pull"). Receiver
/// node m gathers G_m(t) = sum_k ff[k] B_source[k](t - distance[k] / c) over its links; a patch's
/// radiosity is B_i(t) = E_i(t) + albedo_i sum_{a = i and every cluster above i} G_a(t) ("push": a
/// cluster's received light reaches each of its patches). A link may appear several times with the
/// same source and different distances: the pieces of its delay kernel (the spread of its path
/// lengths), each placed between bins by the solver's linear split, so that both the total and the
/// mean delay of every piece are exact.

#include "tprf/core/progress.h"
#include "tprf/geometry/cluster_tree.h"
#include "tprf/geometry/patches.h"
#include "tprf/scene/scene.h"
#include "tprf/transport/glossy_rows.h"
#include "tprf/transport/links.h"

#include <algorithm>
#include <bit>
#include <cmath>

namespace tprf {

class Visibility;

/// Delay octaves: a link of delay d bins (delay_bins_f: distance * inv_bin in float, as the solver
/// computes it) is in octave 0 when d < 1, else 1 + floor(log2 d), at most kDelayOctaves - 1. The
/// solver applies the links of octave k >= 1 in windows of 2^(k-1) bins, and every link of 32 bins
/// or more (the last octave) in its longest window, so a row sorted by octave splits into one range
/// per window, each sorted by source: the order its source tiles walk (solver_plan.h checks that the
/// last octave starts at the longest window).
constexpr int kDelayOctaves = 7;
inline int delay_octave(float distance, float inv_bin) {
    const float d = distance * inv_bin;
    if (!(d >= 1.0f)) return 0;
    const int lag = d < float(1 << 30) ? int(d) : (1 << 30);
    return std::min(int(std::bit_width(unsigned(lag))), kDelayOctaves - 1);
}

struct LinkSet {
    ClusterTree tree;  ///< nodes; no clusters for flat links
    /// CSR over tree.nodes() receivers. Flat: sources non-decreasing within a row. Hierarchical (with
    /// a bin width): delay octaves non-decreasing within a row, then sources, then distances.
    Links links;
    /// When > 0, every link with a cluster at either end is at least this many bins long: the solver
    /// keeps its blocks this short, so that those links are applied a block at a time (push and pull
    /// once per block); shorter ones would be applied patch by patch.
    int block_bins = 0;
    /// The glossy patches' directional rows (add_glossy_links): leaves after the patches, before the
    /// clusters; empty without glossy transport.
    GlossyRows glossy;

    /// The rows the march solves that are not clusters: the patches and the glossy rows.
    std::size_t patches() const { return tree.leaves; }
    /// The first row that is not a patch (the patches' count).
    std::size_t surface_patches() const { return tree.leaves - glossy.rows(); }
    /// The albedo the march takes for leaf row i: the patch's, or its glossy row's.
    const Rgb& albedo(const PatchSet& patches, std::size_t i) const {
        return i < glossy.patches || glossy.empty() ? patches.albedo[i] : glossy.albedo[i - glossy.patches];
    }
    std::size_t nodes() const { return tree.nodes(); }
    /// Bytes held by the tree and the links.
    std::size_t bytes() const { return tree.bytes() + links.bytes() + glossy.bytes(); }
    /// Links with a cluster at either end (kernel pieces counted one by one).
    std::size_t cluster_links() const {
        std::size_t count = 0;
        for (std::size_t m = 0; m < nodes(); ++m)
            for (std::uint64_t k = links.row[m]; k < links.row[m + 1]; ++k)
                count += m >= patches() || links.source[k] >= patches();
        return count;
    }
};

/// Spreads every patch-to-patch link of `set` over the paths between its two patches: a link whose
/// kernel-weighted paths span more than two bins of `bin_width_m` becomes pieces of equal weight
/// (at most max_pieces, one per two bins of span), each at its weighted mean path; their form factors
/// sum to the link's. Keeps each row's order (sorted again by delay octave when the set has clusters).
/// Returns the number of links added.
std::uint64_t spread_patch_links(LinkSet& set, const PatchSet& patches, double bin_width_m, int max_pieces,
                                 int threads = 0);

/// Sorts every row of `links` by delay octave (for bins of 1 / inv_bin), then source, then distance: the
/// order of a hierarchical set's rows.
void sort_rows_by_octave(Links& links, float inv_bin, int threads = 0);

/// The flat method: every facing, visible pair of patches (compute_links), no clusters.
LinkSet flat_link_set(const PatchSet& patches, const Visibility& visibility, const LinkOptions& options = {},
                      LinkStats* stats = nullptr);

/// Options of the hierarchical method (on top of LinkOptions, which rule the patch-to-patch links).
struct HierarchyOptions {
    double tolerance = 1e-3;       ///< largest estimated form-factor error of a cluster link (links.tolerance)
    double bin_width_m = 0.0;      ///< the time axis' bin, metres: a link's delay spread is weighed against it
    int samples = 16;              ///< point pairs sampled per candidate cluster link
    int kernel_pieces = 4;         ///< most pieces of a cluster link's delay kernel
    /// Timing inside the nodes: a cluster link gives all its members one delay kernel, while a member's
    /// own paths are offset by up to the radii of the link's cluster ends (a patch end adds nothing: its
    /// patch links give it one delay too). When > 0 (with bin_width_m), a link whose form factor times
    /// that offset in bins exceeds time_bins x tolerance is refined. 0: off.
    double time_bins = 0.0;
    /// Cluster links are kept only between nodes at least this many bins apart (when bin_width_m > 0);
    /// nearer pairs are refined, and the solver's blocks are this long. 0: four typical patch sizes
    /// in bins, between 1 and kLongestMinLag (a fixed length would leave every pair within it as
    /// patch-to-patch links where bins are coarse against the patches).
    int min_lag_bins = 0;
    /// The most bins min_lag_bins is set to by default: the solver's longest window.
    static constexpr int kLongestMinLag = 32;
};

/// min_lag_bins when it is 0: four patch sizes (`patch_size_m`, a typical patch's diameter) in bins of
/// `bin_width_m`, between 1 and HierarchyOptions::kLongestMinLag.
inline int default_min_lag_bins(double patch_size_m, double bin_width_m) {
    return int(std::clamp(std::floor(4.0 * patch_size_m / bin_width_m), 1.0, double(HierarchyOptions::kLongestMinLag)));
}

/// What the hierarchical build counted.
struct HierarchyStats {
    std::uint64_t leaf_links = 0;     ///< patch-to-patch links (both directions)
    std::uint64_t cluster_links = 0;  ///< links with a cluster at either end (both directions, pieces counted once)
    std::uint64_t candidates = 0;     ///< node pairs the oracle judged
    std::uint64_t rays = 0;           ///< visibility rays cast
};

/// The hierarchical method: a cluster tree and links between nodes at any level, refined until each
/// link's estimated error is under `hierarchy.tolerance`; patch pairs keep compute_links' form factors.
LinkSet hierarchical_link_set(const PatchSet& patches, const Visibility& visibility, const LinkOptions& options,
                              const HierarchyOptions& hierarchy, HierarchyStats* stats = nullptr);

/// Adds the links through mirrors and glass reflections: for every chain of Visibility::chains(), the
/// transfer between every pair of patches on its two ends, from the receiver to the source's mirror
/// image seen through the chain's polygons (the exact point-to-polygon form factor of the clipped
/// image, integrated over the receiver), times the chain's reflectance and the transmittance and
/// visibility of its legs, at the unfolded distance. Patch-to-patch links, merged into the rows in the
/// order the solver expects (`bin_width_m`: the bins of a hierarchical set's delay octaves). Returns
/// the links added. Cost: pairs of patches in front of the planes, as the flat method.
std::uint64_t add_mirror_links(LinkSet& set, const PatchSet& patches, const Visibility& visibility,
                               const LinkOptions& options, double bin_width_m);

/// Adds the glossy patches' directional rows at `rings` rings (links.glossy_resolution; 0 or no glossy
/// patch: nothing) to a set built over `patches`: the rows as leaves after the patches (clusters and
/// their links renumbered), their links merged into the rows in the order the solver expects
/// (`bin_width_m`: the march's bins, as make_link_set's), set.glossy filled (glossy_rows.h). Returns the
/// links added. Cost: every glossy patch against every patch, as the flat method (the lobe between its
/// cells is no link: the march and the steady solve apply it, GlossyRows::lobe).
std::uint64_t add_glossy_links(LinkSet& set, const PatchSet& patches, const Visibility& visibility,
                               const LinkOptions& options, double bin_width_m, int rings);

/// Where make_link_set reports its counts, when given: a hierarchical build's, a flat build's.
struct LinkSetStats {
    HierarchyStats* hierarchy = nullptr;
    LinkStats* flat = nullptr;
};

/// The link set that `settings` asks for: flat, or hierarchical with delay kernels for bins of
/// `bin_width_m`, its patch links spread when settings.spread_pieces > 0 (spread_patch_links), and the
/// glossy patches' rows when settings.glossy_resolution > 0 (add_glossy_links). Links
/// through mirrors are the caller's next step (add_mirror_links), so that it can report them.
LinkSet make_link_set(const PatchSet& patches, const Visibility& visibility, const LinkSettings& settings,
                      double bin_width_m, const LinkOptions& options = {}, LinkSetStats stats = {});

/// What the link stage holds per item while it builds, bytes (the sizes of its records), for sizing a
/// build without running it (tprf info).
struct LinkBuildSizes {
    std::size_t flat_pair = 0;          ///< a facing pair (both links) in the flat builder's lists
    std::size_t hierarchical_pair = 0;  ///< a pair of links (both directions) in the hierarchical builder's records
    std::size_t oracle_node = 0;        ///< a node's points stored for the hierarchical oracle
    std::size_t spread_link = 0;        ///< a spread link's piece in its row's list (spread_patch_links)
    std::size_t mirror_link = 0;        ///< a link through mirrors in its pair list and its row's rebuilt copy
};
LinkBuildSizes link_build_sizes(const HierarchyOptions& options = {});

}  // namespace tprf
