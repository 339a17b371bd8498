// Hierarchical links: the refinement of Hanrahan, Salzman and Aupperle (1991) over a cluster tree
// (Smits, Arvo and Greenberg 1994; Sillion 1995), with a delay kernel on every cluster link.
//
// Every unordered pair of patches is covered exactly once: by the link between the two nodes that
// the refinement of their lowest common cluster stopped at. A candidate pair of nodes (R, S) is
// judged from point pairs sampled uniformly by area on both: the point-to-point kernel
// k = cos_x cos_y / (pi r^2) gives F_RS = A_S E[k] and F_SR = A_R E[k], and its spread over the
// samples bounds how far the form factor seen from any point of one node differs from the link's
// (what pushing a cluster's light to all its patches, and pulling a cluster's radiosity as their
// mean, gets wrong). The link is kept when that bound is under the tolerance on both ends; else the
// larger node is split. Pairs of patches get compute_links' form factors (patch_pair).

#include "tprf/transport/link_set.h"

#include "patch_pairs.h"
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <numeric>
#include <type_traits>

namespace tprf {
namespace {

// One link (or one piece of a link's delay kernel) in both directions, until the CSR is assembled:
// ff_ab is what a receives from b. One record per pair holds the parts in 20 bytes a pair instead of
// 32, the larger share of the link stage's peak.
struct LinkRecord {
    std::uint32_t a;
    std::uint32_t b;
    float ff_ab;
    float ff_ba;
    float distance;
};

// The refinement's counters, per job.
struct Counts {
    std::uint64_t leaf_links = 0, cluster_links = 0, candidates = 0;
    LinkStats pair_stats;
};

constexpr int kMaxSamples = 64;
// Share of the tolerance below which a transfer may be dropped unmeasured.
constexpr double kNegligible = 1e-3;
// Share of the tolerance that a link may carry when some of its patches face away from the other
// node, or a shadow edge crosses it: its error then falls on those patches in one direction.
constexpr double kFacingShare = 0.1;
constexpr int kMaxPieces = 8;
// Largest product of two nodes' patch counts that is linked patch by patch without being judged.
constexpr std::size_t kPatchPairsOnly = 2;
// Largest product of two nodes' patch counts whose facing is decided patch by patch (Builder::all_behind).
constexpr std::size_t kExactFacing = 4096;

// A point of node m, sample k of `count`: stratified by area over the node's patches, uniform within
// the patch it falls on.
struct SamplePoint {
    Vec3 x;
    Vec3 n;
};

// See Builder::facing.
struct FacingAngles {
    double low, high;
};

// Point pairs sampled between two nodes, with the kernel at each (before visibility).
struct PairSamples {
    SamplePoint x[kMaxSamples], y[kMaxSamples];
    double k[kMaxSamples], path[kMaxSamples];
    double k_min = 0.0, k_max = 0.0, k_sum = 0.0;
};

// A node's point stored for the oracle's first look: where and which way it faces, in float.
struct StoredPoint {
    Eigen::Vector3f x, n;
};

class Builder {
public:
    Builder(const PatchSet& patches, const Visibility& vis, const LinkOptions& options, const HierarchyOptions& h,
            const ClusterTree& tree)
        : m_patches(patches), m_vis(vis), m_options(options), m_h(h), m_tree(tree), m_radius(circumradii(patches)),
          m_samples(std::clamp(h.samples, 4, kMaxSamples)), m_pieces(std::clamp(h.kernel_pieces, 1, kMaxPieces)) {
        // Every node's points for the oracle's first look, drawn once: a node is judged against hundreds
        // of others, and drawing its points anew for each was a quarter of the link stage.
        m_cone_angle.resize(tree.nodes());
        for (std::size_t m = 0; m < tree.nodes(); ++m) m_cone_angle[m] = std::acos(std::clamp(tree.cone_cos[m], -1.0, 1.0));
        m_points.resize(tree.nodes() * std::size_t(m_samples));
        parallel_for(tree.nodes(), {options.threads, 256, true}, [&](std::size_t m) {
            for (int k = 0; k < m_samples; ++k) {
                const SamplePoint p = sample(std::uint32_t(m), k, m_samples, 0x51ED270B27A3F9C1ull);
                m_points[m * std::size_t(m_samples) + std::size_t(k)] = {p.x.cast<float>(), p.n.cast<float>()};
            }
        });
    }

    // Every pair of patches below cluster c (none below a patch).
    void refine_self(std::uint32_t c, std::vector<LinkRecord>& out, Counts& counts) const {
        if (m_tree.is_leaf(c)) return;
        const auto [a, b] = m_tree.children[c - m_tree.leaves];
        refine_self(a, out, counts);
        refine_self(b, out, counts);
        refine(a, b, out, counts);
    }

    // Every pair of one patch below r and one below s.
    void refine(std::uint32_t r, std::uint32_t s, std::vector<LinkRecord>& out, Counts& counts) const {
        if (settle(r, s, out, counts)) return;
        const auto [big, other] = split_choice(r, s);
        for (std::uint32_t child : m_tree.children[big - m_tree.leaves]) refine(child, other, out, counts);
    }

    // True when (r, s) is settled: a link (two patches, or two nodes the oracle accepts) or nothing
    // (neither can face the other); false when the pairs of the larger one's children with the other
    // must be judged.
    bool settle(std::uint32_t r, std::uint32_t s, std::vector<LinkRecord>& out, Counts& counts) const {
        const FacingAngles rs = facing(r, s), sr = facing(s, r);
        if (rs.low >= M_PI / 2 || sr.low >= M_PI / 2) return true;
        ++counts.candidates;
        if (m_tree.is_leaf(r) && m_tree.is_leaf(s)) {
            patch_link(r, s, out, counts);
            return true;
        }
        return judge(r, s, rs.high < M_PI / 2 && sr.high < M_PI / 2, out, counts);
    }

    // The node of (r, s) to split, the larger (a patch cannot be split), and the other.
    std::pair<std::uint32_t, std::uint32_t> split_choice(std::uint32_t r, std::uint32_t s) const {
        const bool split_r = !m_tree.is_leaf(r) && (m_tree.is_leaf(s) || m_tree.radius[r] >= m_tree.radius[s]);
        return split_r ? std::pair{r, s} : std::pair{s, r};
    }

    std::size_t leaves_below(std::uint32_t m) const { return m_tree.last[m] - m_tree.first[m]; }

private:
    // The range of angles between a normal of `from`'s cone and a direction from `from`'s sphere to
    // `to`'s: below 90 degrees at `low`, some patch of `from` may face some point of `to`; below 90 at
    // `high`, every patch faces every point. Unknown (0 to pi) when the spheres overlap or the cone is
    // open; two patches are left to patch_pair, which decides exactly.
    FacingAngles facing(std::uint32_t from, std::uint32_t to) const {
        if (m_tree.is_leaf(from) && m_tree.is_leaf(to)) return {0.0, M_PI};
        const Vec3 d = m_tree.centre[to] - m_tree.centre[from];
        const double dist = d.norm(), reach = m_tree.radius[from] + m_tree.radius[to];
        if (dist <= reach || m_tree.cone_cos[from] <= -1.0) return {0.0, M_PI};
        const double off_axis = std::acos(std::clamp(m_tree.cone_axis[from].dot(d) / dist, -1.0, 1.0));
        const double spread = m_cone_angle[from] + std::asin(reach / dist);
        return {off_axis - spread - 1e-9, off_axis + spread};
    }

    // True when no corner of a patch below `to` lies in front of any patch below `from` (by
    // patch_pair's own test and tolerance): no pair of their patches would be linked.
    bool all_behind(std::uint32_t from, std::uint32_t to) const {
        for (std::uint32_t a = m_tree.first[from]; a < m_tree.last[from]; ++a) {
            const std::uint32_t p = m_tree.leaf_order[a];
            const Vec3& n = m_patches.normal[p];
            const Vec3& c = m_patches.centroid[p];
            const double tolerance = 1e-9 * m_radius[p];
            if (n.dot(m_tree.centre[to] - c) + m_tree.radius[to] <= tolerance) continue;  // all of `to` behind
            for (std::uint32_t b = m_tree.first[to]; b < m_tree.last[to]; ++b) {
                const std::uint32_t q = m_tree.leaf_order[b];
                const Vec3* poly = m_patches.polygon(q);
                for (std::size_t k = 0; k < m_patches.corners(q); ++k)
                    if (n.dot(poly[k] - c) > tolerance) return false;
            }
        }
        return true;
    }

    SamplePoint sample(std::uint32_t m, int k, int count, std::uint64_t salt) const {
        const std::uint32_t lo = m_tree.first[m], hi = m_tree.last[m];
        const double a0 = m_tree.area_prefix[lo], a1 = m_tree.area_prefix[hi];
        const double target = a0 + (a1 - a0) * (k + hash01(m, salt, 3 * std::uint64_t(k))) / count;
        auto it = std::upper_bound(m_tree.area_prefix.begin() + lo + 1, m_tree.area_prefix.begin() + hi, target);
        const std::size_t at = std::size_t(it - m_tree.area_prefix.begin()) - 1;
        const std::uint32_t patch = m_tree.leaf_order[std::min<std::size_t>(at, hi - 1)];
        const Vec3 x = patch_point(m_patches, patch, hash01(m, salt, 3 * std::uint64_t(k) + 1),
                                   hash01(m, salt, 3 * std::uint64_t(k) + 2));
        return {x, m_patches.normal[patch]};
    }

    void emit(std::uint32_t r, std::uint32_t s, double f_rs, double f_sr, float distance, std::vector<LinkRecord>& out) const {
        out.push_back({r, s, float(f_rs), float(f_sr), distance});
    }

    void patch_link(std::uint32_t r, std::uint32_t s, std::vector<LinkRecord>& out, Counts& counts) const {
        if (inert(m_patches, r) || inert(m_patches, s)) return;  // as the flat method: nothing to carry
        const std::uint32_t i = std::min(r, s), j = std::max(r, s);
        PairFormFactors f;
        const bool is_near = near_pair(m_patches, m_radius, m_options.near_factor, i, j);
        if (!patch_pair({m_patches, m_vis, m_options, m_radius}, i, j, is_near, f, counts.pair_stats)) return;
        emit(i, j, f.ij, f.ji, float((m_patches.centroid[i] - m_patches.centroid[j]).norm()), out);
        ++counts.leaf_links;
    }

    // The oracle. True when (r, s) is settled: kept as a link with its delay kernel, or dropped as
    // carrying less than the tolerance; false when it must be refined.
    bool judge(std::uint32_t r, std::uint32_t s, bool all_facing, std::vector<LinkRecord>& out, Counts& counts) const;
    void draw(std::uint32_t r, std::uint32_t s, std::uint64_t salt, int count, PairSamples& out) const;
    // What cast_rays found: the visible pairs' kernel sum, and the rays blocked and cast.
    struct RayTally {
        double visible_sum = 0.0;
        int blocked = 0;
        int cast = 0;
    };
    // Visibility of the facing pairs of p, by rays (in packets): each blocked pair's kernel zeroed,
    // the others' scaled by their glass. False, at its first blocked ray, when `shadow_refines`.
    bool cast_rays(PairSamples& p, int count, bool shadow_refines, RayTally& tally, Counts& counts) const;
    // The kernel's range and sum over m_samples point pairs of each node's stored points (m_points).
    struct Look {
        double k_min, k_max, k_sum;
    };
    Look look(std::uint32_t r, std::uint32_t s, std::uint64_t salt) const;
    void emit_kernel(std::uint32_t r, std::uint32_t s, const PairFormFactors& f, const PairSamples& p, int count,
                     std::vector<LinkRecord>& out) const;

    const PatchSet& m_patches;
    const Visibility& m_vis;
    const LinkOptions& m_options;
    const HierarchyOptions& m_h;
    const ClusterTree& m_tree;
    std::vector<double> m_radius;
    std::vector<double> m_cone_angle;  // per node: its normal cone's half-angle (facing, millions of times)
    int m_samples;
    int m_pieces;
    std::vector<StoredPoint> m_points;  // per node, m_samples points (look)
};

// Point pairs of (r, s) and the kernel at each, unoccluded: drawn for this pair.
void Builder::draw(std::uint32_t r, std::uint32_t s, std::uint64_t salt, int count, PairSamples& out) const {
    // Stratum q of r meets a random stratum of s (a fresh permutation per pair): a fixed pairing would
    // weigh some pairs of strata in every estimate and none of the others, a bias that does not
    // average out over the links of a scene.
    int partner[kMaxSamples];
    for (int q = 0; q < count; ++q) partner[q] = q;
    for (int q = count - 1; q > 0; --q)
        std::swap(partner[q], partner[int(hash01(salt, 0x2545F491u, std::uint64_t(q)) * (q + 1))]);
    out.k_min = INFINITY;
    out.k_max = 0.0;
    out.k_sum = 0.0;
    for (int q = 0; q < count; ++q) {
        out.x[q] = sample(r, q, count, salt);
        out.y[q] = sample(s, partner[q], count, salt ^ 0x5bd1e995u);
        const Vec3 d = out.y[q].x - out.x[q].x;
        const double r2 = d.squaredNorm();
        out.path[q] = std::sqrt(r2);
        out.k[q] = std::max(0.0, out.x[q].n.dot(d)) * std::max(0.0, -out.y[q].n.dot(d)) / (M_PI * r2 * r2);
        out.k_min = std::min(out.k_min, out.k[q]);
        out.k_max = std::max(out.k_max, out.k[q]);
        out.k_sum += out.k[q];
    }
}

// The oracle's first look, tens of millions of times on a large mesh: in float, from the stored points,
// stratum q of r against stratum (a + b q) mod count of s, with a and b (coprime to count) hashed from
// the pair. Over the pairs every stratum of s is equally likely to meet each of r's, as with the fresh
// permutation draw() makes, for one hash instead of count - 1.
Builder::Look Builder::look(std::uint32_t r, std::uint32_t s, std::uint64_t salt) const {
    const int count = m_samples;
    const std::uint64_t h = hash64(salt, 0x2545F491u, 0);
    const int offset = int(h % std::uint64_t(count));
    int stride = 1 + int((h >> 32) % std::uint64_t(count - 1));
    while (std::gcd(stride, count) != 1) stride = stride % (count - 1) + 1;
    const StoredPoint* a = m_points.data() + std::size_t(r) * std::size_t(count);
    const StoredPoint* b = m_points.data() + std::size_t(s) * std::size_t(count);
    float k_min = INFINITY, k_max = 0.0f;
    double k_sum = 0.0;
    for (int q = 0, p = offset; q < count; ++q, p = p + stride < count ? p + stride : p + stride - count) {
        const Eigen::Vector3f d = b[p].x - a[q].x;
        const float r2 = d.squaredNorm();
        const float k = std::max(0.0f, a[q].n.dot(d)) * std::max(0.0f, -b[p].n.dot(d)) / (float(M_PI) * r2 * r2);
        k_min = std::min(k_min, k);
        k_max = std::max(k_max, k);
        k_sum += double(k);
    }
    return {double(k_min), double(k_max), k_sum};
}

bool Builder::judge(std::uint32_t r, std::uint32_t s, bool all_facing, std::vector<LinkRecord>& out,
                    Counts& counts) const {
    const double dist = (m_tree.centre[r] - m_tree.centre[s]).norm();
    const double reach = m_tree.radius[r] + m_tree.radius[s];
    const double gap = dist - reach;
    if (!(gap > 0.0)) return false;  // overlapping bounds: the kernel is unbounded there
    if (m_h.bin_width_m > 0.0 && gap < m_h.min_lag_bins * m_h.bin_width_m) return false;
    // A patch and a pair of patches: a cluster link would save at most one link (a piece of its delay
    // kernel is a link too) and need the oracle's samples; their patch links are exact.
    if (leaves_below(r) * leaves_below(s) <= kPatchPairsOnly) return false;
    const double a_r = m_tree.area[r], a_s = m_tree.area[s], a_big = std::max(a_r, a_s);
    const std::uint64_t salt = std::uint64_t(std::min(r, s)) << 32 | std::max(r, s);
    const Look judged = look(r, s, salt);
    if (judged.k_max == 0.0) {
        // No sample faces the other node, yet their cones and bounds allow it. Dropping the pair
        // would lose whatever part does face, always in the same direction (an enclosure would leak):
        // refine it unless even the largest kernel the bounds allow carries a negligible share of the
        // tolerance.
        if (a_big / (M_PI * gap * gap) <= kNegligible * m_h.tolerance) return true;
        // Small pairs are settled exactly: when no patch of one has the other in front, nothing
        // passes, and the refinement below them would find no link.
        return leaves_below(r) * leaves_below(s) <= kExactFacing && (all_behind(r, s) || all_behind(s, r));
    }
    // A member that faces away from the other node gets the link's light all the same (push) or
    // sends with the others (pull): unless the cones show that none does, the kernel's range goes down
    // to zero, whether or not a sample fell on such a member.
    // Such a link may only carry a small share of the tolerance: over the hundreds of links that reach
    // one patch those errors add up in one direction (light on a face turned away, in a shadow).
    if (!(all_facing && judged.k_min > 0.0) && a_big * judged.k_max > kFacingShare * m_h.tolerance) return false;
    if (a_big * (judged.k_max - judged.k_min) > m_h.tolerance) return false;
    // Accepted on geometry. The form factor comes from fresh samples: the ones that judged the pair
    // were accepted because they varied little, which makes them more likely to have missed where the
    // kernel peaks, so their mean is biased low (an enclosure lost 0.2% of its light per bounce).
    // A shadow that covers a small part of either node is found by its rays only when enough of them
    // are cast: more for links that carry more (each patch in such a shadow would get all of it).
    const double carried = a_big * judged.k_sum / m_samples;
    // Timing inside the nodes: the link hands every patch of a cluster one delay kernel, though each
    // patch's own paths are offset by up to the cluster's radius. A patch end adds nothing here: its
    // patch links would give it one delay too, so refining the other end down to patches could not
    // shorten that part (it made the statue's cluster-to-floor pairs patch pairs, a fifth of its links).
    const double offset = (m_tree.is_leaf(r) ? 0.0 : m_tree.radius[r]) + (m_tree.is_leaf(s) ? 0.0 : m_tree.radius[s]);
    if (m_h.time_bins > 0.0 && m_h.bin_width_m > 0.0 &&
        carried * offset / m_h.bin_width_m > m_h.time_bins * m_h.tolerance)
        return false;
    const int count = std::clamp(int(std::ceil(m_samples * std::sqrt(carried / (kFacingShare * m_h.tolerance)))),
                                 m_samples, kMaxSamples);
    PairSamples p;
    draw(r, s, salt ^ 0x9E3779B97F4A7C15ull, count, p);
    // Visibility, by rays between the fresh pairs. A blocked ray means a shadow edge crosses the pair:
    // points of either node may see anything from none to all of the other, and the link would light
    // the shadowed ones as much as the others (or, dropped when no ray passes, leave the lit ones
    // dark). Such a pair is refined, at its first blocked ray (the others would change nothing), unless
    // all it carries is a small share of the tolerance.
    const bool shadow_refines = carried > kFacingShare * m_h.tolerance;
    RayTally rays;
    if (!cast_rays(p, count, shadow_refines, rays, counts)) return false;
    if (rays.blocked > 0 && rays.blocked == rays.cast) return true;  // wholly hidden, and carrying little: dropped
    if (rays.cast == 0) return true;
    emit_kernel(r, s, {a_s * rays.visible_sum / count, a_r * rays.visible_sum / count}, p, count, out);
    ++counts.cluster_links;
    return true;
}

bool Builder::cast_rays(PairSamples& p, int count, bool shadow_refines, RayTally& tally, Counts& counts) const {
    double& visible_sum = tally.visible_sum;
    int& blocked = tally.blocked;
    int& cast = tally.cast;
    const double lift = m_vis.epsilon();
    int ray_of[Visibility::kBatch];
    Vec3 from[Visibility::kBatch], to[Visibility::kBatch];
    double passed[Visibility::kBatch];
    for (int q0 = 0; q0 < count;) {
        int rays = 0;
        for (; q0 < count && rays < Visibility::kBatch; ++q0) {
            if (p.k[q0] <= 0.0) continue;
            ray_of[rays] = q0;
            from[rays] = p.x[q0].x + lift * p.x[q0].n;
            to[rays] = p.y[q0].x + lift * p.y[q0].n;
            ++rays;
        }
        if (rays == 0) break;
        m_vis.transmittances(from, to, rays, passed);
        cast += rays;
        counts.pair_stats.rays += std::uint64_t(rays);
        for (int h = 0; h < rays; ++h) {
            const int q = ray_of[h];
            // Glass between the nodes passes its transmittance; a partial pass is no shadow edge.
            if (!(passed[h] > 0.0)) {
                if (shadow_refines) return false;
                ++blocked;
                p.k[q] = 0.0;
            } else {
                p.k[q] *= passed[h];
                visible_sum += p.k[q];
            }
        }
    }
    return true;
}

// The link's delay kernel from the sampled paths, weighted by their kernel values (delay_pieces: each
// piece at its weighted mean path, so that the total and the mean delay are the samples' exactly).
void Builder::emit_kernel(std::uint32_t r, std::uint32_t s, const PairFormFactors& f, const PairSamples& p, int count,
                          std::vector<LinkRecord>& out) const {
    const double f_rs = f.ij, f_sr = f.ji;
    double share[kMaxPieces], mean[kMaxPieces];
    const int pieces = delay_pieces<double>({p.path, p.k, count}, m_h.bin_width_m, m_pieces, share, mean);
    for (int g = 0; g < pieces; ++g) emit(r, s, f_rs * share[g], f_sr * share[g], float(mean[g]), out);
}

// The CSR by receiver, within a row by delay octave (for bins of 1 / inv_bin; all one octave when
// inv_bin is 0), then source, then distance.
Links assemble(std::size_t nodes, std::vector<std::vector<LinkRecord>>& parts, float inv_bin, int threads) {
    Links links;
    links.row.assign(nodes + 1, 0);
    for (const auto& part : parts)
        for (const LinkRecord& l : part) {
            ++links.row[l.a + 1];
            ++links.row[l.b + 1];
        }
    for (std::size_t m = 0; m < nodes; ++m) links.row[m + 1] += links.row[m];
    const std::size_t total = links.row[nodes];
    links.source.resize(total);
    links.ff.resize(total);
    links.distance.resize(total);
    std::vector<std::uint64_t> cursor(links.row.begin(), links.row.end() - 1);
    for (auto& part : parts) {
        for (const LinkRecord& l : part) {
            const std::uint64_t at = cursor[l.a]++, back = cursor[l.b]++;
            links.source[at] = l.b;
            links.ff[at] = l.ff_ab;
            links.distance[at] = l.distance;
            links.source[back] = l.a;
            links.ff[back] = l.ff_ba;
            links.distance[back] = l.distance;
        }
        std::vector<LinkRecord>().swap(part);
    }
    sort_rows_by_octave(links, inv_bin, threads);
    return links;
}

// A unit of parallel work: every pair below one cluster (b == kNoNode) or between two nodes.
struct Job {
    std::uint32_t a, b;
};

// Cuts the refinement into jobs of at most about `cut` patches a side; the pairs above the cut are
// judged here, their links going to `top`.
std::vector<Job> make_jobs(const Builder& builder, const ClusterTree& tree, std::size_t cut,
                           std::vector<LinkRecord>& top, Counts& counts) {
    std::vector<Job> jobs;
    std::vector<Job> pending;  // pairs still to judge (b != kNoNode) or clusters to open (b == kNoNode)
    if (tree.nodes() > 0) pending.push_back({tree.root(), kNoNode});
    while (!pending.empty()) {
        const Job j = pending.back();
        pending.pop_back();
        if (j.b == kNoNode) {
            if (tree.is_leaf(j.a)) continue;
            if (builder.leaves_below(j.a) <= cut) {
                jobs.push_back(j);
                continue;
            }
            const auto [c0, c1] = tree.children[j.a - tree.leaves];
            pending.push_back({c0, kNoNode});
            pending.push_back({c1, kNoNode});
            pending.push_back({c0, c1});
            continue;
        }
        if (builder.leaves_below(j.a) + builder.leaves_below(j.b) <= 2 * cut) {
            jobs.push_back(j);
            continue;
        }
        if (builder.settle(j.a, j.b, top, counts)) continue;
        const auto [big, other] = builder.split_choice(j.a, j.b);
        for (std::uint32_t child : tree.children[big - tree.leaves]) pending.push_back({child, other});
    }
    return jobs;
}

// The jobs' links and counters, when shares of the build (LinkOptions::shares) each refined theirs: this
// share's jobs go out, every share's come back, and parts[j + 1] and counts[j] of every job j are
// refilled from them. A job's bytes: its index, its record count, its counters, its records.
void exchange_jobs(const LinkShares& shares, std::vector<std::vector<LinkRecord>>& parts, std::vector<Counts>& counts) {
    static_assert(std::is_trivially_copyable_v<LinkRecord> && std::is_trivially_copyable_v<Counts>);
    std::vector<std::byte> mine;
    std::size_t size = 0;  // sized first: the records may be hundreds of MB, not to be copied as they grow
    for (std::size_t j = std::size_t(shares.index); j < counts.size(); j += std::size_t(shares.count))
        size += 2 * sizeof(std::uint64_t) + sizeof(Counts) + parts[j + 1].size() * sizeof(LinkRecord);
    mine.reserve(size);
    const auto put = [&mine](const void* data, std::size_t bytes) {
        if (bytes == 0) return;
        const auto* b = static_cast<const std::byte*>(data);
        mine.insert(mine.end(), b, b + bytes);
    };
    for (std::size_t j = std::size_t(shares.index); j < counts.size(); j += std::size_t(shares.count)) {
        const std::uint64_t header[2] = {j, parts[j + 1].size()};
        put(header, sizeof header);
        put(&counts[j], sizeof(Counts));
        put(parts[j + 1].data(), parts[j + 1].size() * sizeof(LinkRecord));
        std::vector<LinkRecord>().swap(parts[j + 1]);
    }
    const std::vector<std::byte> all = shares.exchange(mine);
    std::vector<std::byte>().swap(mine);
    std::vector<char> seen(counts.size(), 0);
    for (std::size_t at = 0; at < all.size();) {
        std::uint64_t header[2];
        TPRF_CHECK_LE(at + sizeof header + sizeof(Counts), all.size());
        std::memcpy(header, all.data() + at, sizeof header);
        at += sizeof header;
        const std::size_t j = std::size_t(header[0]), n = std::size_t(header[1]);
        TPRF_CHECK_LT(j, counts.size());
        TPRF_CHECK(!seen[j]);
        seen[j] = 1;
        std::memcpy(&counts[j], all.data() + at, sizeof(Counts));
        at += sizeof(Counts);
        TPRF_CHECK_LE(at + n * sizeof(LinkRecord), all.size());
        parts[j + 1].resize(n);
        if (n > 0) std::memcpy(parts[j + 1].data(), all.data() + at, n * sizeof(LinkRecord));  // no null argument
        at += n * sizeof(LinkRecord);
    }
    TPRF_CHECK(std::all_of(seen.begin(), seen.end(), [](char c) { return c != 0; }));
}

}  // namespace

void sort_rows_by_octave(Links& links, float inv_bin, int threads) {
    const bool tinted = links.tinted();
    parallel_for(links.receivers(), {threads, 256, true}, [&](std::size_t m) {
        const std::uint64_t a = links.row[m], b = links.row[m + 1];
        std::vector<RowLink> row;
        row.reserve(b - a);
        for (std::uint64_t k = a; k < b; ++k)
            row.push_back({links.source[k], links.ff[k], links.distance[k], tinted ? links.tint[k] : std::uint16_t(0)});
        std::stable_sort(row.begin(), row.end(), [inv_bin](const RowLink& p, const RowLink& q) {
            const int op = delay_octave(p.distance, inv_bin), oq = delay_octave(q.distance, inv_bin);
            if (op != oq) return op < oq;
            return p.source != q.source ? p.source < q.source : p.distance < q.distance;
        });
        for (std::uint64_t k = a; k < b; ++k) {
            const RowLink& e = row[k - a];
            links.source[k] = e.source;
            links.ff[k] = e.ff;
            links.distance[k] = e.distance;
            if (tinted) links.tint[k] = e.tint;
        }
    });
}

// The shortest cluster link, in bins: hierarchy.min_lag_bins, or when 0, default_min_lag_bins of the
// median patch size (twice the median circumradius). The solver's blocks are this short (a power of
// two at most): patches a few bins wide or more keep blocks of 32 bins, its longest window (measured:
// 8-bin blocks made the Cornell box's solve 20% slower), at the price of patch links between the
// nodes nearer than that, a few dozen per patch (four patch sizes).
int min_lag(const PatchSet& patches, const HierarchyOptions& hierarchy) {
    if (hierarchy.min_lag_bins > 0 || !(hierarchy.bin_width_m > 0.0) || patches.size() == 0) return hierarchy.min_lag_bins;
    std::vector<double> radius = circumradii(patches);
    std::nth_element(radius.begin(), radius.begin() + std::ptrdiff_t(radius.size() / 2), radius.end());
    return default_min_lag_bins(2.0 * radius[radius.size() / 2], hierarchy.bin_width_m);
}

LinkSet hierarchical_link_set(const PatchSet& patches, const Visibility& visibility, const LinkOptions& options,
                              const HierarchyOptions& asked, HierarchyStats* stats) {
    TPRF_CHECK(asked.tolerance > 0.0);
    HierarchyOptions hierarchy = asked;
    hierarchy.min_lag_bins = min_lag(patches, asked);
    const int threads = thread_count(options.threads);
    LinkSet set;
    set.tree = build_cluster_tree(patches);
    const Builder builder(patches, visibility, options, hierarchy, set.tree);
    const std::size_t cut = std::max<std::size_t>(256, patches.size() / 64);
    std::vector<std::vector<LinkRecord>> parts(1);
    Counts top_counts;
    const std::vector<Job> jobs = make_jobs(builder, set.tree, cut, parts[0], top_counts);
    parts.resize(jobs.size() + 1);
    std::vector<Counts> counts(jobs.size());
    std::size_t done = 0;  // jobs finished, counted under the mutex so that reports never go back
    std::mutex progress_mutex;
    // With shares, this one refines every count-th job from its index (jobs come in no order of size).
    const LinkShares& shares = options.shares;
    TPRF_CHECK(shares.count >= 1 && shares.index >= 0 && shares.index < shares.count);
    TPRF_CHECK(shares.count == 1 || shares.exchange);
    const std::size_t share_jobs = (jobs.size() + std::size_t(shares.count - 1 - shares.index)) / std::size_t(shares.count);
    parallel_for(share_jobs, {threads, 1, true}, [&](std::size_t k) {
        const std::size_t j = std::size_t(shares.index) + k * std::size_t(shares.count);
        if (jobs[j].b == kNoNode)
            builder.refine_self(jobs[j].a, parts[j + 1], counts[j]);
        else
            builder.refine(jobs[j].a, jobs[j].b, parts[j + 1], counts[j]);
        parts[j + 1].shrink_to_fit();
        if (options.progress) {
            std::lock_guard<std::mutex> lock(progress_mutex);
            options.progress("links", 0.9 * double(++done) / double(share_jobs));
        }
    });
    if (shares.count > 1) exchange_jobs(shares, parts, counts);
    counts.push_back(top_counts);
    const float inv_bin = hierarchy.bin_width_m > 0.0 ? float(1.0 / hierarchy.bin_width_m) : 0.0f;
    set.links = assemble(set.tree.nodes(), parts, inv_bin, threads);
    if (hierarchy.bin_width_m > 0.0) set.block_bins = hierarchy.min_lag_bins;
    if (options.progress) options.progress("links", 1.0);
    if (stats) {
        *stats = {};
        for (const Counts& c : counts) {
            stats->leaf_links += 2 * c.leaf_links;
            stats->cluster_links += 2 * c.cluster_links;
            stats->candidates += c.candidates;
            stats->rays += c.pair_stats.rays;
        }
    }
    return set;
}

std::size_t hierarchical_pair_bytes() { return sizeof(LinkRecord); }

std::size_t oracle_node_bytes(const HierarchyOptions& options) {
    return std::size_t(std::clamp(options.samples, 4, kMaxSamples)) * sizeof(StoredPoint);
}

}  // namespace tprf
