#pragma once
/// A binary cluster tree over the patches: the nodes that hierarchical links connect.
///
/// Node ids: 0..N-1 are the patches themselves (the leaves), N..M-1 the clusters, M = 2N - 1 (a single
/// patch is its own root). Each cluster covers a contiguous range of `leaf_order`, split in halves by
/// position or by orientation (whichever is cheaper, build_cluster_tree), so that a cluster is compact
/// in space and faces one way where it can; its bounding sphere and normal cone bound what any link
/// from or to it can see. Ids in preorder put every parent before its children: a sweep over ids
/// N..M-1 goes down the tree, the reverse sweep up.

#include "tprf/core/types.h"

#include <array>
#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;

/// No parent: the root.
inline constexpr std::uint32_t kNoNode = 0xFFFFFFFFu;

struct ClusterTree {
    std::size_t leaves = 0;                            ///< N
    std::vector<std::uint32_t> parent;                 ///< M: the cluster holding node m, kNoNode for the root
    std::vector<double> area;                          ///< M: m^2 (a cluster's: the sum of its patches')
    std::vector<Vec3> centre;                          ///< M: area centroid, metres
    std::vector<double> radius;                        ///< M: bounding sphere about `centre` (corners included)
    std::vector<Vec3> cone_axis;                       ///< M: unit axis of the normal cone
    std::vector<double> cone_cos;                      ///< M: every member normal n has n . axis >= cone_cos,
                                                       ///< the widest member's (-1: any direction)
    std::vector<std::array<std::uint32_t, 2>> children;///< M - N: children of cluster N + k
    std::vector<std::uint32_t> leaf_order;             ///< N: patches in tree order
    std::vector<std::uint32_t> first, last;            ///< M: node m covers leaf_order[first[m], last[m])
    std::vector<double> area_prefix;                   ///< N + 1: running sum of patch areas in leaf_order

    std::size_t nodes() const { return parent.size(); }
    std::size_t clusters() const { return nodes() - leaves; }
    bool is_leaf(std::uint32_t m) const { return m < leaves; }
    std::uint32_t root() const { return nodes() == 0 ? kNoNode : (clusters() > 0 ? std::uint32_t(leaves) : 0u); }
    /// Bytes held by the tree.
    std::size_t bytes() const;
    /// Bytes of a tree of `nodes` nodes over `leaves` patches (as bytes() counts them).
    static std::size_t bytes_for(std::size_t leaves, std::size_t nodes) {
        return nodes * (sizeof(std::uint32_t) * 3 + sizeof(double) * 3 + sizeof(Vec3) * 2) +
               (nodes - leaves) * sizeof(std::array<std::uint32_t, 2>) + leaves * sizeof(std::uint32_t) +
               (leaves + 1) * sizeof(double);
    }
};

/// A tree whose nodes are the patches only (the flat method's link set).
ClusterTree leaves_only(const PatchSet& patches);

/// Builds the cluster tree over every patch.
ClusterTree build_cluster_tree(const PatchSet& patches);

}  // namespace tprf
