#pragma once
/// Fixed-radius neighbour search over points (FLANN's KD-tree, used header-only): which patch
/// centroids lie near given query points.

#include "tprf/core/types.h"

#include <cstddef>
#include <vector>

namespace tprf {

/// For every query, the indices of the `points` within `radius` (metres) and their squared distances,
/// in no particular order. Queries run on `threads` threads (0: all cores) through core/parallel.h,
/// so that an allocation failure in one reaches the caller as an exception.
struct Neighbours {
    std::vector<std::vector<std::size_t>> index;
    std::vector<std::vector<double>> distance2;
};

/// `points` and `queries` are metres; an empty `points` gives every query no neighbours.
Neighbours radius_search(const std::vector<Vec3>& points, const std::vector<Vec3>& queries, double radius,
                         int threads = 0);

}  // namespace tprf
