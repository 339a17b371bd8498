#include "tprf/transport/light_sources.h"

#include "tprf/core/time_kernel.h"

#include "tprf/core/error.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <variant>

namespace tprf {

// To its plane when x projects inside, else to the nearest edge.
double distance_to_polygon(const Vec3& x, const Vec3* poly, std::size_t count, const Vec3& normal) {
    const Vec3 projected = x - normal.dot(x - poly[0]) * normal;
    bool inside = true;
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < count; ++k) {
        const Vec3& a = poly[k];
        const Vec3& b = poly[(k + 1) % count];
        if ((b - a).cross(projected - a).dot(normal) < 0) inside = false;
        const Vec3 ab = b - a;
        const double s = std::clamp((x - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        best = std::min(best, (a + s * ab - x).norm());
    }
    return inside ? (x - projected).norm() : best;
}

namespace {

AreaSource make_area_source(const Vec3* corners, std::size_t count, const Rgb& radiance, std::uint32_t object) {
    TPRF_CHECK(count == 3 || count == 4);
    AreaSource a;
    std::copy(corners, corners + count, a.corners.begin());
    a.count = std::uint8_t(count);
    const Vec3 cross = count == 4 ? Vec3((corners[2] - corners[0]).cross(corners[3] - corners[1]))
                                  : Vec3((corners[1] - corners[0]).cross(corners[2] - corners[0]));
    a.normal = cross.normalized();
    a.centroid = Vec3::Zero();
    for (std::size_t k = 0; k < count; ++k) a.centroid += corners[k] / double(count);  // a parallelogram's or triangle's
    a.radiance = radiance;
    a.object = object;
    return a;
}

}  // namespace

PointSource spot_source(const LaserSpot& spot, const PatchSet& patches, const Visibility& visibility) {
    const Vec3& normal = patches.normal[spot.patch];
    PointSource s;
    s.position = spot.point + visibility.epsilon() * normal;
    s.origin = spot.point;
    s.path = spot.path;
    s.lobe = normal;
    if (const GlossyBrdf* brdf = patches.brdf(spot.patch); brdf && !spot.incoming.isZero()) {
        s.intensity = spot.power;  // W arriving: the BRDF says what leaves towards each direction
        s.glossy = true;
        s.brdf = *brdf;
        s.incoming = spot.incoming;
    } else {
        s.intensity = patches.albedo[spot.patch] * spot.power;  // W leaving the spot
    }
    s.patch = spot.patch;
    s.order = 2;
    return s;
}


namespace {

// A spot's profile at `angle` radians from its axis: 1 within the half angle h, 0 beyond h + f, and
// the smoothstep of t = (h + f - angle) / f between (1 at the inner edge, 0 at the outer).
double cone_profile(double angle, double half, double falloff) {
    if (angle <= half) return 1.0;
    if (angle >= half + falloff) return 0.0;
    const double t = (half + falloff - angle) / falloff;
    return t * t * (3.0 - 2.0 * t);
}

// The solid angle a spot's profile weighs, integral of spot_profile over the sphere: 2 pi (1 - cos h)
// inside the half angle h, and the falloff by Simpson's rule (its smoothstep is smooth, so 256
// intervals leave ~1e-10).
double spot_solid_angle(const PointSource& s) {
    if (s.spot_axis.isZero()) return 4.0 * M_PI;
    double sum = 2.0 * M_PI * (1.0 - std::cos(s.spot_half_angle));
    if (s.spot_falloff > 0.0) {
        const int n = 256;
        const double step = s.spot_falloff / n;
        double simpson = 0.0;
        for (int k = 0; k <= n; ++k) {
            const double angle = s.spot_half_angle + k * step;
            const double f = cone_profile(angle, s.spot_half_angle, s.spot_falloff) * std::sin(angle);
            simpson += (k == 0 || k == n ? 1.0 : k % 2 ? 4.0 : 2.0) * f;
        }
        sum += 2.0 * M_PI * simpson * step / 3.0;
    }
    return sum;
}

}  // namespace

double PointSource::spot_profile(const Vec3& dir) const {
    if (spot_axis.isZero()) return 1.0;
    return cone_profile(std::acos(std::clamp(spot_axis.dot(dir), -1.0, 1.0)), spot_half_angle, spot_falloff);
}

Rgb PointSource::intensity_towards(const Vec3& dir) const {
    if (lobe.isZero()) return spot_axis.isZero() ? intensity : Rgb(intensity * spot_profile(dir));
    const double cos_o = lobe.dot(dir);
    if (!(cos_o > 0.0)) return Rgb::Zero();
    if (glossy) return intensity * brdf.eval(lobe, incoming, dir) * cos_o;
    return intensity * cos_o / M_PI;
}

Rgb PointSource::power_sent() const {
    if (lobe.isZero()) return spot_solid_angle(*this) * intensity;
    if (glossy) return intensity * brdf.directional_albedo(std::clamp(lobe.dot(incoming), 1e-9, 1.0));
    return intensity;
}

LaserSpot find_laser_spot(const Vec3& origin, const Vec3& direction, const Visibility& visibility) {
    LaserSpot spot;
    const RayHit hit = visibility.intersect(origin, direction, std::numeric_limits<double>::infinity());
    if (!hit.hit || !hit.front) return spot;
    spot.hit = true;
    spot.patch = hit.patch;
    spot.point = hit.point;
    spot.path = hit.distance;
    spot.incoming = -direction.normalized();
    return spot;
}

std::vector<LaserSpot> trace_laser(const Vec3& origin, const Vec3& direction, const Rgb& power,
                                   const PatchSet& patches, const Visibility& visibility) {
    if (visibility.planes().empty()) {
        LaserSpot spot = find_laser_spot(origin, direction, visibility);
        spot.power = power;
        return {spot};
    }
    std::vector<TracedHit> hits;
    visibility.trace(origin, direction, hits);
    std::vector<LaserSpot> spots;
    for (const TracedHit& h : hits) {
        // A back side absorbs; a mirror's or glass' front without a diffuse part sends nothing itself.
        if (!h.hit.front || !(patches.albedo[h.hit.patch] > 0.0).any()) continue;
        LaserSpot spot;
        spot.hit = true;
        spot.patch = h.hit.patch;
        spot.point = h.hit.point;
        spot.path = h.path;
        spot.power = power * h.weight * h.tint;
        spot.incoming = -(h.turn * direction).normalized();
        spots.push_back(spot);
    }
    if (spots.empty()) spots.push_back(LaserSpot{});
    return spots;
}

namespace {

// Whether some of `points` lies on the reflecting side of the chain's last plane (nearest the source).
bool before_last_plane(const MirrorChain& chain, const std::vector<SpecularPlane>& planes, const Vec3* points,
                       std::size_t count) {
    const std::size_t k = std::size_t(chain.length - 1);
    const SpecularPlane& s = planes[chain.plane[k]];
    for (std::size_t c = 0; c < count; ++c)
        if (chain.side[k] * s.normal.dot(points[c] - s.point) > 0.0) return true;
    return false;
}

}  // namespace

void point_images(const PointSource& s, const Visibility& visibility, std::vector<PointSource>& out) {
    const std::vector<MirrorChain>& chains = visibility.chains();
    for (std::size_t c = 0; c < chains.size(); ++c) {
        const MirrorChain& chain = chains[c];
        if (!before_last_plane(chain, visibility.planes(), &s.origin, 1)) continue;
        PointSource image = s;
        image.position = chain.image(s.position);
        image.origin = chain.image(s.origin);
        image.lobe = chain.unfold.linear * s.lobe;
        image.spot_axis = chain.unfold.linear * s.spot_axis;
        image.incoming = chain.unfold.linear * s.incoming;
        image.patch = kNoPatch;
        image.intensity *= chain.tint;
        image.chain = std::int32_t(c);
        out.push_back(image);
    }
}

void add_images(LightSources& sources, const Visibility& visibility) {
    const std::vector<MirrorChain>& chains = visibility.chains();
    const std::size_t points = sources.points.size(), areas = sources.areas.size();
    for (std::size_t k = 0; k < points; ++k)
        if (sources.points[k].chain < 0) point_images(PointSource(sources.points[k]), visibility, sources.points);
    for (std::size_t c = 0; c < chains.size(); ++c) {
        const MirrorChain& chain = chains[c];
        for (std::size_t k = 0; k < areas; ++k) {
            const AreaSource& a = sources.areas[k];
            if (a.chain >= 0 || !before_last_plane(chain, visibility.planes(), a.polygon(), a.count)) continue;
            std::array<Vec3, 4> corners{};
            for (int q = 0; q < a.count; ++q) corners[std::size_t(q)] = chain.image(a.corners[std::size_t(a.count - 1 - q)]);
            AreaSource image = make_area_source(corners.data(), a.count, a.radiance * chain.tint, a.object);
            image.chain = std::int32_t(c);
            sources.areas.push_back(image);
        }
    }
}

LightSources light_sources(const Scene& scene, const PatchSet& patches, const Visibility& visibility) {
    LightSources sources;
    for (const Light& light : scene.lights)
        if (const auto* point = std::get_if<PointLight>(&light)) {
            PointSource s;
            s.position = s.origin = point->position;
            s.intensity = point->intensity;
            if (point->spot) {
                s.spot_axis = point->direction;
                s.spot_half_angle = point->half_angle_deg * M_PI / 180.0;
                s.spot_falloff = point->falloff_deg * M_PI / 180.0;
            }
            sources.points.push_back(s);
        }
    for (const Light& light : scene.lights)
        if (const auto* laser = std::get_if<Laser>(&light)) {
            const std::vector<LaserSpot> spots = trace_laser(laser->origin, laser->direction, laser->power, patches,
                                                             visibility);
            sources.spots.insert(sources.spots.end(), spots.begin(), spots.end());
        }
    for (const LaserSpot& spot : sources.spots)
        if (spot.hit) sources.points.push_back(spot_source(spot, patches, visibility));
    sources.areas = area_sources(&scene, patches);
    add_images(sources, visibility);
    return sources;
}

Vec3 AreaSource::point(double u, double v) const { return polygon_point(corners.data(), count, u, v); }

std::vector<AreaSource> area_sources(const Scene* scene, const PatchSet& patches) {
    std::vector<AreaSource> out;
    // One source per side of an emissive rectangle, made when its first patch on that side is met.
    std::vector<std::array<bool, 2>> made(scene ? scene->objects.size() : 0, {false, false});
    for (std::size_t i = 0; i < patches.size(); ++i) {
        if (!(patches.emission[i] > 0.0).any()) continue;
        const std::uint32_t object = patches.object[i];
        const RectangleShape* rect = nullptr;
        if (scene && object < scene->objects.size()) rect = std::get_if<RectangleShape>(&scene->objects[object].shape);
        if (!rect) {
            out.push_back(make_area_source(patches.polygon(i), patches.corners(i), patches.emission[i], object));
            continue;
        }
        const bool back = patches.normal[i].dot(rect->u.cross(rect->v)) < 0.0;
        if (made[object][back]) continue;
        made[object][back] = true;
        std::array<Vec3, 4> c = {rect->origin, rect->origin + rect->u, rect->origin + rect->u + rect->v,
                                 rect->origin + rect->v};
        if (back) std::reverse(c.begin(), c.end());
        out.push_back(make_area_source(c.data(), 4, patches.emission[i], object));
    }
    return out;
}

bool arrive(const PointSource& source, const Vec3& x, const Vec3& n, const Visibility& visibility,
            PointArrival& out) {
    const Vec3 d = source.position - x;
    const double r = d.norm();
    if (!(r > 0.0)) return false;
    const double cos_x = n.dot(d) / r;
    if (cos_x <= 0.0) return false;
    const Rgb intensity = source.intensity_towards(Vec3(-d / r));
    if (!(intensity > 0.0).any()) return false;
    const double passed = visibility.passes(source.chain, x + visibility.epsilon() * n, source.position);
    if (!(passed > 0.0)) return false;
    out.path = source.path + (source.origin - x).norm();  // from the true point, not the shadow ray's lifted end
    out.intensity = intensity * passed;
    out.cos_over_r2 = cos_x / (r * r);
    return true;
}

double earliest_path(const LightSources& sources, const Vec3& x) {
    double best = std::numeric_limits<double>::infinity();
    for (const PointSource& s : sources.points) best = std::min(best, s.path + (s.origin - x).norm());
    for (const AreaSource& a : sources.areas)
        best = std::min(best, distance_to_polygon(x, a.polygon(), a.count, a.normal));
    return std::isfinite(best) ? best : 0.0;
}

AreaSampling area_sampling(const AreaSource& a, const Vec3& x, double bin_m, double origin, int shadow_rays,
                           int penumbra_rays) {
    const auto side = [](int cells) { return std::max(1, int(std::lround(std::sqrt(double(std::max(cells, 1)))))); };
    AreaSampling s;
    if (bin_m > 0.0) {
        double far = 0.0;
        for (int k = 0; k < a.count; ++k) far = std::max(far, (a.corners[std::size_t(k)] - x).norm());
        const double spread = far - distance_to_polygon(x, a.polygon(), a.count, a.normal);
        s.timing = int(std::clamp(std::ceil(spread / (kAreaBinsPerTimingCell * bin_m)), 2.0, 32.0));
        s.bin_m = bin_m;
        s.origin = origin;
    }
    s.shadow = side(shadow_rays);
    s.penumbra = std::max(side(penumbra_rays), s.shadow);
    return s;
}

namespace {

// The point of cell (u, v) of an m x m grid over source a: its centre, unless the sampling is jittered.
Vec3 cell_point(const AreaSource& a, const AreaSampling& s, int u, int v, int m) {
    return a.point((u + s.jitter_u) / m, (v + s.jitter_v) / m);
}

// Cell (u, v) of an m x m grid over an area source as point x sees it: its point's (cell_point) path
// from x, the earliest path from x's cell (less x's leg), and the cell's light.
struct TimedCell {
    const Vec3& x;
    int u, v, m;
    double path, nearest, weight;
};

// The cell's light spread over its paths to first order (a trapezoid over the path's changes along the
// cell's half-axes; with x's own cell, when it has one, the trapezoid of the same variance as the four
// changes), never before `nearest`, and cut at the bin edges: one pair per bin it touches.
void cell_spread(const AreaSource& a, const AreaSampling& s, const TimedCell& c, std::vector<AreaPair>& out) {
    const Vec3& x = c.x;
    const int u = c.u, v = c.v, m = c.m;
    const double path = c.path, nearest = c.nearest, weight = c.weight;
    const double cu = (u + s.jitter_u) / m, cv = (v + s.jitter_v) / m, h = 0.5 / m;
    const Vec3 dir = (cell_point(a, s, u, v, m) - x) / path;
    const Footprint& f = s.footprint;
    const double half[4] = {0.5 * dir.dot(a.point(cu + h, cv) - a.point(cu - h, cv)),
                            0.5 * dir.dot(a.point(cu, cv + h) - a.point(cu, cv - h)), f.leg_du - dir.dot(f.du),
                            f.leg_dv - dir.dot(f.dv)};
    const double lowest = std::min(nearest, path);
    double wide, narrow;
    equivalent_trapezoid(half, 4, wide, narrow);
    spread_over_bins({path, wide, narrow, lowest}, s.bin_m, s.origin,
                     [&](double at, double share) { out.push_back({at, weight * share}); });
}

// An m x m grid of timing cells over an area source, seen from the point x with unit normal n.
struct TimingGrid {
    const Vec3& x;
    const Vec3& n;
    int m;
};

// The timing cells of the grid over source a that face x: appends each one's pairs with its weight times
// open(u, v, m) (0: blocked), and returns the weight of every cell that faces x, blocked or not.
template <class Open>
double timing_cells(const AreaSource& a, const AreaSampling& s, const TimingGrid& grid, Open&& open,
                    std::vector<AreaPair>& out) {
    const Vec3& x = grid.x;
    const Vec3& n = grid.n;
    const int m = grid.m;
    const auto distance = [&](const Vec3& offset) {
        return distance_to_polygon(x + offset, a.polygon(), a.count, a.normal);
    };
    double nearest = s.bin_m > 0.0 ? distance(Vec3::Zero()) : 0.0;
    if (s.bin_m > 0.0 && !s.footprint.empty()) nearest = std::min(nearest, s.footprint.least_at_corners(distance));
    double total = 0.0;
    for (int c = 0; c < m * m; ++c) {
        const int u = c % m, v = c / m;
        const Vec3 d = cell_point(a, s, u, v, m) - x;
        const double r2 = d.squaredNorm(), path = std::sqrt(r2);
        const double w = std::max(0.0, n.dot(d)) * std::max(0.0, -a.normal.dot(d)) / (r2 * r2) / (double(m) * m);
        if (!(w > 0.0)) continue;
        total += w;
        const double o = open(u, v, m) * (s.towards ? s.towards(d / path) : 1.0);
        if (!(o > 0.0)) continue;
        if (s.bin_m > 0.0) {
            cell_spread(a, s, {x, u, v, m, path, nearest, w * o}, out);
        } else {
            out.push_back({path, w * o});
        }
    }
    return total;
}

}  // namespace

double passes_from_source(const AreaSource& a, const Visibility& vis, const Vec3& x, const Vec3& n, const Vec3& y) {
    return vis.passes(a.chain, x + vis.epsilon() * n, y + vis.epsilon() * a.normal);
}

void passes_from_source(const AreaSource& a, const Visibility& vis, std::span<const Vec3> x, const Vec3& n,
                        std::span<const Vec3> y, std::span<double> passed) {
    TPRF_CHECK_EQ(x.size(), y.size());
    TPRF_CHECK_EQ(x.size(), passed.size());
    const std::size_t count = x.size();
    if (a.chain >= 0) {
        for (std::size_t k = 0; k < count; ++k) passed[k] = passes_from_source(a, vis, x[k], n, y[k]);
        return;
    }
    constexpr std::size_t kBatch = Visibility::kBatch;
    Vec3 from[kBatch], to[kBatch];
    for (std::size_t k0 = 0; k0 < count; k0 += kBatch) {
        const std::size_t m = std::min(kBatch, count - k0);
        for (std::size_t k = 0; k < m; ++k) {  // the lifts passes_from_source makes
            from[k] = x[k0 + k] + vis.epsilon() * n;
            to[k] = y[k0 + k] + vis.epsilon() * a.normal;
        }
        vis.transmittances(from, to, int(m), passed.data() + k0);
    }
}

int rim_probes(const AreaSource& a, Vec3* out) {
    const auto inset = [&](const Vec3& p) { return Vec3(a.centroid + (1.0 - 1e-3) * (p - a.centroid)); };
    int k = 0;
    for (int c = 0; c < a.count; ++c) {
        const Vec3& p = a.corners[std::size_t(c)];
        const Vec3& q = a.corners[std::size_t((c + 1) % a.count)];
        out[k++] = inset(p);
        out[k++] = inset(0.5 * (p + q));
    }
    return k;
}

double arrive_area(const AreaSource& a, const Vec3& x, const Vec3& n, const Visibility& vis, const AreaSampling& s,
                   std::vector<AreaPair>& out) {
    const int coarse = s.shadow;
    // The share of light that passes between x and the centre of cell (u, v) of an m x m grid (0: blocked).
    const auto open_to = [&](int u, int v, int m) { return passes_from_source(a, vis, x, n, cell_point(a, s, u, v, m)); };
    // Shadow rays to the coarse cells that face x. Where they disagree (a penumbra), the pairs take a
    // finer grid and a ray each; elsewhere each pair takes its coarse cell's ray.
    thread_local std::vector<double> coarse_open;
    coarse_open.assign(std::size_t(coarse * coarse), -1.0);  // -1: not tested
    bool any_open = false, any_blocked = false;
    for (int c = 0; c < coarse * coarse; ++c) {
        const int u = c % coarse, v = c / coarse;
        if (!faces_source(a, x, n, cell_point(a, s, u, v, coarse))) continue;
        const double o = open_to(u, v, coarse);
        coarse_open[std::size_t(c)] = o;
        (o > 0.0 ? any_open : any_blocked) = true;
    }
    if (any_open != any_blocked) {  // the grid agrees: so must the rim
        Vec3 rim[8];
        const int count = rim_probes(a, rim);
        for (int k = 0; k < count && !(any_open && any_blocked); ++k)
            if (faces_source(a, x, n, rim[k])) (passes_from_source(a, vis, x, n, rim[k]) > 0.0 ? any_open : any_blocked) = true;
    }
    if (any_open && any_blocked)  // a penumbra
        return timing_cells(a, s, {x, n, std::max(s.timing, s.penumbra)}, open_to, out);
    return timing_cells(a, s, {x, n, s.timing}, [&](int u, int v, int m) {
        const int cu = u * coarse / m, cv = v * coarse / m;
        double& o = coarse_open[std::size_t(cv * coarse + cu)];
        if (o < 0.0) o = open_to(cu, cv, coarse);  // its centre faces away, this pair does not
        return o;
    }, out);
}

double arrive_area_open(const AreaSource& a, const Vec3& x, const Vec3& n, const AreaSampling& s,
                        std::vector<AreaPair>& out) {
    return timing_cells(a, s, {x, n, s.timing}, [](int, int, int) { return 1.0; }, out);
}

double arrive_area_shaded(const AreaSource& a, const Vec3& x, const Vec3& n, const AreaSampling& s,
                          const std::vector<double>& open, std::vector<AreaPair>& out) {
    TPRF_CHECK_EQ(open.size(), std::size_t(s.timing * s.timing));
    return timing_cells(a, s, {x, n, s.timing}, [&](int u, int v, int) { return open[std::size_t(v * s.timing + u)]; },
                        out);
}

double arrive_area_centroid(const AreaSource& a, const Vec3& x, const Vec3& n, const Visibility& vis,
                            std::vector<AreaPair>& out) {
    const double passed = passes_from_source(a, vis, x, n, a.centroid);
    if (!(passed > 0.0)) return 0.0;
    out.push_back({(x - a.centroid).norm(), passed});
    return 1.0;
}

std::vector<AreaPair> merge_pairs_by_bin(const std::vector<AreaPair>& pairs, double bin_m, double start_m) {
    if (pairs.empty()) return {};
    const BinMap bins{start_m, 1.0 / bin_m};
    const auto bin = [&](double path) { return bins.bin_floor(path); };
    double lowest = std::numeric_limits<double>::infinity(), highest = -lowest;
    for (const AreaPair& q : pairs) {
        lowest = std::min(lowest, bin(q.path));
        highest = std::max(highest, bin(q.path));
    }
    std::vector<AreaPair> per_bin(std::size_t(highest - lowest) + 1);
    for (const AreaPair& q : pairs) {
        AreaPair& b = per_bin[std::size_t(bin(q.path) - lowest)];
        if (b.weight == 0.0) b.path = q.path;
        b.weight += q.weight;
    }
    std::erase_if(per_bin, [](const AreaPair& b) { return !(b.weight > 0.0); });
    return per_bin;
}

}  // namespace tprf
