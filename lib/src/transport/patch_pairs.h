#pragma once
// Private to the transport stage: the patch-to-patch form factor that flat links use for every pair
// and hierarchical links for the pairs they refine down to single patches.

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/transport/links.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace tprf {

struct HierarchyOptions;
struct LinkSet;

struct PairFormFactors {
    double ij = 0.0;  ///< F_ij, visibility included
    double ji = 0.0;  ///< F_ji = F_ij A_i / A_j
};

/// What judging a pair of patches reads: the patches, the visibility, the link options and every
/// patch's circumradius (circumradii).
struct PairScene {
    const PatchSet& patches;
    const Visibility& vis;
    const LinkOptions& options;
    const std::vector<double>& radius;
};

/// Form factors of patches i and j when they face each other and some stratified ray between them is
/// free: the rule their distance calls for (adaptive when `is_near`, Gauss for middle distances, the
/// centroid rule beyond options.far_factor), times the visible fraction. False: no link.
bool patch_pair(const PairScene& scene, std::size_t i, std::size_t j, bool is_near, PairFormFactors& out,
                LinkStats& counts);

/// Deterministic jitter in [0, 1) from three integers (threads must not change the answer). Inline: the
/// hierarchical oracle calls it for every sample of every pair it judges.
inline std::uint64_t hash64(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
    std::uint64_t h = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full ^ c;
    h ^= h >> 33;
    h *= 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    h *= 0xc4ceb9fe1a85ec53ull;
    h ^= h >> 33;
    return h;
}
inline double hash01(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
    return double(hash64(a, b, c) >> 11) * 0x1.0p-53;
}

/// True when i and j are closer than near_factor (r_i + r_j), the pairs integrated adaptively.
bool near_pair(const PatchSet& patches, const std::vector<double>& radius, double near_factor, std::size_t i,
               std::size_t j);

/// A patch with no diffuse part and no emission (a pure mirror or glass) neither gathers nor sends
/// diffuse light: links to or from it would carry nothing.
inline bool inert(const PatchSet& patches, std::size_t i) {
    return !(patches.albedo[i] > 0.0).any() && !(patches.emission[i] > 0.0).any();
}

/// The link builders' record sizes (link_build_sizes), each from the file that holds its record.
std::size_t flat_pair_bytes();                                       // links.cpp
std::size_t hierarchical_pair_bytes();                               // hierarchy.cpp
std::size_t oracle_node_bytes(const HierarchyOptions& options);      // hierarchy.cpp
std::size_t mirror_link_bytes();                                     // mirror_links.cpp

/// Most weighted paths delay_pieces takes.
constexpr int kMaxPiecePaths = 256;

/// `count` paths, each with its weight.
template <typename T>
struct WeightedPaths {
    const T* path;
    const T* weight;
    int count;
};

/// A delay kernel from weighted paths (those of weight <= 0 left out): one piece per two bins of
/// `bin_width` that they span (one when bin_width is 0), at most max_pieces and at most one per path,
/// cut from the paths sorted by length into groups of about equal weight. Writes each non-empty
/// group's share of the total weight and its weighted mean path; returns how many (0: no path has
/// weight). The shares sum to 1 and the mean of the pieces is the paths' weighted mean.
/// (The kernels of cluster links, hierarchy.cpp, and of spread patch links, link_spread.cpp.)
template <typename T>
int delay_pieces(const WeightedPaths<T>& paths, double bin_width, int max_pieces, double* share, double* mean_path) {
    const T* path = paths.path;
    const T* weight = paths.weight;
    const int count = paths.count;
    TPRF_CHECK_LE(count, kMaxPiecePaths);
    int order[kMaxPiecePaths];
    int used = 0;
    double total = 0.0, lo = INFINITY, hi = 0.0;
    for (int q = 0; q < count; ++q)
        if (weight[q] > 0) {
            order[used++] = q;
            total += double(weight[q]);
            lo = std::min(lo, double(path[q]));
            hi = std::max(hi, double(path[q]));
        }
    if (used == 0 || !(total > 0.0)) return 0;
    // A piece's linear split already spreads it over two bins: one piece per two bins of span.
    const int wanted = bin_width > 0.0 ? int((hi - lo) / (2.0 * bin_width)) : 0;
    const int pieces = std::clamp(wanted, 1, std::max(1, std::min(max_pieces, used)));
    if (pieces > 1) std::sort(order, order + used, [&](int a, int b) { return path[a] < path[b]; });
    for (int g = 0; g < pieces; ++g) share[g] = mean_path[g] = 0.0;
    double before = 0.0;
    for (int u = 0; u < used; ++u) {
        const int q = order[u];
        const int g = std::min(pieces - 1, int((before + 0.5 * double(weight[q])) / total * pieces));
        share[g] += double(weight[q]);
        mean_path[g] += double(weight[q]) * double(path[q]);
        before += double(weight[q]);
    }
    int kept = 0;
    for (int g = 0; g < pieces; ++g) {
        if (!(share[g] > 0.0)) continue;
        mean_path[kept] = mean_path[g] / share[g];
        share[kept] = share[g] / total;
        ++kept;
    }
    return kept;
}

/// One link of a row while the row is rebuilt or reordered (spread_patch_links, sort_rows_by_octave).
struct RowLink {
    std::uint32_t source;
    float ff, distance;
    std::uint16_t tint;
};

/// A link to add to a built set (links through mirrors, glossy rows' links).
struct ExtraLink {
    std::uint32_t receiver;
    std::uint32_t source;
    float ff;
    float distance;
    std::uint16_t tint;  // Links::tint
};

/// Adds `extra` to the rows of `set`, each row sorted as the solver expects (by delay octave of bins of
/// `bin_width_m` first when the set has clusters). (mirror_links.cpp)
void merge_extra_links(LinkSet& set, std::vector<ExtraLink>& extra, double bin_width_m);

/// Circumradius of every patch.
std::vector<double> circumradii(const PatchSet& patches);

// ---- Glossy patches' cells (glossy_rows.cpp) ----

struct GlossyRows;

/// One of a glossy patch's cells and its share of the light between the patch and another polygon.
struct CellShare {
    int cell;
    double weight;
};

/// The polygon on the other end of a glossy patch's pair: a patch, or a patch's image through mirrors.
struct SharedPolygon {
    const Vec3* corners;
    std::size_t count;
    Vec3 normal;      ///< its front, towards the glossy patch
    Vec3 centroid;
    double radius;    ///< circumradius
    bool near;        ///< a near pair (near_pair): its form factor is not its centroid's
};

/// Patch j as the other end of a pair.
SharedPolygon shared_patch(const PatchSet& patches, std::size_t j, double radius, bool near);

/// How the light between glossy patch p (its cells of `rings` rings) and `other` divides among p's
/// cells: the share of the pair's form factor (the integral of cos cos / r^2 over both) whose direction
/// from p to `other` lies in each cell. One cell when other's corners, its edges' midpoints and its
/// centroid all lie in one as p's centroid sees them (and the pair is not near); otherwise k x k points
/// on `other`, k from 2 to 8, about four points per cell it spans, seen from p's centroid or, for a near
/// pair, from 3 x 3 points on p. The shares add up to 1, in increasing cell order. So the light a cell
/// sends out reaches patches whose form factors add up to the cell's own share of the hemisphere (a
/// pair's form factor given whole to the cell of its centroid leaves some cells with too few receivers
/// and others with too many, and a closed room of glossy walls then loses or makes light).
std::vector<CellShare> cell_shares(const PatchSet& patches, int rings, std::size_t p, const SharedPolygon& other);

/// Patches i and j linked directly or through a chain of mirrors, i glossy: F_ij and F_ji (the chain's
/// weights included), the distance (unfolded), the chain's tint, whether each end's patch row sends (is
/// not inert), and the cell shares at i (towards j as i sees it) and at j (towards i; empty when j is not
/// glossy).
struct GlossyPair {
    std::size_t i = 0, j = 0;
    double f_ij = 0.0, f_ji = 0.0;
    float distance = 0.0f;
    std::uint16_t tint = 0;
    bool i_sends = true, j_sends = true;
    std::vector<CellShare> at_i, at_j;
};

/// The glossy rows' links of a pair, from glossy i's side: i's in-cells gather j's patch row and j's
/// out-cells facing i (one bin early), i's patch row takes j's out-cells facing it, and a Lambertian j's
/// patch row takes i's out-cells facing it. A pair of glossy patches is given once from each end.
void glossy_pair_cells(const GlossyRows& rows, const GlossyPair& pair, std::vector<ExtraLink>& out);

}  // namespace tprf
