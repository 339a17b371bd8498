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
    // One thread inside FLANN (its own OpenMP region would end in std::terminate on an exception);
    // the chunks run in parallel here instead. The tree is read-only while searched.
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, 0.0f, false);
    params.cores = 1;
    const float r2 = float(radius * radius);
    const std::size_t chunks = (queries.size() + kQueryChunk - 1) / kQueryChunk;
    parallel_for(chunks, {threads, 1, true}, [&](std::size_t c) {
        const std::size_t q0 = c * kQueryChunk, q1 = std::min(queries.size(), q0 + kQueryChunk);
        flann::Matrix<double> query(qxyz.data() + 3 * q0, q1 - q0, 3);
        std::vector<std::vector<std::size_t>> index;
        std::vector<std::vector<double>> d2;
        tree.radiusSearch(query, index, d2, r2, params);
        for (std::size_t q = q0; q < q1; ++q) {
            found.index[q] = std::move(index[q - q0]);
            found.distance2[q] = std::move(d2[q - q0]);
        }
    });
    return found;
}

}  // namespace tprf
