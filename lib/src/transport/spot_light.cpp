#include "tprf/transport/spot_light.h"
#include "tprf/transport/glossy_rows.h"

#include "tprf/core/time_axis.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"

#include <algorithm>
#include <cmath>

namespace tprf {
namespace {

// The shortest path from l to s by way of the plane of patch j, both in front of it: the path to the
// mirror image of s, |l - s'|^2 = |l - s|^2 + 4 d_l d_s (d: heights above the plane). No path through
// the patch is shorter.
double shortest_by_plane(const PatchSet& patches, std::uint32_t j, const Vec3& l, const Vec3& s) {
    const Vec3& n = patches.normal[j];
    const double dl = std::max(0.0, n.dot(l - patches.centroid[j])), ds = std::max(0.0, n.dot(s - patches.centroid[j]));
    return std::sqrt((l - s).squaredNorm() + 4.0 * dl * ds);
}

// Sample k of patch j, with the patch's front normal.
struct ViewSample {
    const ViewCells& cells;
    std::uint32_t patch;
    std::size_t k;
    const Vec3& n;
};

// A glossy patch's BRDF at one of its samples, from the laser's end towards the sensor's.
Rgb reflected(const GlossyBrdf& brdf, const ViewSample& s, const PatchView& laser, const PatchView& sensor) {
    const Vec3& y = s.cells.point[std::size_t(s.patch) * std::size_t(kViewSamples) + s.k];
    return brdf.eval(s.n, (laser.from - y).normalized(), (sensor.from - y).normalized());
}

}  // namespace

std::vector<PointSource> spot_sources(const LaserSpot& spot, const PatchSet& patches, const Visibility& visibility) {
    std::vector<PointSource> out{spot_source(spot, patches, visibility)};
    point_images(PointSource(out.front()), visibility, out);
    return out;
}

void spot_arrivals(const std::vector<PointSource>& spots, const Receiver& at, const Visibility& visibility,
                   std::vector<PathBox>& out) {
    for (const PointSource& source : spots) {
        PointArrival a;
        if (!arrive(source, at.point, at.normal, visibility, a)) continue;
        const Rgb radiance = at.albedo * a.intensity * a.cos_over_r2 / M_PI;
        const double path = a.path + at.leg;
        out.push_back({path, path, channel_mean(radiance)});
    }
}

// Views are in patch order, so the patches both ends see are found by one merge.
void third_bounce(const PatchSet& patches, const ThirdBounce& ends, std::vector<PathBox>& out) {
    const std::vector<PatchView>& from_laser = ends.from_laser;
    const std::vector<PatchView>& from_sensor = ends.from_sensor;
    const double legs = ends.legs;
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
        const Rgb own = ends.ends * patches.albedo[j] * patches.area[j];
        const GlossyBrdf* brdf = ends.cells ? patches.brdf(j) : nullptr;
        const auto a_end = run_end(a, from_laser.end()), b_end = run_end(b, from_sensor.end());
        for (auto va = a; va != a_end; ++va)
            for (auto vb = b; vb != b_end; ++vb) {
                const double scale = channel_mean(own * va->tint * vb->tint);
                const Rgb glossy = brdf ? Rgb(ends.ends * patches.area[j] * va->tint * vb->tint * M_PI) : Rgb::Zero();
                // The points as patch j sees them (their images through the views' chains).
                const double first = legs + shortest_by_plane(patches, j, va->from, vb->from);
                for (std::size_t k = 0; k < std::size_t(kViewSamples); ++k) {
                    const double g = double(va->g[k]) * double(vb->g[k]);
                    if (!(g > 0.0)) continue;
                    // A glossy patch: pi f(wi, wo) at the sample in place of its albedo.
                    const double weight =
                        brdf ? channel_mean(glossy * reflected(*brdf, {*ends.cells, j, k, patches.normal[j]}, *va, *vb))
                             : scale;
                    const double path = legs + double(va->path[k]) + double(vb->path[k]);
                    const double spread = std::abs(double(va->du[k]) + double(vb->du[k])) +
                                          std::abs(double(va->dv[k]) + double(vb->dv[k]));
                    out.push_back({std::min(path, std::max(first, path - spread)), path + spread, weight * g});
                }
            }
        a = a_end;
        b = b_end;
    }
}

Illumination spot_pulses(const PatchSet& patches, const LaserSpot& spot, const std::vector<PatchView>& views,
                         const TimeAxis& time, const GlossyRows* glossy) {
    if (glossy && glossy->empty()) glossy = nullptr;
    std::vector<std::vector<Pulse>> cells(glossy ? glossy->rows() : 0);
    const Rgb exitance = patches.albedo[spot.patch] * spot.power / (M_PI * kViewSamples);
    const double leg = spot.path;
    const BinMap map = time.bin_map();
    const double start = map.start_m, bin_width = 1.0 / map.inv_bin;
    Illumination out;
    out.row.assign(patches.size() + 1, 0);
    for (const PatchView& v : views) {
        const MeanView m = mean_view(v);
        if (!(m.sum > 0.0)) continue;
        // Split linearly between the two bins about its path, whatever solver.delay says.
        const BinSplit at = split_lag(map.position(leg + m.path), DelayMode::Linear);
        const double whole = double(at.first), f = at.frac;
        for (int side = 0; side < 2; ++side) {
            const double share = side == 0 ? 1.0 - f : f;
            if (!(share > 0.0)) continue;
            Pulse pulse;
            pulse.path = start + (whole + side + 0.5) * bin_width;  // the middle of its bin
            const Rgb irradiance = exitance * v.tint * (m.sum * share);
            pulse.energy = patches.albedo[v.patch] * irradiance;
            pulse.order = 2;
            pulse.point_source = 0;
            out.pulses.push_back(pulse);
            ++out.row[v.patch + 1];
            if (!glossy || glossy->slot[v.patch] < 0) continue;
            // A glossy patch's lobe: its out-cells through the cells' reflectance from the spot.
            glossy->lobe_pulses(patches, v.patch, spot.point, pulse, irradiance, cells);
        }
    }
    for (std::size_t i = 0; i < patches.size(); ++i) out.row[i + 1] += out.row[i];
    for (std::size_t r = 0; r < cells.size(); ++r) {
        out.pulses.insert(out.pulses.end(), cells[r].begin(), cells[r].end());
        out.row.push_back(out.pulses.size());
    }
    return out;
}

}  // namespace tprf
