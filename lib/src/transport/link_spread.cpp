// Delay spread of patch-to-patch links (link_set.h, spread_patch_links; links.spread_pieces).
//
// A link into patch i from patch j moves j's light at the centroid-to-centroid delay, split between
// two bins. The light that reaches i's centroid from j takes every path |c_i - y| over the points y
// of j, weighted by the kernel cos_i cos_y / r^2: a span of up to j's size. When bins are finer
// than that, a receiver's profile is a sum of spikes at its sources' centroid delays, and bounced
// light shows a comb in time with the patches' spacing (and, in frames, ripples at patch spacing).
// Here each such link becomes pieces of equal weight along its sorted paths, each at its weighted
// mean path, as cluster links' kernels are (hierarchy.cpp): the pieces' form factors sum to the
// link's, and the mean delay is the kernel-weighted mean path.
//
// Only the sender's side is spread. The receiver's own extent is not: the camera reads a profile at
// its own points, and the next bounce spreads it as a sender. Spreading both sides (over pairs of
// points) blurred the Cornell box's bounced light twice: its median pixel error rose from 1.02% to
// 1.38%, against 1.07% this way (docs/links.md).

#include "tprf/transport/link_set.h"

#include "patch_pairs.h"
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <span>

namespace tprf {
namespace {

constexpr int kSide = 4;  // points of a source patch: one per stratum of a kSide x kSide grid
constexpr int kPoints = kSide * kSide;
// A sender wider than kNearRatio times its distance to the receiver's centroid (a neighbour across a
// crease) sees the kernel vary by orders of magnitude over it: it gets kNearSide x kNearSide points.
constexpr double kNearRatio = 0.25;
constexpr int kNearSide = 12;
constexpr int kMaxPoints = kNearSide * kNearSide;
static_assert(kMaxPoints <= kMaxPiecePaths);

// side x side points of patch j, one jittered in each stratum of its unit square, uniform in area.
void strata_points(const PatchSet& patches, std::size_t j, int side, Eigen::Vector3f* out) {
    for (int s = 0; s < side * side; ++s) {
        const double u = (s % side + hash01(j, std::uint64_t(side), 2 * std::uint64_t(s))) / side;
        const double v = (s / side + hash01(j, std::uint64_t(side), 2 * std::uint64_t(s) + 1)) / side;
        out[s] = patch_point(patches, j, u, v).cast<float>();
    }
}

// kPoints points of every patch (strata_points), drawn once: a patch sends through hundreds of links.
std::vector<Eigen::Vector3f> source_points(const PatchSet& patches, int threads) {
    std::vector<Eigen::Vector3f> points(patches.size() * kPoints);
    parallel_for(patches.size(), {threads, 256, true},
                 [&](std::size_t j) { strata_points(patches, j, kSide, points.data() + j * kPoints); });
    return points;
}

// How finely a link is cut: bins of bin_width, at most max_pieces pieces.
struct PieceLimit {
    double bin_width;
    int max_pieces;
};

// Appends to `row` the pieces of `link`, into patch i from patch j = link.source: its paths from i's
// centroid to j's `points`, weighted by the kernel cos_i cos_j / r^2; at most max_pieces, one per two
// bins that the paths span. The link itself when no point of j faces i's centroid.
void append_pieces(const PatchSet& patches, std::span<const Eigen::Vector3f> points, std::size_t i, const PieceLimit& limit,
                   const RowLink& link, std::vector<RowLink>& row) {
    const std::size_t j = link.source;
    const int count = int(points.size());
    const double bin_width = limit.bin_width;
    const int max_pieces = limit.max_pieces;
    const Eigen::Vector3f x = patches.centroid[i].cast<float>();
    const Eigen::Vector3f ni = patches.normal[i].cast<float>(), nj = patches.normal[j].cast<float>();
    std::array<float, kMaxPoints> path, weight;
    int used = 0;
    for (int s = 0; s < count; ++s) {
        const Eigen::Vector3f d = points[s] - x;
        const float r2 = d.squaredNorm();
        const float k = std::max(0.0f, ni.dot(d)) * std::max(0.0f, -nj.dot(d)) / (r2 * r2);
        if (!(k > 0.0f) || !std::isfinite(k)) continue;
        path[std::size_t(used)] = std::sqrt(r2);
        weight[std::size_t(used)] = k;
        ++used;
    }
    double share[kMaxSpreadPieces], mean[kMaxSpreadPieces];
    const int pieces = delay_pieces<float>({path.data(), weight.data(), used}, bin_width, max_pieces, share, mean);
    if (pieces == 0) row.push_back(link);
    for (int g = 0; g < pieces; ++g) row.push_back({link.source, link.ff * float(share[g]), float(mean[g]), link.tint});
}

}  // namespace

std::uint64_t spread_patch_links(LinkSet& set, const PatchSet& patches, double bin_width_m, int max_pieces,
                                 int threads) {
    TPRF_CHECK(bin_width_m > 0.0);
    max_pieces = std::clamp(max_pieces, 1, kMaxSpreadPieces);
    Links& in = set.links;
    const std::size_t nodes = in.receivers(), leaves = set.patches();
    const bool tinted = in.tinted();
    // Each row's links with their pieces, then the rows' lengths, then the CSR.
    const std::vector<Eigen::Vector3f> points = source_points(patches, threads);
    const std::vector<double> radius = circumradii(patches);
    std::vector<std::vector<RowLink>> rows(nodes);
    parallel_for(nodes, {threads, 64, true}, [&](std::size_t m) {
        std::vector<RowLink>& row = rows[m];
        row.reserve(in.row[m + 1] - in.row[m]);
        std::array<Eigen::Vector3f, kMaxPoints> near;
        for (std::uint64_t k = in.row[m]; k < in.row[m + 1]; ++k) {
            const std::size_t j = in.source[k];
            const RowLink link{in.source[k], in.ff[k], in.distance[k], tinted ? in.tint[k] : std::uint16_t(0)};
            if (m >= leaves || j >= leaves || m == j) {
                row.push_back(link);
            } else if (radius[j] <= kNearRatio * (patches.centroid[m] - patches.centroid[j]).norm()) {
                append_pieces(patches, {points.data() + j * kPoints, kPoints}, m, {bin_width_m, max_pieces}, link, row);
            } else {
                strata_points(patches, j, kNearSide, near.data());
                append_pieces(patches, near, m, {bin_width_m, max_pieces}, link, row);
            }
        }
    });
    const std::uint64_t before = in.size();
    Links out;
    out.row.assign(nodes + 1, 0);
    for (std::size_t m = 0; m < nodes; ++m) out.row[m + 1] = out.row[m] + rows[m].size();
    out.tints = std::move(in.tints);
    in = Links{};  // the input's arrays are freed before the output's are allocated
    const std::size_t total = out.row[nodes];
    out.source.resize(total);
    out.ff.resize(total);
    out.distance.resize(total);
    if (tinted) out.tint.resize(total);
    parallel_for(nodes, {threads, 256, true}, [&](std::size_t m) {
        std::uint64_t at = out.row[m];
        for (const RowLink& p : rows[m]) {
            out.source[at] = p.source;
            out.ff[at] = p.ff;
            out.distance[at] = p.distance;
            if (tinted) out.tint[at] = p.tint;
            ++at;
        }
        std::vector<RowLink>().swap(rows[m]);
    });
    if (nodes > leaves) sort_rows_by_octave(out, float(1.0 / bin_width_m), threads);
    in = std::move(out);
    return in.size() - before;
}

}  // namespace tprf
