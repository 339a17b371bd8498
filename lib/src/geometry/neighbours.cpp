#include "tprf/geometry/neighbours.h"

#include "tprf/core/parallel.h"

#include <flann/flann.hpp>

#include <algorithm>

namespace tprf {
namespace {

std::vector<double> flat_xyz(const std::vector<Vec3>& v) {
    std::vector<double> xyz(3 * v.size());
    for (std::size_t i = 0; i < v.size(); ++i)
        for (int k = 0; k < 3; ++k) xyz[3 * i + std::size_t(k)] = v[i][k];
    return xyz;
}

// Queries per task: enough to amortise a task, few enough to balance two threads.
constexpr std::size_t kQueryChunk = 1024;

}  // namespace

Neighbours radius_search(const std::vector<Vec3>& points, const std::vector<Vec3>& queries, double radius,
                         int threads) {
    Neighbours found;
    found.index.resize(queries.size());
    found.distance2.resize(queries.size());
    if (points.empty() || queries.empty()) return found;
    std::vector<double> xyz = flat_xyz(points), qxyz = flat_xyz(queries);
    flann::Matrix<double> data(xyz.data(), points.size(), 3);
    flann::KDTreeSingleIndex<flann::L2_Simple<double>> tree(data, flann::KDTreeSingleIndexParams(12));
    tree.buildIndex();
    // The queries run in parallel here, each through the tree's own search with a result set of ours:
    // FLANN's radiusSearch opens an OpenMP region of its own (even for one thread) in which an
    // exception ends in std::terminate, so an allocation failing there (under ulimit -v, say) aborted
    // the process. The same result set, radius and (unsorted) order as radiusSearch gives. The tree is
    // read-only while searched; no point is ever removed, so its indices are the points' own.
    const flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, 0.0f, false);
    const double r2 = double(float(radius * radius));
    const std::size_t chunks = (queries.size() + kQueryChunk - 1) / kQueryChunk;
    parallel_for(chunks, {threads, 1, true}, [&](std::size_t c) {
        const std::size_t q0 = c * kQueryChunk, q1 = std::min(queries.size(), q0 + kQueryChunk);
        flann::RadiusResultSet<double> result(r2);
        for (std::size_t q = q0; q < q1; ++q) {
            result.clear();
            tree.findNeighbors(result, qxyz.data() + 3 * q, params);
            const std::size_t n = result.size();
            found.index[q].resize(n);
            found.distance2[q].resize(n);
            if (n > 0) result.copy(found.index[q].data(), found.distance2[q].data(), n, params.sorted);
        }
    });
    return found;
}

}  // namespace tprf
