#include "tprf/transport/links.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/neighbours.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "patch_pairs.h"


#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <mutex>

namespace tprf {
namespace {

// One unordered pair's result, kept by its lower-numbered patch until the CSR is assembled.
// One unordered pair while the links are collected: 8 bytes, so that the collection costs less than
// the CSR arrays it becomes (12 bytes a link, 24 a pair). F_ji follows by reciprocity and the
// distance from the centroids.
struct PairLink {
    std::uint32_t other;  // j > i
    float ff_ij;          // i -> j
};

// Strata of a 4 x 4 grid, ordered so that the first four cover the four quadrants: when those
// agree the pair is decided early.
constexpr std::array<int, 16> kStrataA = {0, 10, 8, 2, 5, 15, 13, 7, 1, 11, 9, 3, 4, 14, 12, 6};
constexpr std::array<int, 16> kStrataB = {10, 0, 2, 8, 15, 5, 7, 13, 11, 1, 3, 9, 14, 4, 6, 12};

Vec3 stratified_point(const PatchSet& patches, std::size_t i, int stratum, double ju, double jv, double lift) {
    const double u = ((stratum % 4) + ju) / 4.0, v = ((stratum / 4) + jv) / 4.0;
    return patch_point(patches, i, u, v) + lift * patches.normal[i];
}

// True when some corner of b lies strictly in front of a's plane.
bool any_in_front(const PatchSet& patches, std::size_t a, std::size_t b, double tolerance) {
    const Vec3& n = patches.normal[a];
    const Vec3& c = patches.centroid[a];
    const Vec3* poly = patches.polygon(b);
    for (std::size_t k = 0; k < patches.corners(b); ++k)
        if (n.dot(poly[k] - c) > tolerance) return true;
    return false;
}

// For each patch i, the patches j > i closer than near_factor * (r_i + r_j), sorted: a FLANN radius
// search over the centroids with the largest radius that can matter, then the exact criterion.
std::vector<std::vector<std::uint32_t>> near_pairs(const PatchSet& patches, const std::vector<double>& radius,
                                                   double near_factor, int threads) {
    const std::size_t n = patches.size();
    std::vector<std::vector<std::uint32_t>> out(n);
    if (n < 2) return out;
    const double r_max = *std::max_element(radius.begin(), radius.end());
    const Neighbours found = radius_search(patches.centroid, patches.centroid, near_factor * 2.0 * r_max, threads);
    const auto& indices = found.index;
    const auto& dist2 = found.distance2;
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < indices[i].size(); ++k) {
            const std::size_t j = indices[i][k];
            if (j <= i) continue;
            const double limit = near_factor * (radius[i] + radius[j]);
            if (dist2[i][k] < limit * limit) out[i].push_back(static_cast<std::uint32_t>(j));
        }
        std::sort(out[i].begin(), out[i].end());
    }
    return out;
}

// Fraction of stratified rays between i and j that nothing blocks; the first rays decide when they agree.
// The rays go in packets (Visibility::transmittances): the first ones, then the rest.
double visible_fraction(const PatchSet& patches, const Visibility& vis, std::size_t i, std::size_t j,
                        const LinkOptions& options, std::uint64_t& rays) {
    const int total = std::clamp(options.visibility_rays, 1, 16);
    const int first = std::clamp(options.first_rays, 1, total);
    const double lift = vis.epsilon();
    double visible = 0.0;  // rays that pass, each weighed by the glass it crosses
    int cast = 0;
    Vec3 a[Visibility::kBatch], b[Visibility::kBatch];
    double passed[Visibility::kBatch];
    while (cast < total) {
        if (cast == first && (visible == 0.0 || visible == double(cast))) break;
        const int end = std::min(cast < first ? first : total, cast + Visibility::kBatch);
        for (int k = cast; k < end; ++k) {
            a[k - cast] = stratified_point(patches, i, kStrataA[std::size_t(k)], hash01(i, j, 4 * std::uint64_t(k)),
                                           hash01(i, j, 4 * std::uint64_t(k) + 1), lift);
            b[k - cast] = stratified_point(patches, j, kStrataB[std::size_t(k)], hash01(i, j, 4 * std::uint64_t(k) + 2),
                                           hash01(i, j, 4 * std::uint64_t(k) + 3), lift);
        }
        vis.transmittances(a, b, end - cast, passed);
        for (int k = 0; k < end - cast; ++k) visible += passed[k];
        cast = end;
    }
    rays += std::uint64_t(cast);
    return visible / double(cast);
}

}  // namespace

std::size_t Links::bytes() const {
    return row.size() * sizeof(std::uint64_t) + source.size() * sizeof(std::uint32_t) +
           ff.size() * sizeof(float) + distance.size() * sizeof(float) + tint.size() * sizeof(std::uint16_t) +
           tints.size() * sizeof(tints[0]);
}

void check_tints(const Links& links) {
    if (links.tint.empty()) return;
    TPRF_CHECK_EQ(links.tint.size(), links.size());
    TPRF_CHECK_LT(std::size_t(0), links.tints.size());
    TPRF_CHECK((links.tints[0] == std::array<float, 3>{1.0f, 1.0f, 1.0f}));
    for (std::uint16_t t : links.tint) TPRF_CHECK_LT(std::size_t(t), links.tints.size());
}

bool patch_pair(const PairScene& scene, std::size_t i, std::size_t j, bool is_near, PairFormFactors& out,
                LinkStats& counts) {
    const PatchSet& patches = scene.patches;
    const LinkOptions& options = scene.options;
    const std::vector<double>& radius = scene.radius;
    if (!any_in_front(patches, i, j, 1e-9 * radius[i]) || !any_in_front(patches, j, i, 1e-9 * radius[j])) return false;
    ++counts.pairs_tested;
    // Visibility first: on a scanned statue a fifth of the facing pairs are hidden, and their rays
    // cost less than the form factor (a pair whose form factor is zero, which the rays would have
    // spared, is one in a hundred there).
    const double v = visible_fraction(patches, scene.vis, i, j, options, counts.rays);
    if (v <= 0.0) return false;
    // Integrate over the smaller patch, with the exact inner integral over the larger one.
    const bool i_outer = patches.area[i] <= patches.area[j];
    const std::size_t s = i_outer ? i : j, t = i_outer ? j : i;
    double f_st;
    const double far = options.far_factor * (radius[i] + radius[j]);
    if (is_near) {
        ++counts.near_pairs;
        f_st = polygon_form_factor({patches.polygon(s), patches.corners(s), patches.normal[s]},
                                   {patches.polygon(t), patches.corners(t), patches.normal[t]}, options.quadrature);
    } else if ((patches.centroid[i] - patches.centroid[j]).squaredNorm() < far * far) {
        f_st = polygon_form_factor_gauss({patches.polygon(s), patches.corners(s), patches.normal[s]},
                                         {patches.polygon(t), patches.corners(t), patches.normal[t]});
    } else {
        f_st = point_polygon_form_factor(patches.centroid[s], patches.normal[s], patches.polygon(t),
                                         patches.corners(t), patches.normal[t]);
    }
    if (!(f_st > 0.0)) return false;
    const double f_ts = f_st * patches.area[s] / patches.area[t];  // reciprocity
    out.ij = (i_outer ? f_st : f_ts) * v;
    out.ji = (i_outer ? f_ts : f_st) * v;
    return true;
}

bool near_pair(const PatchSet& patches, const std::vector<double>& radius, double near_factor, std::size_t i,
               std::size_t j) {
    const double limit = near_factor * (radius[i] + radius[j]);
    return (patches.centroid[i] - patches.centroid[j]).squaredNorm() < limit * limit;
}

std::vector<double> circumradii(const PatchSet& patches) {
    std::vector<double> r(patches.size());
    for (std::size_t i = 0; i < patches.size(); ++i) r[i] = circumradius(patches, i);
    return r;
}

namespace {

// The links of patch i to every later patch j > i that faces it and is not fully occluded (patch_pair).
void pair_row(const PairScene& scene, const std::vector<std::uint32_t>& near_i, std::size_t i, std::vector<PairLink>& row,
              LinkStats& counts) {
    const PatchSet& patches = scene.patches;
    const std::size_t n = patches.size();
    if (inert(patches, i)) return;
    std::size_t near_cursor = 0;
    for (std::size_t j = i + 1; j < n; ++j) {
        const bool is_near = near_cursor < near_i.size() && near_i[near_cursor] == j;
        if (is_near) ++near_cursor;
        if (inert(patches, j)) continue;
        PairFormFactors f;
        if (patch_pair(scene, i, j, is_near, f, counts))
            row.push_back({static_cast<std::uint32_t>(j), static_cast<float>(f.ij)});
    }
    row.shrink_to_fit();
}

// The CSR by receiver. Row i takes its sources k < i (scattered from pairs[k], in increasing k) and
// then its own j > i, so that sources increase along every row. Frees the pairs as it goes.
Links assemble(const PatchSet& patches, std::vector<std::vector<PairLink>>& pairs) {
    const std::size_t n = patches.size();
    Links links;
    links.row.assign(n + 1, 0);
    std::vector<std::uint64_t> lower(n, 0);
    for (std::size_t i = 0; i < n; ++i)
        for (const PairLink& p : pairs[i]) ++lower[p.other];
    for (std::size_t i = 0; i < n; ++i) links.row[i + 1] = links.row[i] + lower[i] + pairs[i].size();
    const std::size_t total = links.row[n];
    links.source.resize(total);
    links.ff.resize(total);
    links.distance.resize(total);
    std::vector<std::uint64_t> cursor(links.row.begin(), links.row.end() - 1);
    for (std::size_t i = 0; i < n; ++i) {
        std::uint64_t own = links.row[i] + lower[i];
        for (const PairLink& p : pairs[i]) {
            const std::uint64_t at = cursor[p.other]++;
            const float distance = static_cast<float>((patches.centroid[i] - patches.centroid[p.other]).norm());
            links.source[at] = static_cast<std::uint32_t>(i);
            links.ff[at] = static_cast<float>(double(p.ff_ij) * patches.area[i] / patches.area[p.other]);
            links.distance[at] = distance;
            links.source[own] = p.other;
            links.ff[own] = p.ff_ij;
            links.distance[own] = distance;
            ++own;
        }
        std::vector<PairLink>().swap(pairs[i]);
    }
    return links;
}

// Reports the share of pair work done, at most once per percent, from whichever worker finishes a row.
class LinkProgress {
public:
    LinkProgress(const ProgressFn& progress, std::size_t n) : m_progress(progress), m_total(0.5 * double(n) * double(n) + 1.0) {}
    void row_done(std::uint64_t pairs) {
        const std::uint64_t work = m_done.fetch_add(pairs) + pairs;
        if (!m_progress) return;
        const double fraction = double(work) / m_total;
        std::lock_guard<std::mutex> lock(m_mutex);
        if (fraction - m_reported < 0.01) return;
        m_reported = fraction;
        m_progress("links", std::min(fraction, 1.0));
    }

private:
    const ProgressFn& m_progress;
    double m_total;
    std::atomic<std::uint64_t> m_done{0};
    std::mutex m_mutex;
    double m_reported = 0.0;
};

}  // namespace

Links compute_links(const PatchSet& patches, const Visibility& vis, const LinkOptions& options, LinkStats* stats) {
    const std::size_t n = patches.size();
    TPRF_CHECK_LT(n, std::size_t{0xFFFFFFFFu});
    const int threads = thread_count(options.threads);
    const std::vector<double> radius = circumradii(patches);
    const std::vector<std::vector<std::uint32_t>> near = near_pairs(patches, radius, options.near_factor, threads);
    std::vector<std::vector<PairLink>> pairs(n);
    std::atomic<std::uint64_t> tested{0}, near_count{0}, ray_count{0};
    LinkProgress progress(options.progress, n);
    // A progress callback may throw (a cancelled run): parallel_for hands that to this thread.
    parallel_for(n, {threads, 8, true}, [&](std::size_t i) {
        LinkStats counts;
        pair_row({patches, vis, options, radius}, near[i], i, pairs[i], counts);
        tested += counts.pairs_tested;
        near_count += counts.near_pairs;
        ray_count += counts.rays;
        progress.row_done(n - i);
    });
    Links links = assemble(patches, pairs);
    if (options.progress) options.progress("links", 1.0);
    if (stats) {
        stats->pairs_tested = tested;
        stats->near_pairs = near_count;
        stats->rays = ray_count;
    }
    return links;
}

std::size_t flat_pair_bytes() { return sizeof(PairLink); }

}  // namespace tprf
