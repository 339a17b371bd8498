#include "tprf/pipeline/capture.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/pipeline/ranks.h"
#include "tprf/scene/scene.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <span>
#include <utility>

namespace tprf {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_from(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

double mean3(const Rgb& c) { return (c[0] + c[1] + c[2]) / 3.0; }

// One sensor point's share of a patch's profile: radiance = weight . B_patch(t - leg), per colour.
struct SensorTap {
    std::uint32_t patch = 0;
    Rgb weight = Rgb::Zero();  // albedo_s A_j / (pi^2 S) sum g, per colour (sr^-1)
    double leg = 0.0;          // the g-weighted mean path from the patch to the point, metres
};

// Everything fixed for the whole capture.
struct CapturePlan {
    const Scene& scene;
    const Capture& capture;
    const PatchSet& patches;
    const Visibility& visibility;
    CapturePoints points;
    ViewCells cells{};             // every patch's samples and cells, shared by all views
    bool confocal = true;
    bool solve = false;
    int max_bounces = -1;          // the capture's (sensor side)
    std::size_t sensors = 0;       // sensor points
    std::size_t pair_base = 0;     // the first pair of this rank's rows of H (0: one rank)
    int T = 0;
    double start = 0.0, inv_bin = 0.0;
    // The march's axis (march_time): bins capture.march_bin_factor times wider than the scene's, from
    // the same start.
    TimeAxis march{};
    double march_inv_bin = 0.0;
    // Laser point l's rows of this rank's H (T bins per sensor point it is paired with).
    float* rows_of(std::vector<float>& H, std::size_t l) const { return H.data() + (first_pair(l) - pair_base) * std::size_t(T); }
    double laser_leg(std::size_t l) const { return capture.account_first_and_last_bounces ? points.laser[l].device_leg : 0.0; }
    double sensor_leg(std::size_t s) const {
        return capture.account_first_and_last_bounces ? points.sensor[s].device_leg : 0.0;
    }
    bool keeps(int order) const { return max_bounces < 0 || order <= max_bounces; }
    // The sensor points that laser point l is measured at, as pair indices and sensor indices.
    std::size_t first_pair(std::size_t l) const { return confocal ? l : l * sensors; }
    std::size_t pair_count() const { return confocal ? 1 : sensors; }
    std::size_t sensor_of(std::size_t l, std::size_t k) const { return confocal ? l : k; }
    std::int64_t bin(double path) const { return std::int64_t(std::floor((path - start) * inv_bin)); }
    std::int64_t march_bin(double path) const { return std::int64_t(std::floor((path - start) * march_inv_bin)); }
};

void deposit(std::vector<float>& H, const CapturePlan& p, std::size_t pair, double path, double value) {
    const std::int64_t b = p.bin(path);
    if (b < 0 || b >= p.T || value == 0.0) return;
    H[(pair - p.pair_base) * std::size_t(p.T) + std::size_t(b)] += float(value);
}

// `value` spread evenly over the paths [lo, hi] (metres), each bin taking its share of the interval.
void deposit_box(std::vector<float>& H, const CapturePlan& p, std::size_t pair, double lo, double hi, double value) {
    const std::int64_t first = p.bin(lo), last = p.bin(hi);
    if (first == last || !(hi > lo)) {
        deposit(H, p, pair, lo, value);
        return;
    }
    const double per_metre = value / (hi - lo), width = 1.0 / p.inv_bin;
    float* row = H.data() + (pair - p.pair_base) * std::size_t(p.T);
    for (std::int64_t b = std::max<std::int64_t>(first, 0); b <= std::min<std::int64_t>(last, p.T - 1); ++b) {
        const double start = p.start + double(b) * width;
        const double overlap = std::min(hi, start + width) - std::max(lo, start);
        if (overlap > 0.0) row[b] += float(per_metre * overlap);
    }
}

// Laser point l's spot as point sources: the spot straight, and its images through mirrors and glass.
std::vector<PointSource> spot_sources(const CapturePlan& p, std::size_t l) {
    std::vector<PointSource> out{
        spot_source(wall_spot(p.points.laser[l], p.capture.laser_power, p.laser_leg(l)), p.patches, p.visibility)};
    point_images(PointSource(out.front()), p.visibility, out);
    return out;
}

// Orders 1 and 2: the spot itself where sensor point s's cell holds it, and the spot's light reaching
// s straight (a relay surface that is not planar) or through mirrors (`spots`: spot_sources(p, l)).
void add_spot_light(const CapturePlan& p, std::size_t l, std::size_t s, std::size_t pair,
                    const std::vector<PointSource>& spots, std::vector<float>& H) {
    const WallPoint& laser = p.points.laser[l];
    const WallPoint& sensor = p.points.sensor[s];
    const Rgb spot = p.patches.albedo[laser.patch] * p.capture.laser_power;  // W leaving the spot
    const CaptureGrid& g = p.capture.sensor_grid;
    const double tolerance = 10.0 * p.visibility.epsilon();
    if (p.keeps(1) && grid_cell(g, laser.point, tolerance) == std::int64_t(s)) {
        const double cell = g.u.cross(g.v).norm() / double(g.size());
        deposit(H, p, pair, p.laser_leg(l) + p.sensor_leg(s), mean3(spot) / (M_PI * cell));
    }
    if (!p.keeps(2)) return;
    for (const PointSource& source : spots) {
        PointArrival a;
        if (!arrive(source, sensor.point, sensor.normal, p.visibility, a)) continue;
        const Rgb radiance = p.patches.albedo[sensor.patch] * a.intensity * a.cos_over_r2 / M_PI;
        deposit(H, p, pair, a.path + p.sensor_leg(s), mean3(radiance));
    }
}

// The shortest path from l to s by way of the plane of patch j, both in front of it: the path to the
// mirror image of s, |l - s'|^2 = |l - s|^2 + 4 d_l d_s (d: heights above the plane). No path through
// the patch is shorter.
double shortest_by_plane(const PatchSet& patches, std::uint32_t j, const Vec3& l, const Vec3& s) {
    const Vec3& n = patches.normal[j];
    const double dl = std::max(0.0, n.dot(l - patches.centroid[j])), ds = std::max(0.0, n.dot(s - patches.centroid[j]));
    return std::sqrt((l - s).squaredNorm() + 4.0 * dl * ds);
}

// Order 3: spot -> patch j -> sensor point, over the samples that both ends see. Each sample's light is
// spread over the paths of its cell: its exact path +- the first-order change across the cell, the
// start clamped at the shortest path by way of the patch's plane. The path is convex in the point of
// the patch, so the tangent's minimum over the cell is never later than the cell's true first light:
// onsets are never late, and early only by the path's curvature across a cell (docs/capture.md).
// Views are in patch order, so the patches both see are found by one merge.
void add_third_bounce(const CapturePlan& p, std::size_t l, std::size_t s, std::size_t pair,
                      const std::vector<PatchView>& from_laser, const std::vector<PatchView>& from_sensor,
                      std::vector<float>& H) {
    if (!p.keeps(3)) return;
    const Rgb ends = p.patches.albedo[p.points.laser[l].patch] * p.capture.laser_power *
                     p.patches.albedo[p.points.sensor[s].patch] / (M_PI * M_PI * M_PI * kViewSamples);
    const double legs = p.laser_leg(l) + p.sensor_leg(s);
    // Each patch's views from either end (straight, and through each chain of mirrors) pair up.
    const auto run_end = [](auto it, auto end) {
        const std::uint32_t j = it->patch;
        while (it != end && it->patch == j) ++it;
        return it;
    };
    auto a = from_laser.begin(), b = from_sensor.begin();
    while (a != from_laser.end() && b != from_sensor.end()) {
        if (a->patch < b->patch) {
            ++a;
            continue;
        }
        if (b->patch < a->patch) {
            ++b;
            continue;
        }
        const std::uint32_t j = a->patch;
        const Rgb own = ends * p.patches.albedo[j] * p.patches.area[j];
        const auto a_end = run_end(a, from_laser.end()), b_end = run_end(b, from_sensor.end());
        for (auto va = a; va != a_end; ++va)
            for (auto vb = b; vb != b_end; ++vb) {
                const double scale = mean3(own * va->tint * vb->tint);
                // The points as patch j sees them (their images through the views' chains).
                const double first = legs + shortest_by_plane(p.patches, j, va->from, vb->from);
                for (std::size_t k = 0; k < std::size_t(kViewSamples); ++k) {
                    const double g = double(va->g[k]) * double(vb->g[k]);
                    if (!(g > 0.0)) continue;
                    const double path = legs + double(va->path[k]) + double(vb->path[k]);
                    const double spread = std::abs(double(va->du[k]) + double(vb->du[k])) +
                                          std::abs(double(va->dv[k]) + double(vb->dv[k]));
                    deposit_box(H, p, pair, std::min(path, std::max(first, path - spread)), path + spread, scale * g);
                }
            }
        a = a_end;
        b = b_end;
    }
}

// The g-weighted mean path from a wall point to a patch, and the sum of g: what the solved part of a
// capture uses at both ends (the spot's pulse into the patch, the sensor point's tap on it), so that
// exchanging laser and sensor points exchanges identical pieces.
struct MeanView {
    double sum = 0.0;
    double path = 0.0;
};

MeanView mean_view(const PatchView& v) {
    MeanView m;
    double moment = 0.0;
    for (int k = 0; k < kViewSamples; ++k) {
        m.sum += double(v.g[std::size_t(k)]);
        moment += double(v.g[std::size_t(k)]) * double(v.path[std::size_t(k)]);
    }
    if (m.sum > 0.0) m.path = moment / m.sum;
    return m;
}

// The pulses that laser point l's spot sends into the patch system for the march (CSR by patch): each
// patch's first-bounce exitance at its mean path, split between the two bins of the march about it as
// the taps split their legs. The gather takes these pulses out of the solved profiles again (their light is
// add_third_bounce's, exact per sample); they only feed the later bounces.
Illumination spot_illumination(const CapturePlan& p, std::size_t l, const std::vector<PatchView>& views) {
    const WallPoint& laser = p.points.laser[l];
    const Rgb spot = p.patches.albedo[laser.patch] * p.capture.laser_power / (M_PI * kViewSamples);
    const double bin_width = 1.0 / p.march_inv_bin;
    Illumination out;
    out.row.assign(p.patches.size() + 1, 0);
    for (const PatchView& v : views) {
        const MeanView m = mean_view(v);
        if (!(m.sum > 0.0)) continue;
        const double at = (p.laser_leg(l) + m.path - p.start) * p.march_inv_bin;
        const double whole = std::floor(at), f = at - whole;
        for (int side = 0; side < 2; ++side) {
            const double share = side == 0 ? 1.0 - f : f;
            if (!(share > 0.0)) continue;
            Pulse pulse;
            pulse.path = p.start + (whole + side + 0.5) * bin_width;  // the middle of its bin
            pulse.energy = p.patches.albedo[v.patch] * spot * v.tint * (m.sum * share);
            pulse.order = 2;
            pulse.point_source = 0;
            out.pulses.push_back(pulse);
            ++out.row[v.patch + 1];
        }
    }
    for (std::size_t i = 0; i < p.patches.size(); ++i) out.row[i + 1] += out.row[i];
    return out;
}

std::vector<SensorTap> sensor_taps(const CapturePlan& p, std::size_t s, const std::vector<PatchView>& views) {
    const Rgb albedo = p.patches.albedo[p.points.sensor[s].patch] / (M_PI * M_PI * kViewSamples);
    std::vector<SensorTap> taps;
    taps.reserve(views.size());
    for (const PatchView& v : views) {
        const MeanView m = mean_view(v);
        if (!(m.sum > 0.0)) continue;
        taps.push_back({v.patch, albedo * v.tint * p.patches.area[v.patch] * m.sum, m.path + p.sensor_leg(s)});
    }
    return taps;
}

// A confocal point's last legs by patch, as a marched lattice moves its later light (march_grid_step):
// a patch's taps added up (straight and through mirrors), `factor` the colour mean of their weights and
// `leg` their factor-weighted mean leg, metres; at a marched point, `light` is the later light the point
// received by way of the patch (summed over the bins).
struct PatchLeg {
    std::uint32_t patch = 0;
    float factor = 0.0f;
    float leg = 0.0f;
    float light = 0.0f;
};

// `taps` in patch order (sensor_taps keeps the views' order); `received`, if not null, each tap's light.
std::vector<PatchLeg> patch_legs(const std::vector<SensorTap>& taps, const double* received) {
    std::vector<PatchLeg> out;
    double factor = 0.0, moment = 0.0, light = 0.0;
    for (std::size_t i = 0; i < taps.size(); ++i) {
        const double w = mean3(taps[i].weight);
        factor += w;
        moment += w * taps[i].leg;
        if (received) light += received[i];
        if (i + 1 < taps.size() && taps[i + 1].patch == taps[i].patch) continue;
        if (factor > 0.0 && (!received || light > 0.0))
            out.push_back({taps[i].patch, float(factor), float(moment / factor), float(light)});
        factor = moment = light = 0.0;
    }
    return out;
}

// The views of a set of wall points, in parallel.
std::vector<std::vector<PatchView>> view_all(const CapturePlan& p, const std::vector<WallPoint>& points, std::size_t from,
                                             std::size_t to, int threads) {
    std::vector<std::vector<PatchView>> views(to - from);
    parallel_for(to - from, {threads, 1, true},
                 [&](std::size_t k) { views[k] = view_patches(points[from + k], p.patches, p.visibility, p.cells); });
    return views;
}

// The light of laser point l that needs no march (orders 1 to 3) at every sensor point it is paired with.
void add_exact(const CapturePlan& p, std::size_t l, const std::vector<PatchView>& laser_views,
               const std::vector<std::vector<PatchView>>& sensor_views, std::vector<float>& H) {
    const std::vector<PointSource> spots = spot_sources(p, l);
    for (std::size_t k = 0; k < p.pair_count(); ++k) {
        const std::size_t s = p.sensor_of(l, k), pair = p.first_pair(l) + k;
        add_spot_light(p, l, s, pair, spots, H);
        add_third_bounce(p, l, s, pair, laser_views, p.confocal ? laser_views : sensor_views[s], H);
    }
}

// One laser point's profiles of a solved block, less its exact pulses, at its sensor points: each tap
// shifts its patch's profile by its leg, split between two bins (or rounded, with solver.delay nearest).
// A march on bins F times wider (march_bin_factor) is spread back over the scene's bins: march bin k
// stands for the path k F scene bins after the start (as a delta there is split between the two march
// bins about it), and its light goes to the scene's bins about that path by linear interpolation, a
// hat F bins wide on either side. Each bin's light is kept, and so is its mean path.
class CaptureFilm {
public:
    explicit CaptureFilm(const CapturePlan& p) : m_plan(p) {}

    // `rows`: the laser point's row of H for its first sensor point (its others follow, T bins each).
    // `received` (or null): the light each of the first sensor point's taps gave it, added up.
    void add(const SolveBlock& block, std::size_t lane, float* rows, const Illumination& pulses,
             const std::vector<std::vector<SensorTap>>& taps_by_pair, std::vector<float>& indirect,
             double* received) const {
        const std::size_t n = block.patches, bins = std::size_t(block.bins), K = std::size_t(block.illuminations);
        indirect.resize(n * bins * 3);
        for (std::size_t j = 0; j < n; ++j)
            for (std::size_t b = 0; b < bins; ++b)
                for (std::size_t c = 0; c < 3; ++c)
                    indirect[(j * bins + b) * 3 + c] = block.radiosity[((j * bins + b) * K + lane) * 3 + c];
        for (std::size_t j = 0; j < n; ++j)
            for (std::uint64_t k = pulses.row[j]; k < pulses.row[j + 1]; ++k) {
                const Pulse& pulse = pulses.pulses[k];
                const std::int64_t b = m_plan.march_bin(pulse.path) - block.first_bin;
                if (b < 0 || b >= std::int64_t(bins)) continue;
                float* v = indirect.data() + (j * bins + std::size_t(b)) * 3;
                // What is left is the light of later orders; float cancellation must not make it negative.
                for (int c = 0; c < 3; ++c) v[c] = std::max(0.0f, v[c] - float(pulse.energy[c]));
            }
        for (std::size_t k = 0; k < m_plan.pair_count(); ++k)
            for (std::size_t i = 0; i < taps_by_pair[k].size(); ++i) {
                const double light = add_tap(taps_by_pair[k][i], rows + k * std::size_t(m_plan.T), block.first_bin, bins, indirect);
                if (k == 0 && received) received[i] += light;
            }
    }

private:
    // Adds the tap's light to `out` and returns it (the kernel's taps sum to 1: what falls outside the
    // window included).
    double add_tap(const SensorTap& tap, float* out, int first_bin, std::size_t bins, const std::vector<float>& indirect) const {
        const double lag = tap.leg * m_plan.inv_bin;
        const bool nearest = m_plan.scene.solver.delay == DelayMode::Nearest;
        const std::int64_t whole = std::int64_t(std::floor(nearest ? lag + 0.5 : lag));
        const float f = nearest ? 0.0f : float(lag - double(whole));
        const float w[3] = {float(tap.weight[0] / 3.0), float(tap.weight[1] / 3.0), float(tap.weight[2] / 3.0)};
        // The march bin's light over scene bins [-(F - 1), F] about its path plus `whole`: the hat of
        // the march bin, h(m) = (F - |m|) / F^2, and the leg's split, (1 - f) h(m) + f h(m - 1). For F = 1
        // that is the split alone: 1 - f and f.
        const int F = m_plan.capture.march_bin_factor;
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
                if (t >= 0 && t < m_plan.T) out[t] += kernel[m + F - 1] * v;
            }
        }
        return light;
    }

    const CapturePlan& m_plan;
};

CapturePlan make_plan(const Scene& scene, const PatchSet& patches, const Visibility& visibility) {
    CapturePlan p{scene, *scene.capture, patches, visibility, locate_capture_points(scene, patches, visibility)};
    p.cells = view_cells(patches);
    p.confocal = p.capture.type == CaptureType::Confocal;
    p.max_bounces = p.capture.max_bounces;
    p.solve = capture_needs_links(scene);
    p.sensors = p.points.sensor.size();
    p.T = scene.time.bins;
    p.start = scene.time.start_m();
    p.inv_bin = 1.0 / scene.time.bin_width_m();
    p.march = march_time(scene);
    p.march_inv_bin = 1.0 / p.march.bin_width_m();
    return p;
}

// Laser points `lasers` solved together: their spots' pulses march through the links in one batch, and
// every block is filmed at their sensor points, laser point k's into rows[k] (rows of T bins, one per
// sensor point it is paired with).
// `legs` (confocal, or null): each laser point's last legs with the later light received by way of each.
void solve_batch(const CapturePlan& p, const LinkSet& links, std::span<const std::size_t> lasers,
                 std::span<float* const> rows, const std::vector<std::vector<PatchView>>& laser_views,
                 const std::vector<std::vector<SensorTap>>& sensor_taps_all, const CaptureOptions& options,
                 CaptureResult& result, std::vector<std::vector<PatchLeg>>* legs = nullptr) {
    const std::size_t K = lasers.size();
    std::vector<Illumination> illuminations(K);
    std::vector<std::vector<std::vector<SensorTap>>> taps(K);
    parallel_for(K, {options.threads, 1, true}, [&](std::size_t k) {
        illuminations[k] = spot_illumination(p, lasers[k], laser_views[k]);
        if (p.confocal) taps[k] = {sensor_taps(p, lasers[k], laser_views[k])};
    });
    std::vector<const Illumination*> batch;
    for (const Illumination& i : illuminations) batch.push_back(&i);
    SolverOptions solver;
    solver.delay = p.scene.solver.delay;
    solver.max_bounces = p.max_bounces < 0 ? -1 : p.max_bounces - 1;  // patch orders: one less than the sensor's
    solver.threads = options.threads;
    // Patch light from before the window still reaches the sensor points inside it, a tap's leg later.
    double longest = 0.0;
    for (const auto& by_pair : taps)
        for (const auto& list : by_pair)
            for (const SensorTap& tap : list) longest = std::max(longest, tap.leg);
    for (const auto& list : sensor_taps_all)
        for (const SensorTap& tap : list) longest = std::max(longest, tap.leg);
    // A march bin's hat reaches F - 1 scene bins before its path: one march bin more.
    solver.first_bin = -bins_before_window(p.march, longest) - (p.capture.march_bin_factor > 1 ? 1 : 0);
    if (legs) TPRF_CHECK(p.confocal);
    const CaptureFilm film(p);
    std::vector<std::vector<double>> received(legs ? K : 0);
    for (std::size_t k = 0; k < received.size(); ++k) received[k].assign(taps[k].front().size(), 0.0);
    double film_seconds = 0.0;
    const auto start = Clock::now();
    const SolveStats stats = solve_transient(p.patches, links, std::span<const Illumination* const>(batch), p.march,
                                             solver, [&](const SolveBlock& block) {
        const auto t0 = Clock::now();
        parallel_for(K, {options.threads, 1, true}, [&](std::size_t k) {
            thread_local std::vector<float> indirect;
            film.add(block, k, rows[k], illuminations[k], p.confocal ? taps[k] : sensor_taps_all, indirect,
                     legs ? received[k].data() : nullptr);
        });
        film_seconds += seconds_from(t0);
    });
    if (legs) {
        legs->resize(K);
        for (std::size_t k = 0; k < K; ++k) (*legs)[k] = patch_legs(taps[k].front(), received[k].data());
    }
    result.seconds_solve += seconds_from(start) - film_seconds;
    result.seconds_gather += film_seconds;
    result.link_bin_updates += stats.link_bin_updates;
    ++result.marches;
}

// Illuminations per march: options.batch, or the most (up to kMaxBatch) whose march fits the memory
// budget; the rings grow linearly with the batch (one lane per illumination and colour).
int choose_batch(const CapturePlan& p, const LinkSet& links, const CaptureOptions& options) {
    if (options.batch > 0) return std::min(options.batch, kMaxBatch);
    if (options.memory_bytes == 0) return kMaxBatch;
    bool grey = p.capture.laser_power[0] == p.capture.laser_power[1] && p.capture.laser_power[1] == p.capture.laser_power[2];
    for (const Rgb& a : p.patches.albedo) grey = grey && a[0] == a[1] && a[1] == a[2];
    for (const auto& t : links.links.tints) grey = grey && t[0] == t[1] && t[1] == t[2];  // tinted mirrors
    SolverOptions solver;
    solver.max_bounces = p.max_bounces < 0 ? -1 : p.max_bounces - 1;
    const double one = double(solve_working_bytes(p.patches, links, p.march, solver, 1, grey ? 1 : 3));
    const double all = double(solve_working_bytes(p.patches, links, p.march, solver, kMaxBatch, grey ? 1 : 3));
    const double per_lane = std::max(0.0, (all - one) / (kMaxBatch - 1));
    const double room = double(options.memory_bytes) - one;
    if (room < 0.0)
        throw Error("a capture's march needs about " + std::to_string(std::size_t(one / 1e6)) +
                    " MB for one illumination, over the memory left (" +
                    std::to_string(options.memory_bytes / 1000000) + " MB): raise --max-memory or patches.max_edge");
    int batch = per_lane > 0.0 ? int(std::clamp(1.0 + room / per_lane, 1.0, double(kMaxBatch))) : kMaxBatch;
    // The lane count also picks the march's kernels (a flat set's links are packed for 1, 3, 8, 16 and 24
    // lanes, not for 48), so the straight line is checked where it lands.
    while (batch > 1 && double(solve_working_bytes(p.patches, links, p.march, solver, batch, grey ? 1 : 3)) >
                            double(options.memory_bytes))
        --batch;
    return batch;
}

// Laser points [first, last) of `rank`: whole units of `unit` laser points (a batch, so that every rank
// forms the batches a single process forms; lanes of one march are not bitwise independent of their
// batch mates), as evenly as the count of units allows, in rank order.
std::pair<std::size_t, std::size_t> share_of(std::size_t lasers, std::size_t unit, int rank, int ranks) {
    const std::size_t units = (lasers + unit - 1) / unit;
    const auto start = [&](int r) { return std::min(lasers, units * std::size_t(r) / std::size_t(ranks) * unit); };
    return {start(rank), start(rank + 1)};
}

// The marched coordinates along a grid side of `count` points: every step-th from 0, and the last.
std::vector<int> lattice(int count, int step) {
    std::vector<int> at;
    for (int a = 0; a < count; a += step) at.push_back(a);
    if (at.back() != count - 1) at.push_back(count - 1);
    return at;
}

// Where coordinate a falls among the marched ones `at`: the index of the last one not after it, and
// the weight of the next one (0 on a marched coordinate).
std::pair<std::size_t, float> bracket(const std::vector<int>& at, int a) {
    const std::size_t k = std::size_t(std::upper_bound(at.begin(), at.end(), a) - at.begin()) - 1;
    if (at[k] == a) return {k, 0.0f};
    return {k, float(a - at[k]) / float(at[k + 1] - at[k])};
}

// A confocal scan's later bounces marched at a lattice of its points (march_grid_step): the marched
// coordinates along each side, and in lattice order (a major) each lattice point's laser point, its
// later light (T bins each) and its last legs, lattice point k's legs[start[k], start[k + 1]), with their
// light's sum and light-weighted mean leg.
struct LatticeLight {
    std::vector<int> as, bs;
    std::vector<std::size_t> points;
    std::vector<float> later;
    std::vector<std::uint64_t> start;
    std::vector<PatchLeg> legs;
    std::vector<double> light, mean_leg;
};

// march_grid_step S > 1 (confocal): the later bounces marched at the lattice of every S-th grid point
// along each side (and the last), the ranks sharing the lattice by whole batches as they share the
// laser points, and every rank receiving all of it.
LatticeLight march_lattice(const CapturePlan& p, const LinkSet& links, const RankGroup& ranks, std::size_t batch,
                           const CaptureOptions& options, CaptureResult& result, CaptureShare& share) {
    const CaptureGrid& g = p.capture.laser_grid;
    LatticeLight out;
    out.as = lattice(g.nu, p.capture.march_grid_step);
    out.bs = lattice(g.nv, p.capture.march_grid_step);
    std::vector<std::size_t>& marched = out.points;
    for (int a : out.as)
        for (int b : out.bs) marched.push_back(std::size_t(a) * std::size_t(g.nv) + std::size_t(b));
    const std::size_t T = std::size_t(p.T);
    const auto [m0, m1] = share_of(marched.size(), batch, ranks.rank(), ranks.size());
    std::vector<float> mine((m1 - m0) * T, 0.0f);
    std::vector<std::uint64_t> counts;
    std::vector<PatchLeg> mine_legs;
    const std::vector<std::vector<SensorTap>> no_sensor_taps;  // confocal: each laser point's own
    for (std::size_t k0 = m0; k0 < m1; k0 += batch) {
        const std::size_t k1 = std::min(m1, k0 + batch);
        const auto t0 = Clock::now();
        std::vector<WallPoint> points;
        std::vector<float*> rows;
        for (std::size_t k = k0; k < k1; ++k) {
            points.push_back(p.points.laser[marched[k]]);
            rows.push_back(mine.data() + (k - m0) * T);
        }
        // Viewed again when the scan comes to them: keeping every point's views from here would hold
        // hundreds of MB on a large scan, viewing them again costs a few percent.
        const std::vector<std::vector<PatchView>> views = view_all(p, points, 0, points.size(), options.threads);
        share.seconds_views += seconds_from(t0);
        std::vector<std::vector<PatchLeg>> legs;
        solve_batch(p, links, std::span<const std::size_t>(marched).subspan(k0, k1 - k0), rows, views, no_sensor_taps,
                    options, result, &legs);
        for (const auto& list : legs) {
            counts.push_back(list.size());
            mine_legs.insert(mine_legs.end(), list.begin(), list.end());
        }
        if (options.progress) options.progress("march", double(k1 - m0) / double(m1 - m0));
    }
    out.later = ranks.all_gather(std::span<const float>(mine));
    out.legs = ranks.all_gather(std::span<const PatchLeg>(mine_legs));
    const std::vector<std::uint64_t> all_counts = ranks.all_gather(std::span<const std::uint64_t>(counts));
    TPRF_CHECK_EQ(out.later.size(), marched.size() * T);
    TPRF_CHECK_EQ(all_counts.size(), marched.size());
    out.start.assign(marched.size() + 1, 0);
    for (std::size_t k = 0; k < marched.size(); ++k) out.start[k + 1] = out.start[k] + all_counts[k];
    TPRF_CHECK_EQ(out.start.back(), out.legs.size());
    out.light.assign(marched.size(), 0.0);
    out.mean_leg.assign(marched.size(), 0.0);
    for (std::size_t k = 0; k < marched.size(); ++k) {
        double moment = 0.0;
        for (std::uint64_t i = out.start[k]; i < out.start[k + 1]; ++i) {
            out.light[k] += double(out.legs[i].light);
            moment += double(out.legs[i].light) * double(out.legs[i].leg);
        }
        if (out.light[k] > 0.0) out.mean_leg[k] = moment / out.light[k];
    }
    return out;
}

// Laser point l's later light from the lattice (march_grid_step), added to its row of H: the later
// light of the (up to) four lattice points around it, each moved to l and the four blended bilinearly.
// A later path leaves the point for a patch i and comes back from a patch j; only those two legs depend
// on the point. So a lattice point q's light moves to l by the change of its last legs, weighted as q
// received its later light from each patch, and the first legs change likewise (the scan is confocal:
// the first legs' light is the last legs' by reciprocity): its paths lengthen by twice the change of
// the mean last leg (less the sensor's device leg, plus the laser's), and its light scales by the square
// of the change of the last legs' factors. With the patches' light at q fixed this is exact to first
// order in the step from q to l. Patches that l sees and q's later light did not come back from add
// nothing. A lattice point takes its own light (weight 1, moved by nothing).
void add_moved(const CapturePlan& p, const LatticeLight& lattice_light, std::size_t l, const std::vector<PatchLeg>& here,
               float* out) {
    const CaptureGrid& g = p.capture.laser_grid;
    const auto [ia, wa] = bracket(lattice_light.as, int(l / std::size_t(g.nv)));
    const auto [ib, wb] = bracket(lattice_light.bs, int(l % std::size_t(g.nv)));
    const std::size_t nb = lattice_light.bs.size(), T = std::size_t(p.T);
    const std::size_t corner[4] = {ia * nb + ib, (ia + 1) * nb + ib, ia * nb + ib + 1, (ia + 1) * nb + ib + 1};
    const double weight[4] = {(1.0 - wa) * (1.0 - wb), wa * (1.0 - wb), (1.0 - wa) * wb, wa * wb};
    const bool nearest = p.scene.solver.delay == DelayMode::Nearest;
    for (int c = 0; c < 4; ++c) {
        if (weight[c] == 0.0) continue;  // (and the corner may lie beyond the last marched one)
        const std::size_t q = corner[c];
        TPRF_CHECK_LT(q, lattice_light.points.size());
        const std::size_t ql = lattice_light.points[q];
        // The sums over q's patches that l sees too, with their factors' ratio.
        double moved = 0.0, moved_moment = 0.0;
        auto h = here.begin();
        for (std::uint64_t i = lattice_light.start[q]; i < lattice_light.start[q + 1]; ++i) {
            const PatchLeg& from = lattice_light.legs[i];
            while (h != here.end() && h->patch < from.patch) ++h;
            if (h == here.end() || h->patch != from.patch) continue;
            const double share = double(from.light) * (double(h->factor) / double(from.factor));
            moved += share;
            moved_moment += share * double(h->leg);
        }
        if (!(moved > 0.0)) continue;  // l sees none of the patches q's later light came from
        const double ratio = moved / lattice_light.light[q];
        const double lag = (2.0 * (moved_moment / moved - lattice_light.mean_leg[q]) - (p.sensor_leg(l) - p.sensor_leg(ql)) +
                            (p.laser_leg(l) - p.laser_leg(ql))) * p.inv_bin;
        // Split between two bins as a tap splits its leg (or rounded, with solver.delay nearest).
        const std::int64_t whole = std::int64_t(std::floor(nearest ? lag + 0.5 : lag));
        const float f = nearest ? 0.0f : float(lag - double(whole)), w = float(weight[c] * ratio * ratio);
        const float* from = lattice_light.later.data() + q * T;
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

// Laser points [first, last) into this rank's rows of H: views, the exact orders and, batch by batch,
// the march (or, with march_grid_step > 1, the lattice marched first and its light moved to each point).
// `sensor_views` and `taps_all`: the sensor side of an exhaustive capture.
void compute_share(const CapturePlan& p, const LinkSet* links, const RankGroup& ranks, std::size_t first, std::size_t last,
                   const std::vector<std::vector<PatchView>>& sensor_views,
                   const std::vector<std::vector<SensorTap>>& taps_all, const CaptureOptions& options,
                   CaptureResult& result, CaptureShare& share) {
    const std::size_t step = p.solve ? std::size_t(result.batch) : std::size_t(64);
    const bool moved = p.solve && p.capture.march_grid_step > 1;
    LatticeLight lattice_light;
    if (moved) lattice_light = march_lattice(p, *links, ranks, step, options, result, share);
    for (std::size_t l0 = first; l0 < last; l0 += step) {
        const std::size_t l1 = std::min(last, l0 + step);
        const auto t0 = Clock::now();
        const std::vector<std::vector<PatchView>> laser_views = view_all(p, p.points.laser, l0, l1, options.threads);
        share.seconds_views += seconds_from(t0);
        const auto t1 = Clock::now();
        parallel_for(l1 - l0, {options.threads, 1, true}, [&](std::size_t k) {
            add_exact(p, l0 + k, laser_views[k], sensor_views, result.H);
            if (moved)
                add_moved(p, lattice_light, l0 + k, patch_legs(sensor_taps(p, l0 + k, laser_views[k]), nullptr),
                          p.rows_of(result.H, l0 + k));
        });
        for (std::size_t k = 0; k < l1 - l0 && p.confocal; ++k) share.view_pairs += laser_views[k].size();
        share.seconds_gather += seconds_from(t1);
        if (p.solve && !moved) {
            std::vector<std::size_t> lasers(l1 - l0);
            std::vector<float*> rows(l1 - l0);
            for (std::size_t k = 0; k < l1 - l0; ++k) {
                lasers[k] = l0 + k;
                rows[k] = p.rows_of(result.H, l0 + k);
            }
            solve_batch(p, *links, lasers, rows, laser_views, taps_all, options, result);
        }
        if (options.progress) options.progress("capture", double(l1 - first) / double(last - first));
    }
    share.marches = result.marches;
    share.link_bin_updates = result.link_bin_updates;
    share.seconds_solve = result.seconds_solve;
    share.seconds_gather += result.seconds_gather;
}

// Rank 0 collects every rank's share and rows of H: rank order is laser order, so H is put together in
// place, the same bytes whatever the timing. The capture's counts become the sums over the ranks.
void exchange(const RankGroup& ranks, const CaptureShare& mine, CaptureResult& result) {
    const auto start = Clock::now();
    if (ranks.size() == 1) {
        result.shares = {mine};
        return;
    }
    result.shares = ranks.gather(std::span<const CaptureShare>(&mine, 1));
    result.H = ranks.gather(std::span<const float>(result.H));
    result.seconds_exchange = seconds_from(start);
    if (ranks.rank() != 0) return;
    TPRF_CHECK_EQ(result.H.size(), result.pairs * std::size_t(result.bins));
    result.marches = 0;
    result.link_bin_updates = 0;
    result.view_pairs = 0;
    for (const CaptureShare& s : result.shares) {
        result.marches += s.marches;
        result.link_bin_updates += s.link_bin_updates;
        result.view_pairs += s.view_pairs;
    }
}

}  // namespace

CaptureResult compute_capture(const Scene& scene, const PatchSet& patches, const Visibility& visibility,
                              const LinkSet* links, const CaptureOptions& options) {
    const SingleRank alone;
    const RankGroup& ranks = options.ranks ? *options.ranks : alone;
    const auto start = Clock::now();
    CapturePlan p = make_plan(scene, patches, visibility);
    CaptureResult result;
    CaptureShare share;
    share.seconds_views = seconds_from(start);
    result.pairs = p.capture.pairs();
    result.bins = p.T;
    result.solved = p.solve;
    if (p.solve) TPRF_CHECK(links != nullptr);
    const std::size_t lasers = p.points.laser.size();
    // The batch is rank 0's choice (from its memory limit), so that every rank forms the same batches.
    if (p.solve)
        result.batch = int(std::min<std::int64_t>(
            ranks.broadcast(ranks.rank() == 0 ? std::int64_t(choose_batch(p, *links, options)) : 0),
            std::int64_t(lasers)));
    const auto [first, last] = share_of(lasers, p.solve ? std::size_t(result.batch) : 1, ranks.rank(), ranks.size());
    share.first_laser = first;
    share.laser_points = last - first;
    p.pair_base = p.first_pair(first);
    result.H.assign((p.first_pair(last) - p.pair_base) * std::size_t(p.T), 0.0f);
    // An exhaustive capture pairs every laser point with every sensor point: the sensor side is viewed
    // once (by every rank).
    std::vector<std::vector<PatchView>> sensor_views;
    std::vector<std::vector<SensorTap>> taps_all;
    if (!p.confocal) {
        const auto t0 = Clock::now();
        sensor_views = view_all(p, p.points.sensor, 0, p.sensors, options.threads);
        if (p.solve)
            for (std::size_t s = 0; s < p.sensors; ++s) taps_all.push_back(sensor_taps(p, s, sensor_views[s]));
        share.seconds_views += seconds_from(t0);
    }
    compute_share(p, links, ranks, first, last, sensor_views, taps_all, options, result, share);
    result.seconds_views = share.seconds_views;
    result.seconds_gather = share.seconds_gather;
    result.view_pairs = share.view_pairs;
    exchange(ranks, share, result);
    for (const auto& v : sensor_views) result.view_pairs += v.size();
    result.points = std::move(p.points);
    return result;
}

bool capture_needs_links(const Scene& scene) {
    return scene.capture && (scene.capture->max_bounces < 0 || scene.capture->max_bounces >= 4);
}

bool render_needs_links(const Scene& scene) { return scene.camera || capture_needs_links(scene); }

std::size_t marched_laser_points(const Capture& capture) {
    const CaptureGrid& g = capture.laser_grid;
    if (capture.march_grid_step <= 1) return g.size();
    return lattice(g.nu, capture.march_grid_step).size() * lattice(g.nv, capture.march_grid_step).size();
}

TimeAxis march_time(const Scene& scene) {
    const int F = scene.capture ? scene.capture->march_bin_factor : 1;
    if (F <= 1) return scene.time;
    TimeAxis axis = scene.time;
    axis.bin_width *= F;
    axis.bins = (scene.time.bins + F - 1) / F + 1;
    return axis;
}

}  // namespace tprf
