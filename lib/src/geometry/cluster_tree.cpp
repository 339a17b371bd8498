#include "tprf/geometry/cluster_tree.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace tprf {
namespace {

// Node m's bounds and cone from its own patch.
void set_leaf(const PatchSet& patches, ClusterTree& t, std::uint32_t i) {
    t.area[i] = patches.area[i];
    t.centre[i] = patches.centroid[i];
    t.radius[i] = circumradius(patches, i);
    t.cone_axis[i] = patches.normal[i];
    t.cone_cos[i] = 1.0;
}

// Cluster c's area, centre and cone axis from its two children: the area-weighted centre and mean of
// their axes (its sphere: tighten(); its cone's width: cone_width()). No axis (the cone is open) when
// the children's normals cancel.
void merge(ClusterTree& t, std::uint32_t c) {
    const auto [a, b] = t.children[c - t.leaves];
    t.area[c] = t.area[a] + t.area[b];
    t.centre[c] = (t.area[a] * t.centre[a] + t.area[b] * t.centre[b]) / t.area[c];
    const Vec3 sum = t.area[a] * t.cone_axis[a] + t.area[b] * t.cone_axis[b];
    const double len = sum.norm();
    const bool open = !(len > 1e-9 * t.area[c]) || t.cone_cos[a] <= -1.0 || t.cone_cos[b] <= -1.0;
    t.cone_axis[c] = len > 1e-9 * t.area[c] ? Vec3(sum / len) : t.cone_axis[a];
    t.cone_cos[c] = open ? -1.0 : 1.0;  // the width: cone_width(), once every axis is set
}

struct Range {
    std::uint32_t first, last;  // into leaf_order
    std::uint32_t parent;       // cluster id, or kNoNode
    int slot;                   // which child of the parent
};

// What a group of patches costs as a node: the square of its centroids' extent, times a factor that
// grows with the spread of its normals (a node whose patches face different ways must be refined
// wherever a link would reach some of them from behind). After the orientation heuristic of
// many-light hierarchies (Conty Estevez and Kulla 2018).
double group_cost(const PatchSet& patches, const std::uint32_t* ids, std::size_t count) {
    Vec3 lo = Vec3::Constant(INFINITY), hi = Vec3::Constant(-INFINITY), mean = Vec3::Zero();
    for (std::size_t k = 0; k < count; ++k) {
        lo = lo.cwiseMin(patches.centroid[ids[k]]);
        hi = hi.cwiseMax(patches.centroid[ids[k]]);
        mean += patches.area[ids[k]] * patches.normal[ids[k]];
    }
    const double len = mean.norm();
    double widest = 1.0;  // smallest cosine to the mean normal
    for (std::size_t k = 0; k < count && len > 0.0; ++k) widest = std::min(widest, patches.normal[ids[k]].dot(mean) / len);
    const double angle = len > 0.0 ? std::acos(std::clamp(widest, -1.0, 1.0)) : M_PI;
    return (hi - lo).squaredNorm() * (1.0 + 2.0 * angle / M_PI);
}

// Reorders ids[0, count) so that the first half holds the smaller keys (median split), ties by id.
template <class Key>
void median_split(std::uint32_t* ids, std::size_t count, Key key) {
    std::nth_element(ids, ids + count / 2, ids + count, [&](std::uint32_t x, std::uint32_t y) {
        const double kx = key(x), ky = key(y);
        return kx < ky || (kx == ky && x < y);
    });
}

// Splits ids[0, count) in two halves: at the median centroid along the longest axis of their box, or
// at the median normal component along the axis where the normals differ most, whichever gives the
// cheaper pair of groups (group_cost).
void split_group(const PatchSet& patches, std::uint32_t* ids, std::size_t count, std::vector<std::uint32_t>& scratch) {
    Vec3 lo = Vec3::Constant(INFINITY), hi = Vec3::Constant(-INFINITY);
    Vec3 nlo = Vec3::Constant(INFINITY), nhi = Vec3::Constant(-INFINITY);
    for (std::size_t k = 0; k < count; ++k) {
        lo = lo.cwiseMin(patches.centroid[ids[k]]);
        hi = hi.cwiseMax(patches.centroid[ids[k]]);
        nlo = nlo.cwiseMin(patches.normal[ids[k]]);
        nhi = nhi.cwiseMax(patches.normal[ids[k]]);
    }
    int axis = 0, naxis = 0;
    (hi - lo).maxCoeff(&axis);
    const double normal_range = (nhi - nlo).maxCoeff(&naxis);
    median_split(ids, count, [&](std::uint32_t i) { return patches.centroid[i][axis]; });
    if (normal_range < 1e-6) return;  // one orientation: the spatial split it is
    const std::size_t mid = count / 2;
    const double spatial = group_cost(patches, ids, mid) + group_cost(patches, ids + mid, count - mid);
    scratch.assign(ids, ids + count);
    median_split(scratch.data(), count, [&](std::uint32_t i) { return patches.normal[i][naxis]; });
    const double oriented = group_cost(patches, scratch.data(), mid) + group_cost(patches, scratch.data() + mid, count - mid);
    if (oriented < spatial) std::copy(scratch.begin(), scratch.end(), ids);
}

// Splits every range of more than one patch in two (split_group), assigning cluster ids in preorder
// (every parent before its children).
void split_ranges(const PatchSet& patches, ClusterTree& t) {
    const std::size_t n = t.leaves;
    std::uint32_t next_cluster = std::uint32_t(n);
    std::vector<Range> stack{{0, std::uint32_t(n), kNoNode, 0}};
    std::vector<std::uint32_t> scratch;
    while (!stack.empty()) {
        const Range r = stack.back();
        stack.pop_back();
        std::uint32_t id;
        if (r.last - r.first == 1) {
            id = t.leaf_order[r.first];
        } else {
            id = next_cluster++;
            split_group(patches, t.leaf_order.data() + r.first, r.last - r.first, scratch);
            const std::uint32_t mid = r.first + (r.last - r.first) / 2;
            // Pushed second-child first, so that the first child is taken next (preorder).
            stack.push_back({mid, r.last, id, 1});
            stack.push_back({r.first, mid, id, 0});
        }
        t.first[id] = r.first;
        t.last[id] = r.last;
        t.parent[id] = r.parent;
        if (r.parent != kNoNode) t.children[r.parent - n][std::size_t(r.slot)] = id;
    }
}

void allocate(ClusterTree& t, std::size_t n, std::size_t m) {
    t.leaves = n;
    t.parent.assign(m, kNoNode);
    t.area.assign(m, 0.0);
    t.centre.assign(m, Vec3::Zero());
    t.radius.assign(m, 0.0);
    t.cone_axis.assign(m, Vec3::UnitZ());
    t.cone_cos.assign(m, 1.0);
    t.children.assign(m - n, {kNoNode, kNoNode});
    t.leaf_order.resize(n);
    std::iota(t.leaf_order.begin(), t.leaf_order.end(), 0u);
    t.first.assign(m, 0);
    t.last.assign(m, 0);
}

// Cluster c's radius from its patches' corners: the sphere about the area centroid that holds them
// (a sphere around the children's spheres would be up to 2.4 times looser).
void tighten(const PatchSet& patches, ClusterTree& t, std::uint32_t c) {
    double r2 = 0.0;
    for (std::uint32_t k = t.first[c]; k < t.last[c]; ++k) {
        const std::uint32_t i = t.leaf_order[k];
        const Vec3* poly = patches.polygon(i);
        for (std::size_t q = 0; q < patches.corners(i); ++q) r2 = std::max(r2, (poly[q] - t.centre[c]).squaredNorm());
    }
    t.radius[c] = std::sqrt(r2);
}

// Cluster c's cone width from its patches' normals: the widest angle between the axis and a normal.
// (The union of the children's cones, used before, was wider at every level up, and a loose cone makes
// the oracle take clusters whose patches all face a node for clusters with some facing away.)
void cone_width(const PatchSet& patches, ClusterTree& t, std::uint32_t c) {
    if (t.cone_cos[c] <= -1.0) return;  // open
    double lowest = 1.0;
    for (std::uint32_t k = t.first[c]; k < t.last[c]; ++k)
        lowest = std::min(lowest, t.cone_axis[c].dot(patches.normal[t.leaf_order[k]]));
    t.cone_cos[c] = std::max(lowest, -1.0);
}

void finish(const PatchSet& patches, ClusterTree& t) {
    for (std::uint32_t i = 0; i < t.leaves; ++i) set_leaf(patches, t, i);
    // Preorder ids: every child has a larger id than its parent, so a reverse sweep is bottom-up.
    for (std::size_t c = t.nodes(); c-- > t.leaves;) merge(t, std::uint32_t(c));
    for (std::size_t c = t.leaves; c < t.nodes(); ++c) {
        tighten(patches, t, std::uint32_t(c));
        cone_width(patches, t, std::uint32_t(c));
    }
    t.area_prefix.assign(t.leaves + 1, 0.0);
    for (std::size_t k = 0; k < t.leaves; ++k) t.area_prefix[k + 1] = t.area_prefix[k] + t.area[t.leaf_order[k]];
}

}  // namespace

std::size_t ClusterTree::bytes() const {
    return parent.size() * (sizeof(std::uint32_t) * 3 + sizeof(double) * 3 + sizeof(Vec3) * 2) +
           children.size() * sizeof(children[0]) + leaf_order.size() * sizeof(std::uint32_t) +
           area_prefix.size() * sizeof(double);  // as bytes_for
}

ClusterTree leaves_only(const PatchSet& patches) {
    ClusterTree t;
    allocate(t, patches.size(), patches.size());
    for (std::uint32_t i = 0; i < t.leaves; ++i) {
        t.first[i] = i;
        t.last[i] = i + 1;
    }
    finish(patches, t);
    return t;
}

ClusterTree build_cluster_tree(const PatchSet& patches) {
    const std::size_t n = patches.size();
    TPRF_CHECK_LT(n, std::size_t{0x7FFFFFFFu});
    ClusterTree t;
    if (n == 0) return t;
    allocate(t, n, 2 * n - 1);
    split_ranges(patches, t);
    finish(patches, t);
    return t;
}

}  // namespace tprf
