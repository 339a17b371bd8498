#include "tprf/pipeline/capture.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/imaging/capture_film.h"
#include "tprf/imaging/lattice_move.h"
#include "tprf/pipeline/ranks.h"
#include "tprf/scene/scene.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/patch_views.h"
#include "tprf/transport/solver.h"
#include "tprf/transport/spot_light.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <span>
#include <utility>

namespace tprf {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_from(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// Everything fixed for the whole capture.
struct CaptureSetup {
    const Scene& scene;
    const Capture& capture;
    const PatchSet& patches;
    const Visibility& visibility;
    CapturePoints points;
    PatchViewer viewer;            // every patch's samples and cells, shared by all views
    CaptureBins bins{};            // H's bins and the march's
    TimeAxis march{};              // the march's axis (march_time)
    bool confocal = true;
    bool solve = false;
    int max_bounces = -1;          // the capture's (sensor side)
    std::size_t sensors = 0;       // sensor points
    std::size_t pair_base = 0;     // the first pair of this rank's rows of H (0: one rank)
    // Laser point l's rows of this rank's H (T bins per sensor point it is paired with).
    float* rows_of(std::vector<float>& H, std::size_t l) const {
        return H.data() + (first_pair(l) - pair_base) * std::size_t(bins.bins);
    }
    double laser_leg(std::size_t l) const { return capture.account_first_and_last_bounces ? points.laser[l].device_leg : 0.0; }
    double sensor_leg(std::size_t s) const {
        return capture.account_first_and_last_bounces ? points.sensor[s].device_leg : 0.0;
    }
    // The sensor points that laser point l is measured at, as pair indices and sensor indices.
    std::size_t first_pair(std::size_t l) const { return confocal ? l : l * sensors; }
    std::size_t pair_count() const { return confocal ? 1 : sensors; }
    std::size_t sensor_of(std::size_t l, std::size_t k) const { return confocal ? l : k; }
    CaptureScene exact_scene() const { return {capture, patches, visibility, viewer.cells()}; }
};

CaptureSetup make_capture_setup(const Scene& scene, const PatchSet& patches, const Visibility& visibility) {
    CaptureSetup p{scene, *scene.capture, patches, visibility, locate_capture_points(scene, patches, visibility),
                   PatchViewer(patches, visibility)};
    p.confocal = p.capture.type == CaptureType::Confocal;
    p.max_bounces = p.capture.max_bounces;
    p.solve = capture_needs_links(scene);
    p.sensors = p.points.sensor.size();
    p.march = march_time(scene);
    p.bins = {.bins = scene.time.bins,
              .scene = scene.time.bin_map(),
              .march = p.march.bin_map(),
              .march_factor = p.capture.march_bin_factor,
              .delay = scene.solver.delay};
    return p;
}

// What a capture runs with, from start to end: its setup, the links (null unless it marches), the ranks
// that share it and the caller's options.
struct CaptureRun {
    const CaptureSetup& setup;
    const LinkSet* links;
    const RankGroup& ranks;
    const CaptureOptions& options;
};

// The views of a set of wall points, in parallel.
std::vector<std::vector<PatchView>> view_all(const CaptureSetup& p, const std::vector<WallPoint>& points, std::size_t from,
                                             std::size_t to, int threads) {
    std::vector<std::vector<PatchView>> views(to - from);
    parallel_for(to - from, {threads, 1, true}, [&](std::size_t k) {
        const WallPoint& w = points[from + k];
        views[k] = p.viewer.view(w.point, w.normal, w.patch);
    });
    return views;
}

// The light of laser point l that needs no march (orders 1 to 3) at every sensor point it is paired with.
void add_exact(const CaptureSetup& p, std::size_t l, const std::vector<PatchView>& laser_views,
               const std::vector<std::vector<PatchView>>& sensor_views, std::vector<float>& H) {
    const std::vector<PointSource> spots =
        spot_sources(wall_spot(p.points.laser[l], p.capture.laser_power, p.laser_leg(l)), p.patches, p.visibility);
    thread_local std::vector<PathBox> boxes;
    for (std::size_t k = 0; k < p.pair_count(); ++k) {
        const std::size_t s = p.sensor_of(l, k), pair = p.first_pair(l) + k;
        boxes.clear();
        exact_light(p.exact_scene(), {.laser = p.points.laser[l],
                                      .sensor = p.points.sensor[s],
                                      .sensor_cell = std::int64_t(s),
                                      .laser_leg = p.laser_leg(l),
                                      .sensor_leg = p.sensor_leg(s),
                                      .spots = spots,
                                      .laser_views = laser_views,
                                      .sensor_views = p.confocal ? laser_views : sensor_views[s]},
                    boxes);
        add_path_boxes(p.bins, boxes, H.data() + (pair - p.pair_base) * std::size_t(p.bins.bins));
    }
}

// Laser points marched together: their spots' pulses march through the links in one batch, and every
// block is filmed at their sensor points, laser point k's into rows[k] (rows of T bins, one per sensor
// point it is paired with).
struct Batch {
    std::span<const std::size_t> lasers;
    std::span<float* const> rows;
    const std::vector<std::vector<PatchView>>& laser_views;
    // An exhaustive capture's taps of every sensor point (confocal: empty, each laser point's own).
    const std::vector<std::vector<SensorTap>>& sensor_taps;
    // Confocal, or null: each laser point's last legs with the later light received by way of each.
    std::vector<std::vector<PatchLeg>>* legs = nullptr;
};

// The solver's options for a batch whose taps are `taps` (per laser point and pair) and `sensor_taps`.
SolverOptions batch_solver(const CaptureSetup& p, const std::vector<std::vector<std::vector<SensorTap>>>& taps,
                           const std::vector<std::vector<SensorTap>>& sensor_taps, int threads) {
    SolverOptions solver;
    solver.delay = p.scene.solver.delay;
    solver.max_bounces = capture_march_bounces(p.capture);
    solver.threads = threads;
    // Patch light from before the window still reaches the sensor points inside it, a tap's leg later.
    double longest = 0.0;
    for (const auto& by_pair : taps)
        for (const auto& list : by_pair)
            for (const SensorTap& tap : list) longest = std::max(longest, tap.leg);
    for (const auto& list : sensor_taps)
        for (const SensorTap& tap : list) longest = std::max(longest, tap.leg);
    // A march bin's hat reaches F - 1 scene bins before its path: one march bin more.
    solver.first_bin = -bins_before_window(p.march, longest) - (p.capture.march_bin_factor > 1 ? 1 : 0);
    return solver;
}

void solve_batch(const CaptureRun& run, const Batch& batch, CaptureResult& result) {
    const CaptureSetup& p = run.setup;
    const std::size_t K = batch.lasers.size();
    std::vector<Illumination> illuminations(K);
    std::vector<std::vector<std::vector<SensorTap>>> taps(K);
    parallel_for(K, {run.options.threads, 1, true}, [&](std::size_t k) {
        const std::size_t l = batch.lasers[k];
        illuminations[k] = spot_pulses(p.patches, wall_spot(p.points.laser[l], p.capture.laser_power, p.laser_leg(l)),
                                       batch.laser_views[k], p.march, &run.links->glossy);
        if (p.confocal)
            taps[k] = {sensor_taps(p.patches, p.points.sensor[l], p.sensor_leg(l), batch.laser_views[k], &run.links->glossy)};
    });
    std::vector<const Illumination*> marched;
    for (const Illumination& i : illuminations) marched.push_back(&i);
    const SolverOptions solver = batch_solver(p, taps, batch.sensor_taps, run.options.threads);
    if (batch.legs) TPRF_CHECK(p.confocal);
    std::vector<std::vector<double>> received(batch.legs ? K : 0);
    for (std::size_t k = 0; k < received.size(); ++k) received[k].assign(taps[k].front().size(), 0.0);
    std::vector<CaptureFilm::Lane> lanes(K);
    for (std::size_t k = 0; k < K; ++k)
        lanes[k] = {batch.rows[k], &illuminations[k], p.confocal ? &taps[k] : &batch.sensor_taps,
                    batch.legs ? received[k].data() : nullptr};
    CaptureFilm film(p.bins, std::move(lanes), run.options.threads);
    Film* const films[1] = {&film};
    double film_seconds = 0.0;
    const auto start = Clock::now();
    const SolveStats stats = solve_transient(p.patches, *run.links, std::span<const Illumination* const>(marched), p.march,
                                             solver, film_sink(films, film_seconds));
    film.finish();
    if (batch.legs) {
        batch.legs->resize(K);
        for (std::size_t k = 0; k < K; ++k) (*batch.legs)[k] = patch_legs(taps[k].front(), received[k].data());
    }
    result.seconds_solve += seconds_from(start) - film_seconds;
    result.seconds_gather += film_seconds;
    result.link_bin_updates += stats.link_bin_updates;
    ++result.marches;
}

// Illuminations per march: options.batch, or the most (up to kMaxBatch) whose march fits the memory
// budget; the rings grow linearly with the batch (one lane per illumination and colour).
int choose_batch(const CaptureSetup& p, const LinkSet& links, const CaptureOptions& options) {
    if (options.batch > 0) return std::min(options.batch, kMaxBatch);
    if (options.memory_bytes == 0) return kMaxBatch;
    const Rgb& power = p.capture.laser_power;
    const int channels = march_channels(power[0] == power[1] && power[1] == power[2] && keeps_grey(p.patches, links.links));
    SolverOptions solver;
    solver.max_bounces = capture_march_bounces(p.capture);
    std::vector<double> sized(kMaxBatch + 1, -1.0);  // each size planned once (the plan sorts the lists)
    const auto working = [&](int batch) {
        double& bytes = sized[std::size_t(batch)];
        if (bytes < 0.0) bytes = double(solve_working_bytes(p.patches, links, p.march, solver, batch, channels));
        return bytes;
    };
    if (const double one = working(1); one > double(options.memory_bytes))
        throw Error("a capture's march needs about " + std::to_string(std::size_t(one / 1e6)) +
                    " MB for one illumination, over the memory left (" +
                    std::to_string(options.memory_bytes / 1000000) + " MB): raise --max-memory or patches.max_edge");
    return capture_batch(working, double(options.memory_bytes));
}

// Laser points [first, last) of `rank`: whole units of `unit` laser points (a batch, so that every rank
// forms the batches a single process forms; lanes of one march are not bitwise independent of their
// batch mates), as evenly as the count of units allows, in rank order.
std::pair<std::size_t, std::size_t> share_of(std::size_t lasers, std::size_t unit, int rank, int ranks) {
    const std::size_t units = (lasers + unit - 1) / unit;
    const auto start = [&](int r) { return std::min(lasers, units * std::size_t(r) / std::size_t(ranks) * unit); };
    return {start(rank), start(rank + 1)};
}

// march_grid_step S > 1 (confocal): the later bounces marched at the lattice of every S-th grid point
// along each side (and the last), the ranks sharing the lattice by whole batches as they share the
// laser points, and every rank receiving all of it.
LatticeLight march_lattice(const CaptureRun& run, std::size_t batch, CaptureResult& result, CaptureShare& share) {
    const CaptureSetup& p = run.setup;
    const CaptureGrid& g = p.capture.laser_grid;
    LatticeLight out;
    out.as = lattice(g.nu, p.capture.march_grid_step);
    out.bs = lattice(g.nv, p.capture.march_grid_step);
    std::vector<std::size_t>& marched = out.points;
    for (int a : out.as)
        for (int b : out.bs) marched.push_back(std::size_t(a) * std::size_t(g.nv) + std::size_t(b));
    for (std::size_t l : marched) {
        out.laser_leg.push_back(p.laser_leg(l));
        out.sensor_leg.push_back(p.sensor_leg(l));
    }
    const std::size_t T = std::size_t(p.bins.bins);
    const auto [m0, m1] = share_of(marched.size(), batch, run.ranks.rank(), run.ranks.size());
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
        const std::vector<std::vector<PatchView>> views = view_all(p, points, 0, points.size(), run.options.threads);
        share.seconds_views += seconds_from(t0);
        std::vector<std::vector<PatchLeg>> legs;
        solve_batch(run, {std::span<const std::size_t>(marched).subspan(k0, k1 - k0), rows, views, no_sensor_taps, &legs},
                    result);
        for (const auto& list : legs) {
            counts.push_back(list.size());
            mine_legs.insert(mine_legs.end(), list.begin(), list.end());
        }
        if (run.options.progress) run.options.progress("march", double(k1 - m0) / double(m1 - m0));
    }
    out.later = run.ranks.all_gather(std::span<const float>(mine));
    out.legs = run.ranks.all_gather(std::span<const PatchLeg>(mine_legs));
    const std::vector<std::uint64_t> all_counts = run.ranks.all_gather(std::span<const std::uint64_t>(counts));
    TPRF_CHECK_EQ(out.later.size(), marched.size() * T);
    out.index(all_counts);
    return out;
}

// An exhaustive capture's sensor side, viewed once (by every rank): what each sensor point sees, and its
// taps when the capture marches. Empty for a confocal capture.
struct SensorSide {
    std::vector<std::vector<PatchView>> views;
    std::vector<std::vector<SensorTap>> taps;
};

// Laser points [first, last) into this rank's rows of H: views, the exact orders and, batch by batch,
// the march (or, with march_grid_step > 1, the lattice marched first and its light moved to each point).
void compute_share(const CaptureRun& run, std::pair<std::size_t, std::size_t> lasers, const SensorSide& sensors,
                   CaptureResult& result, CaptureShare& share) {
    const CaptureSetup& p = run.setup;
    const auto [first, last] = lasers;
    const std::size_t step = p.solve ? std::size_t(result.batch) : std::size_t(64);
    const bool moved = p.solve && p.capture.march_grid_step > 1;
    LatticeLight lattice_light;
    if (moved) lattice_light = march_lattice(run, step, result, share);
    const std::size_t nv = std::size_t(p.capture.laser_grid.nv);
    for (std::size_t l0 = first; l0 < last; l0 += step) {
        const std::size_t l1 = std::min(last, l0 + step);
        const auto t0 = Clock::now();
        const std::vector<std::vector<PatchView>> laser_views = view_all(p, p.points.laser, l0, l1, run.options.threads);
        share.seconds_views += seconds_from(t0);
        const auto t1 = Clock::now();
        parallel_for(l1 - l0, {run.options.threads, 1, true}, [&](std::size_t k) {
            const std::size_t l = l0 + k;
            add_exact(p, l, laser_views[k], sensors.views, result.H);
            if (!moved) return;
            const std::vector<PatchLeg> legs =
                patch_legs(sensor_taps(p.patches, p.points.sensor[l], p.sensor_leg(l), laser_views[k], &run.links->glossy),
                           nullptr);
            add_moved(lattice_light, {int(l / nv), int(l % nv), p.laser_leg(l), p.sensor_leg(l), legs}, p.bins,
                      p.rows_of(result.H, l));
        });
        for (std::size_t k = 0; k < l1 - l0 && p.confocal; ++k) share.view_pairs += laser_views[k].size();
        share.seconds_gather += seconds_from(t1);
        if (p.solve && !moved) {
            std::vector<std::size_t> batch(l1 - l0);
            std::vector<float*> rows(l1 - l0);
            for (std::size_t k = 0; k < l1 - l0; ++k) {
                batch[k] = l0 + k;
                rows[k] = p.rows_of(result.H, l0 + k);
            }
            solve_batch(run, {batch, rows, laser_views, sensors.taps}, result);
        }
        if (run.options.progress) run.options.progress("capture", double(l1 - first) / double(last - first));
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
    CaptureSetup p = make_capture_setup(scene, patches, visibility);
    const CaptureRun run{p, links, ranks, options};
    CaptureResult result;
    CaptureShare share;
    share.seconds_views = seconds_from(start);
    result.pairs = p.capture.pairs();
    result.bins = p.bins.bins;
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
    result.H.assign((p.first_pair(last) - p.pair_base) * std::size_t(p.bins.bins), 0.0f);
    // An exhaustive capture pairs every laser point with every sensor point: the sensor side is viewed
    // once (by every rank).
    SensorSide sensors;
    if (!p.confocal) {
        const auto t0 = Clock::now();
        sensors.views = view_all(p, p.points.sensor, 0, p.sensors, options.threads);
        if (p.solve)
            for (std::size_t s = 0; s < p.sensors; ++s)
                sensors.taps.push_back(
                    sensor_taps(p.patches, p.points.sensor[s], p.sensor_leg(s), sensors.views[s], &links->glossy));
        share.seconds_views += seconds_from(t0);
    }
    compute_share(run, {first, last}, sensors, result, share);
    result.seconds_views = share.seconds_views;
    result.seconds_gather = share.seconds_gather;
    result.view_pairs = share.view_pairs;
    exchange(ranks, share, result);
    for (const auto& v : sensors.views) result.view_pairs += v.size();
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
