#pragma once
/// The light sources of a scene in one description, shared by every stage that needs direct light:
/// the illumination of the patches (transport/illumination.h) and the exact direct light at sensing
/// points (imaging/gather.h) evaluate the same point sources through the same function.
///
/// A point light is a point source; a laser becomes the spot it hits, which sends the light it
/// reflects on as a point whose intensity follows the spot's BRDF: Lambertian, or a glossy surface's
/// f(beam, dir) (its own patch is lit by the spot's power directly). Emissive
/// surfaces are area sources: whole polygons (an emissive rectangle however finely it is cut into
/// patches), whose first bounce is integrated from the polygon (transport/illumination.h), so that
/// its cost does not grow with the emitter's patch count.

#include "tprf/core/types.h"
#include "tprf/scene/brdf.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <vector>

namespace tprf {

struct Scene;
struct PatchSet;
class Visibility;

/// No patch.
inline constexpr std::uint32_t kNoPatch = std::numeric_limits<std::uint32_t>::max();

/// A point that sends light in all directions of a hemisphere or sphere.
struct PointSource {
    Vec3 position = Vec3::Zero();   ///< where shadow rays end, metres (a laser spot: lifted off its surface)
    Vec3 origin = Vec3::Zero();     ///< the true point, metres (for the earliest-arrival bound)
    double path = 0.0;              ///< optical path travelled before light leaves it, metres
    /// Isotropic (lobe zero): the radiant intensity, W/sr per channel. With a lobe: the power it sends,
    /// W per channel, so that the intensity towards dir is intensity * max(0, lobe . dir) / pi. A glossy
    /// one (a laser spot on a glossy surface): the power arriving, so that the intensity towards dir is
    /// intensity * f(incoming, dir) * max(0, lobe . dir).
    Rgb intensity = Rgb::Zero();
    Vec3 lobe = Vec3::Zero();       ///< zero: isotropic; else the unit normal of a Lambertian lobe
    /// An isotropic source's cone (a spot light): zero for none, else the unit axis; its intensity is
    /// scaled by spot_profile() of the angle to it.
    Vec3 spot_axis = Vec3::Zero();
    double spot_half_angle = 0.0;   ///< radians of full intensity about spot_axis
    double spot_falloff = 0.0;      ///< radians more over which it falls to 0 (smoothstep)
    bool glossy = false;            ///< a glossy spot: `brdf` (about `lobe`) says what leaves
    GlossyBrdf brdf;                ///< a glossy spot's reflectance
    Vec3 incoming = Vec3::Zero();   ///< a glossy spot: the unit direction the light came from (back along the beam)
    std::uint32_t patch = kNoPatch; ///< the patch it lies on, which it does not light
    std::uint8_t order = 1;         ///< bounce order of the light it delivers (1: point light, 2: laser spot)
    /// -1: a real source. Else the mirror image of one through Visibility::chains()[chain]: position,
    /// origin and lobe are the images, and its light reaches x only along that chain (Visibility::unfolded).
    std::int32_t chain = -1;

    /// Radiant intensity towards the unit direction `dir`, W/sr.
    Rgb intensity_towards(const Vec3& dir) const;
    /// A spot's share of its intensity towards the unit direction `dir`: 1 within spot_half_angle of
    /// spot_axis, 0 beyond spot_half_angle + spot_falloff, a smoothstep in the angle between (1
    /// everywhere without a spot_axis).
    double spot_profile(const Vec3& dir) const;
    /// The power it sends over all directions, W per channel (a glossy spot: the arriving power times
    /// the BRDF's directional albedo along the beam).
    Rgb power_sent() const;
};

/// The hit point of a laser, if it hits a front side.
struct LaserSpot {
    bool hit = false;
    std::uint32_t patch = 0;
    Vec3 point = Vec3::Zero();  ///< metres
    double path = 0.0;          ///< |origin - point|, metres
    Rgb power = Rgb::Zero();    ///< the laser's power, W per channel
    /// The unit direction back along the beam's last piece (through mirrors, the turned beam), for a
    /// glossy spot's BRDF; zero where it is not known (a capture's laser point: its spot is Lambertian).
    Vec3 incoming = Vec3::Zero();
};

/// A convex planar polygon that sends radiance L_e from its front: an emissive rectangle (each side of
/// a two-sided one), or one emissive patch of any other object (a mesh's).
struct AreaSource {
    std::array<Vec3, 4> corners{};   ///< counter-clockwise about `normal`, metres
    std::uint8_t count = 0;          ///< corners used: 3 or 4 (a quad is a parallelogram)
    Vec3 normal = Vec3::UnitZ();     ///< unit front normal
    Vec3 centroid = Vec3::Zero();    ///< metres
    Rgb radiance = Rgb::Zero();      ///< L_e, W/(m^2 sr)
    std::uint32_t object = 0;        ///< index into Scene::objects
    std::int32_t chain = -1;         ///< -1: real; else a mirror image through Visibility::chains()[chain]

    const Vec3* polygon() const { return corners.data(); }
    /// The point at (u, v) in the unit square, uniform in area (polygon_point).
    Vec3 point(double u, double v) const;
};

/// Every source of a scene.
struct LightSources {
    /// Point lights (scene order), then the lasers' spots, then their mirror images (add_images)
    std::vector<PointSource> points;
    /// Where each laser landed: in scene order, one per laser when no mirror or glass is hit (hit or
    /// not), else one per surface its beam reaches through them
    std::vector<LaserSpot> spots;
    std::vector<AreaSource> areas;       ///< the emissive patches as whole polygons (area_sources), then images
};

/// Appends to `sources` the mirror image of every real point and area source through every chain of
/// `visibility` whose last plane has the source on its reflecting side.
void add_images(LightSources& sources, const Visibility& visibility);

/// Appends to `out` the mirror images of the real point source `s` (add_images' rule): position,
/// origin and lobe reflected, its own patch no longer excluded (it may see itself in a mirror).
void point_images(const PointSource& s, const Visibility& visibility, std::vector<PointSource>& out);

/// The emissive patches of `patches` as area sources: the patches of an emissive rectangle of `scene`
/// (per side) become that rectangle; every other emissive patch is a source of its own. Without a
/// scene (nullptr), every emissive patch is its own source.
std::vector<AreaSource> area_sources(const Scene* scene, const PatchSet& patches);

/// Where a laser's ray first meets the scene (a back side absorbs: hit stays false).
LaserSpot find_laser_spot(const Vec3& origin, const Vec3& direction, const Visibility& visibility);

/// Every diffuse front side a laser's beam reaches, through mirrors and glass (Visibility::trace), with
/// `power` times the specular weight of the way; one spot (hit or not) when the scene has no mirror
/// or glass in the beam's way, as find_laser_spot finds it.
std::vector<LaserSpot> trace_laser(const Vec3& origin, const Vec3& direction, const Rgb& power,
                                   const PatchSet& patches, const Visibility& visibility);

/// The spot as a point source, its light leaving at spot.path (a laser's spot, or a capture's laser
/// point on the wall): on a glossy patch with spot.incoming known, radiant intensity
/// P f(incoming, dir) cos(theta) (the patch's BRDF); else Lambertian, albedo P cos(theta) / pi about its
/// patch's normal.
PointSource spot_source(const LaserSpot& spot, const PatchSet& patches, const Visibility& visibility);

/// Collects the scene's sources over its patches (lasers traced to their spots).
LightSources light_sources(const Scene& scene, const PatchSet& patches, const Visibility& visibility);

/// Direct light of a point source at a surface point, before the surface's albedo.
struct PointArrival {
    double path = 0.0;              ///< the source's path plus the straight leg to the point, metres
    Rgb intensity = Rgb::Zero();    ///< W/sr towards the point
    double cos_over_r2 = 0.0;       ///< cos(theta at the point) / r^2, m^-2

    /// The exitance the point reflects (albedo times irradiance), W/m^2 per channel.
    Rgb reflected(const Rgb& albedo) const { return albedo * intensity * cos_over_r2; }
};

/// Light of `source` reaching the point x with unit normal n on its front side, with a shadow ray from
/// x (lifted along n) to the source. False when x is behind, unlit, or in shadow.
bool arrive(const PointSource& source, const Vec3& x, const Vec3& n, const Visibility& visibility,
            PointArrival& out);

/// One unblocked point pair between a surface point x and an area source: its path |y - x| and its
/// weight, the kernel cos cos / r^2 times its cell's share of the source.
struct AreaPair {
    double path = 0.0;
    double weight = 0.0;
};

/// A surface point's cell, when the point stands for one (a pixel sample's share of its pixel): the
/// points point + s du + t dv, s and t in [-1, 1], each seen along a straight leg from one (virtual)
/// sensor, `leg` metres long at the point and changing by leg_du and leg_dv along the half-axes. Zero
/// half-axes: a point.
struct Footprint {
    Vec3 du = Vec3::Zero(), dv = Vec3::Zero();
    double leg = 0.0, leg_du = 0.0, leg_dv = 0.0;

    bool empty() const { return du.isZero() && dv.isZero(); }
    /// The leg at point + s du + t dv, exactly (0 when there is no leg: unwarped).
    double leg_at(double s, double t) const {
        if (!(leg > 0.0)) return 0.0;
        const Vec3 d = s * du + t * dv;
        return std::sqrt(std::max(0.0, leg * leg + 2.0 * leg * (s * leg_du + t * leg_dv) + d.squaredNorm()));
    }
    /// The least over the cell's four corners of distance(corner) + leg_at(corner) - leg: with a convex
    /// distance, the earliest path through the cell (less the point's leg) unless it lies inside.
    template <class Distance>
    double least_at_corners(Distance&& distance) const {
        double best = std::numeric_limits<double>::infinity();
        for (const double s : {-1.0, 1.0})
            for (const double t : {-1.0, 1.0}) best = std::min(best, distance(Vec3(s * du + t * dv)) + leg_at(s, t) - leg);
        return best;
    }
};

/// Shadow rays from a surface point to an area source first, and where they disagree (the defaults of
/// IlluminationOptions and GatherOptions).
inline constexpr int kAreaShadowRays = 16;
inline constexpr int kAreaPenumbraRays = 256;

/// How an area source is sampled from one surface point: a grid of cells over the source.
struct AreaSampling {
    int timing = 4;     ///< cells per side that time the light
    int shadow = 4;     ///< cells per side that shadow rays test first
    int penumbra = 16;  ///< cells per side, a ray each, where those disagree (or `timing`, if finer)
    /// When > 0, each cell's light is spread over its paths as they change to first order along the
    /// cell's two half-axes (never before x's distance to the source), and cut at the bin edges
    /// origin + k bin_m: one pair per bin it touches. When 0, one pair at the centre's path.
    double bin_m = 0.0;
    double origin = 0.0;
    /// The surface point's own cell, when it stands for one (a pixel sample's): each pair's light is
    /// spread over the paths of both cells, the source's and the point's, to first order, and never
    /// before the earliest path at the point's cell's corners.
    Footprint footprint;
    /// Where in its cell each grid's point lies, as a fraction of the cell along u and v (0.5: the
    /// centre). The samples of one pixel take different offsets, so that together they see more points
    /// of the source than one grid has.
    double jitter_u = 0.5, jitter_v = 0.5;
    /// When set, each pair's weight is scaled by this function of the unit direction from the surface
    /// point towards the pair's cell (a glossy point's BRDF term); the total returned is not.
    std::function<double(const Vec3&)> towards;
};

/// Bins of the time axis that one timing cell of an area source spans, about: each cell's light is
/// spread over its paths to first order (a trapezoid), so a cell may span several bins.
inline constexpr double kAreaBinsPerTimingCell = 4.0;

/// The sampling of source a seen from x: timing cells whose paths span about kAreaBinsPerTimingCell
/// bins of `bin_m` (2 to 32 per side; 4 when bin_m is 0), their light cut at the bin edges `origin` +
/// k bin_m, and shadow grids of about `shadow_rays` and `penumbra_rays` cells.
AreaSampling area_sampling(const AreaSource& a, const Vec3& x, double bin_m, double origin, int shadow_rays,
                           int penumbra_rays);

/// Whether surface point x (unit normal n) and point y of area source a face each other.
inline bool faces_source(const AreaSource& a, const Vec3& x, const Vec3& n, const Vec3& y) {
    return n.dot(y - x) > 0.0 && a.normal.dot(y - x) < 0.0;
}

/// The share of light that passes between surface point x (unit normal n) and point y of area source
/// a (0: blocked), each lifted off its surface by the visibility's epsilon.
double passes_from_source(const AreaSource& a, const Visibility& visibility, const Vec3& x, const Vec3& n,
                          const Vec3& y);

/// passes_from_source() of the points y[k] of a, each seen from x[k] (unit normal n), into passed[k] (the
/// three of one size): the same answers, a real source's rays cast in packets (Visibility::transmittances).
void passes_from_source(const AreaSource& a, const Visibility& visibility, std::span<const Vec3> x, const Vec3& n,
                        std::span<const Vec3> y, std::span<double> passed);

/// Points on the rim of area source a that the shadow test probes besides its grid's cell centres: its
/// corners and the middles of its sides, each moved a thousandth of the way to the centroid. A shadow
/// edge that hides a sliver along a side (narrower than half a cell) misses every cell centre but
/// not the rim. Writes up to 8 points; returns how many.
int rim_probes(const AreaSource& a, Vec3* out);

/// The light of area source a at the point x with unit normal n: appends to `out` the pairs between x
/// and the cells' points (their centres, unless jittered) that shadow rays find unblocked (to the shadow grid's cells; where those
/// disagree, a penumbra, to every cell of the finer grid), and returns the weight of all pairs, blocked
/// or not (0 when no cell centre faces x). The rim (rim_probes) is tested with the shadow grid: when
/// its rays disagree with the grid's, it is a penumbra too. The unblocked share of the weight is the share of the
/// exact form factor point_polygon_form_factor(x, n, a) that reaches x.
double arrive_area(const AreaSource& a, const Vec3& x, const Vec3& n, const Visibility& visibility,
                   const AreaSampling& sampling, std::vector<AreaPair>& out);

/// arrive_area with every cell open (no shadow rays): for a caller that has found the source wholly
/// visible from x by rays of its own.
double arrive_area_open(const AreaSource& a, const Vec3& x, const Vec3& n, const AreaSampling& sampling,
                        std::vector<AreaPair>& out);

/// arrive_area_open with each timing cell's pairs weighted by the open share the caller found for it,
/// `open[v * sampling.timing + u]` in [0, 1] for cell (u, v) of the timing grid: for a pixel whose
/// samples shared shadow rays of their own.
double arrive_area_shaded(const AreaSource& a, const Vec3& x, const Vec3& n, const AreaSampling& sampling,
                          const std::vector<double>& open, std::vector<AreaPair>& out);

/// When no cell centre of `a` faces x, yet F > 0 (a sliver near x's horizon): one pair along the path
/// from x to a's centroid, of weight 1, if that ray is unblocked. Returns the weight added (1 or 0).
double arrive_area_centroid(const AreaSource& a, const Vec3& x, const Vec3& n, const Visibility& visibility,
                            std::vector<AreaPair>& out);

/// `pairs` summed per bin of width bin_m from start_m (one pair per bin that has any, at its first
/// pair's path, in increasing bins). Exact for every consumer, each of which places light by its bin.
std::vector<AreaPair> merge_pairs_by_bin(const std::vector<AreaPair>& pairs, double bin_m, double start_m);

/// The shortest optical path by which any light of `sources` can reach x, metres (0 without sources).
double earliest_path(const LightSources& sources, const Vec3& x);

/// Distance from x to a convex planar polygon with unit normal `normal`, metres.
double distance_to_polygon(const Vec3& x, const Vec3* poly, std::size_t count, const Vec3& normal);

}  // namespace tprf
