#include "tprf/imaging/capture_film.h"
#include "tprf/transport/glossy_rows.h"

#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <cmath>

namespace tprf {
namespace {

void deposit(const CaptureBins& p, float* row, double path, double value) {
    const std::int64_t b = p.bin(path);
    if (b < 0 || b >= p.bins || value == 0.0) return;
    row[b] += float(value);
}

// `value` spread evenly over the paths [lo, hi] (metres), each bin taking its share of the interval.
void deposit_box(const CaptureBins& p, float* row, const PathBox& box) {
    const double lo = box.lo, hi = box.hi, value = box.value;
    const std::int64_t first = p.bin(lo), last = p.bin(hi);
    if (first == last || !(hi > lo)) {
        deposit(p, row, lo, value);
        return;
    }
    const double per_metre = value / (hi - lo), width = 1.0 / p.scene.inv_bin;
    for (std::int64_t b = std::max<std::int64_t>(first, 0); b <= std::min<std::int64_t>(last, p.bins - 1); ++b) {
        const double start = p.scene.start_m + double(b) * width;
        const double overlap = std::min(hi, start + width) - std::max(lo, start);
        if (overlap > 0.0) row[b] += float(per_metre * overlap);
    }
}

}  // namespace

void add_path_boxes(const CaptureBins& bins, const std::vector<PathBox>& boxes, float* row) {
    for (const PathBox& box : boxes) deposit_box(bins, row, box);
}

void exact_light(const CaptureScene& scene, const WallPair& pair, std::vector<PathBox>& out) {
    const Capture& capture = scene.capture;
    const PatchSet& patches = scene.patches;
    const auto keeps = [&](int order) { return capture.max_bounces < 0 || order <= capture.max_bounces; };
    const Rgb spot = patches.albedo[pair.laser.patch] * capture.laser_power;  // W leaving the spot
    const CaptureGrid& g = capture.sensor_grid;
    const double tolerance = 10.0 * scene.visibility.epsilon();
    if (keeps(1) && grid_cell(g, pair.laser.point, tolerance) == pair.sensor_cell) {
        const double cell = g.u.cross(g.v).norm() / double(g.size());
        const double path = pair.laser_leg + pair.sensor_leg;
        out.push_back({path, path, channel_mean(spot) / (M_PI * cell)});
    }
    if (!keeps(2)) return;
    spot_arrivals(pair.spots, {pair.sensor.point, pair.sensor.normal, patches.albedo[pair.sensor.patch], pair.sensor_leg},
                  scene.visibility, out);
    if (!keeps(3)) return;
    const Rgb ends = patches.albedo[pair.laser.patch] * capture.laser_power * patches.albedo[pair.sensor.patch] /
                     (M_PI * M_PI * M_PI * kViewSamples);
    third_bounce(patches, {pair.laser_views, pair.sensor_views, ends, pair.laser_leg + pair.sensor_leg, &scene.cells}, out);
}

std::vector<SensorTap> sensor_taps(const PatchSet& patches, const WallPoint& sensor, double leg,
                                   const std::vector<PatchView>& views, const GlossyRows* glossy) {
    if (glossy && glossy->empty()) glossy = nullptr;
    const Rgb albedo = patches.albedo[sensor.patch] / (M_PI * M_PI * kViewSamples);
    std::vector<SensorTap> taps;
    taps.reserve(views.size());
    for (const PatchView& v : views) {
        const MeanView m = mean_view(v);
        if (!(m.sum > 0.0)) continue;
        const Rgb weight = albedo * v.tint * patches.area[v.patch] * m.sum;
        taps.push_back({v.patch, weight, m.path + leg, v.patch});
        if (!glossy || glossy->slot[v.patch] < 0) continue;
        int cell[4];
        double part[4];
        glossy->cells_about(patches, v.patch, sensor.point - patches.centroid[v.patch], cell, part);
        for (int e = 0; e < 4; ++e)
            if (part[e] > 0.0)
                taps.push_back({glossy->out_row(std::size_t(glossy->slot[v.patch]), cell[e]), weight * part[e], m.path + leg,
                                v.patch});
    }
    return taps;
}

CaptureFilm::CaptureFilm(const CaptureBins& bins, std::vector<Lane> lanes, int threads)
    : m_bins(bins), m_lanes(std::move(lanes)), m_threads(threads) {}

void CaptureFilm::add_block(const SolveBlock& block) {
    parallel_for(m_lanes.size(), {m_threads, 1, true}, [&](std::size_t k) {
        thread_local std::vector<float> indirect;
        add_lane(block, k, indirect);
    });
}

// Lane k's profiles of the block, less its spot's pulses, at its sensor points.
void CaptureFilm::add_lane(const SolveBlock& block, std::size_t lane, std::vector<float>& indirect) const {
    const Lane& l = m_lanes[lane];
    const Illumination& pulses = *l.pulses;
    const std::size_t n = block.patches, bins = std::size_t(block.bins), K = std::size_t(block.illuminations);
    indirect.resize(n * bins * 3);
    for (std::size_t j = 0; j < n; ++j) {
        if (block.unread(j)) {  // a glossy in-cell: no tap reads it
            std::fill_n(indirect.data() + j * bins * 3, bins * 3, 0.0f);
            continue;
        }
        for (std::size_t b = 0; b < bins; ++b)
            for (std::size_t c = 0; c < 3; ++c)
                indirect[(j * bins + b) * 3 + c] = block.radiosity[((j * bins + b) * K + lane) * 3 + c];
    }
    for (std::size_t j = 0; j < n; ++j)
        for (std::uint64_t k = pulses.row[j]; k < pulses.row[j + 1]; ++k) {
            const Pulse& pulse = pulses.pulses[k];
            const std::int64_t b = m_bins.march_bin(pulse.path) - block.first_bin;
            if (b < 0 || b >= std::int64_t(bins)) continue;
            float* v = indirect.data() + (j * bins + std::size_t(b)) * 3;
            // What is left is the light of later orders; float cancellation must not make it negative.
            for (int c = 0; c < 3; ++c) v[c] = std::max(0.0f, v[c] - float(pulse.energy[c]));
        }
    const std::vector<std::vector<SensorTap>>& taps_by_pair = *l.taps;
    for (std::size_t k = 0; k < taps_by_pair.size(); ++k)
        for (std::size_t i = 0; i < taps_by_pair[k].size(); ++i) {
            const double light = add_tap(taps_by_pair[k][i], l.rows + k * std::size_t(m_bins.bins), block, indirect);
            if (k == 0 && l.received) l.received[i] += light;
        }
}

// Adds the tap's light to `out` and returns it (the kernel's taps sum to 1: what falls outside the
// window included).
double CaptureFilm::add_tap(const SensorTap& tap, float* out, const SolveBlock& block,
                            const std::vector<float>& indirect) const {
    const int first_bin = block.first_bin;
    const std::size_t bins = std::size_t(block.bins);
    const BinSplit split = m_bins.scene.split(tap.leg, m_bins.delay);
    const std::int64_t whole = split.first;
    const float f = float(split.frac);
    const float w[3] = {float(tap.weight[0] / 3.0), float(tap.weight[1] / 3.0), float(tap.weight[2] / 3.0)};
    // The march bin's light over scene bins [-(F - 1), F] about its path plus `whole`: the hat of
    // the march bin, h(m) = (F - |m|) / F^2, and the leg's split, (1 - f) h(m) + f h(m - 1). For F = 1
    // that is the split alone: 1 - f and f.
    const int F = m_bins.march_factor;
    const auto hat = [F](int m) { return std::abs(m) < F ? float(F - std::abs(m)) / float(F * F) : 0.0f; };
    float kernel[2 * Capture::kMaxMarchBinFactor];
    for (int m = 1 - F; m <= F; ++m) kernel[m + F - 1] = (1.0f - f) * hat(m) + f * hat(m - 1);
    const float* in = indirect.data() + std::size_t(tap.patch) * bins * 3;
    double light = 0.0;
    for (std::size_t b = 0; b < bins; ++b) {
        const float v = w[0] * in[b * 3] + w[1] * in[b * 3 + 1] + w[2] * in[b * 3 + 2];
        if (v == 0.0f) continue;
        light += double(v);
        const std::int64_t t0 = (first_bin + std::int64_t(b)) * F + whole;
        for (int m = 1 - F; m <= F; ++m) {
            const std::int64_t t = t0 + m;
            if (t >= 0 && t < m_bins.bins) out[t] += kernel[m + F - 1] * v;
        }
    }
    return light;
}

}  // namespace tprf
