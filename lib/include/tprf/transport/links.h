#pragma once
/// Links: which patches exchange light, how much (form factor) and how late (centroid distance).

#include "tprf/geometry/form_factors.h"
#include "tprf/core/progress.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace tprf {

struct PatchSet;
class Visibility;

/// The links grouped by receiver (CSR). Receiver i gathers from sources source[k] for
/// k in [row[i], row[i+1]): B_i(t) += albedo_i * ff[k] * B_source(t - distance[k] / c).
/// The form factor is stored once per direction; the receiver's albedo is applied by the solver.
struct Links {
    std::vector<std::uint64_t> row;     ///< N + 1 offsets
    std::vector<std::uint32_t> source;  ///< L, sending patch j, increasing within a row
    std::vector<float> ff;              ///< L, F_ij: fraction of the light leaving i that reaches j,
                                        ///< visibility included (equal, by reciprocity, to the
                                        ///< share of j's power that i receives, per unit area)
    std::vector<float> distance;        ///< L, centroid-to-centroid distance, metres
    /// Per-channel factors of links through tinted mirrors and glass: empty (every link grey), or L
    /// indices into `tints`, 0 for a grey link. Link k carries ff[k] * tints[tint[k]][c] in channel c.
    std::vector<std::uint16_t> tint;
    /// The palette of tint: tints[0] = {1, 1, 1}; empty when `tint` is.
    std::vector<std::array<float, 3>> tints;

    /// Number of links L.
    std::size_t size() const { return source.size(); }
    /// Whether some link carries a non-grey tint.
    bool tinted() const { return !tint.empty(); }
    /// Link k's factor in channel c (1 for grey links).
    float tint_factor(std::uint64_t k, int c) const {
        return tint.empty() ? 1.0f : tints[tint[k]][std::size_t(c)];
    }
    /// Number of receivers N.
    std::size_t receivers() const { return row.empty() ? 0 : row.size() - 1; }
    /// Bytes held by the link arrays.
    std::size_t bytes() const;
    /// Bytes of a grey link in the arrays (source, form factor, distance) and of a row offset.
    static constexpr std::size_t kLinkBytes = sizeof(std::uint32_t) + 2 * sizeof(float);
    static constexpr std::size_t kRowBytes = sizeof(std::uint64_t);
};

/// Checks that `links.tint` is empty or holds one index per link into `tints`, whose entry 0 is
/// {1, 1, 1}; throws InternalError otherwise (the solvers check before they read the tints).
void check_tints(const Links& links);

/// Options of the link stage.
/// A link build split between processes that each build part of it (MPI ranks, docs/mpi.md): share
/// `index` of `count` builds its part, and `exchange` turns its part's bytes into every share's,
/// concatenated in share order, on every share (a collective: every share calls it once). The result
/// is the same link set, bit for bit, on every share and for any count. Hierarchical links only; flat
/// links are built whole by every share.
struct LinkShares {
    int index = 0, count = 1;
    std::function<std::vector<std::byte>(std::span<const std::byte>)> exchange;
};

struct LinkOptions {
    int visibility_rays = 16;      ///< stratified rays per pair when the first ones disagree
    int first_rays = 4;            ///< rays cast first; when all agree the pair is decided by them
    double near_factor = 2.0;      ///< pairs closer than near_factor * (r_i + r_j) (circumradii) are
                                   ///< integrated adaptively (found by a FLANN radius search)
    double far_factor = 8.0;       ///< pairs farther than far_factor * (r_i + r_j) use the centroid
                                   ///< rule; those in between a Gauss product rule
    FormFactorQuadrature quadrature;  ///< the adaptive rule of near pairs
    int threads = 0;               ///< 0: all cores
    ProgressFn progress;           ///< phase "links"
    LinkShares shares;             ///< one share (this process builds everything) by default
};

/// Statistics of a link build.
struct LinkStats {
    std::uint64_t pairs_tested = 0;  ///< unordered pairs that face each other
    std::uint64_t near_pairs = 0;    ///< of those, integrated adaptively
    std::uint64_t rays = 0;          ///< visibility rays cast
};

/// Computes the links of every pair of patches that face each other and are not fully occluded.
Links compute_links(const PatchSet& patches, const Visibility& visibility, const LinkOptions& options = {},
                    LinkStats* stats = nullptr);

}  // namespace tprf
