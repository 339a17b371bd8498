#include "tprf/imaging/lattice_move.h"

#include "tprf/core/error.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace tprf {
namespace {

// Where coordinate a falls among the marched ones `at`: the index of the last one not after it, and
// the weight of the next one (0 on a marched coordinate).
std::pair<std::size_t, float> bracket(const std::vector<int>& at, int a) {
    const std::size_t k = std::size_t(std::upper_bound(at.begin(), at.end(), a) - at.begin()) - 1;
    if (at[k] == a) return {k, 0.0f};
    return {k, float(a - at[k]) / float(at[k + 1] - at[k])};
}

}  // namespace

std::vector<PatchLeg> patch_legs(const std::vector<SensorTap>& taps, const double* received) {
    std::vector<PatchLeg> out;
    double factor = 0.0, moment = 0.0, light = 0.0;
    for (std::size_t i = 0; i < taps.size(); ++i) {
        const double w = channel_mean(taps[i].weight);
        factor += w;
        moment += w * taps[i].leg;
        if (received) light += received[i];
        if (i + 1 < taps.size() && taps[i + 1].surface == taps[i].surface) continue;
        if (factor > 0.0 && (!received || light > 0.0))
            out.push_back({taps[i].surface, float(factor), float(moment / factor), float(light)});
        factor = moment = light = 0.0;
    }
    return out;
}

std::vector<int> lattice(int count, int step) {
    std::vector<int> at;
    for (int a = 0; a < count; a += step) at.push_back(a);
    if (at.back() != count - 1) at.push_back(count - 1);
    return at;
}

void LatticeLight::index(const std::vector<std::uint64_t>& counts) {
    const std::size_t marched = points.size();
    TPRF_CHECK_EQ(counts.size(), marched);
    start.assign(marched + 1, 0);
    for (std::size_t k = 0; k < marched; ++k) start[k + 1] = start[k] + counts[k];
    TPRF_CHECK_EQ(start.back(), legs.size());
    light.assign(marched, 0.0);
    mean_leg.assign(marched, 0.0);
    for (std::size_t k = 0; k < marched; ++k) {
        double moment = 0.0;
        for (std::uint64_t i = start[k]; i < start[k + 1]; ++i) {
            light[k] += double(legs[i].light);
            moment += double(legs[i].light) * double(legs[i].leg);
        }
        if (light[k] > 0.0) mean_leg[k] = moment / light[k];
    }
}

void add_moved(const LatticeLight& marched, const MovedPoint& to, const CaptureBins& bins, float* out) {
    const auto [ia, wa] = bracket(marched.as, to.a);
    const auto [ib, wb] = bracket(marched.bs, to.b);
    const std::size_t nb = marched.bs.size(), T = std::size_t(bins.bins);
    const std::size_t corner[4] = {ia * nb + ib, (ia + 1) * nb + ib, ia * nb + ib + 1, (ia + 1) * nb + ib + 1};
    const double weight[4] = {(1.0 - wa) * (1.0 - wb), wa * (1.0 - wb), (1.0 - wa) * wb, wa * wb};
    const std::vector<PatchLeg>& here = to.legs;
    for (int c = 0; c < 4; ++c) {
        if (weight[c] == 0.0) continue;  // (and the corner may lie beyond the last marched one)
        const std::size_t q = corner[c];
        TPRF_CHECK_LT(q, marched.points.size());
        // The sums over q's patches that the point sees too, with their factors' ratio.
        double moved = 0.0, moved_moment = 0.0;
        auto h = here.begin();
        for (std::uint64_t i = marched.start[q]; i < marched.start[q + 1]; ++i) {
            const PatchLeg& from = marched.legs[i];
            while (h != here.end() && h->patch < from.patch) ++h;
            if (h == here.end() || h->patch != from.patch) continue;
            const double share = double(from.light) * (double(h->factor) / double(from.factor));
            moved += share;
            moved_moment += share * double(h->leg);
        }
        if (!(moved > 0.0)) continue;  // the point sees none of the patches q's later light came from
        const double ratio = moved / marched.light[q];
        const double leg = 2.0 * (moved_moment / moved - marched.mean_leg[q]) - (to.sensor_leg - marched.sensor_leg[q]) +
                           (to.laser_leg - marched.laser_leg[q]);
        // Split between two bins as a tap splits its leg (or rounded, with solver.delay nearest).
        const BinSplit at = bins.scene.split(leg, bins.delay);
        const std::int64_t whole = at.first;
        const float f = float(at.frac), w = float(weight[c] * ratio * ratio);
        const float* from = marched.later.data() + q * T;
        const float split[2] = {w * (1.0f - f), w * f};
        for (int side = 0; side < 2; ++side) {
            if (split[side] == 0.0f) continue;
            const std::int64_t shift = whole + side;  // out[t] takes from[t - shift]
            const std::int64_t begin = std::max<std::int64_t>(0, shift);
            const std::int64_t end = std::min<std::int64_t>(std::int64_t(T), std::int64_t(T) + shift);
            for (std::int64_t t = begin; t < end; ++t) out[t] += split[side] * from[t - shift];
        }
    }
}

}  // namespace tprf
