#pragma once
/// A scene as plain data: what a scene file (docs/scene.md) says, in SI units. No JSON here:
/// scene/parse_json.h builds a Scene from a file, scene/validate.h checks one however it was built.

#include "tprf/core/types.h"
#include "tprf/scene/sensor_settings.h"
#include "tprf/core/time_axis.h"

#include <Eigen/Geometry>

#include <filesystem>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace tprf {

/// A calibrated camera's pinhole in pixels, OpenCV's convention: x right, y down, the centre of pixel
/// (column c, row r) at (c, r); a point at normalised coordinates (x, y) lands at (fx x + cx, fy y + cy).
struct Intrinsics {
    double fx = 0.0, fy = 0.0;  ///< focal lengths, pixels, > 0
    double cx = 0.0, cy = 0.0;  ///< principal point, pixels
};

/// Brown-Conrady lens distortion as OpenCV applies it to normalised coordinates (x, y), r^2 = x^2 + y^2:
/// x' = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2), and
/// y' = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y.
struct Distortion {
    double k1 = 0.0, k2 = 0.0, k3 = 0.0, p1 = 0.0, p2 = 0.0;

    bool none() const { return k1 == 0.0 && k2 == 0.0 && k3 == 0.0 && p1 == 0.0 && p2 == 0.0; }
    /// (x', y') of the undistorted normalised point (x, y).
    Vec2 apply(const Vec2& xy) const;
    /// The Jacobian d(x', y') / d(x, y) at (x, y).
    Eigen::Matrix2d jacobian(const Vec2& xy) const;
    /// The undistorted point whose image is `distorted`, by Newton's method from it; nullopt where it
    /// does not converge to 1e-12 or lands where the map folds (a non-positive Jacobian).
    std::optional<Vec2> undo(const Vec2& distorted) const;
};

/// Pinhole camera (docs/scene.md: vertical fov in degrees, or intrinsics; row 0 at the top).
struct Camera {
    Vec3 position = Vec3::Zero();   ///< metres
    Vec3 look_at = Vec3::UnitX();   ///< metres, != position
    Vec3 up = Vec3::UnitZ();        ///< non-zero, not parallel to look_at - position
    double fov_deg = 40.0;          ///< vertical field of view, (0, 180); unused with intrinsics
    /// Set: the pinhole in pixels (it replaces fov_deg); unset: fx = fy = (height / 2) / tan(fov / 2)
    /// with the principal point at the image centre (Camera::pinhole()).
    std::optional<Intrinsics> intrinsics;
    Distortion distortion;          ///< none by default
    int width = 0;                  ///< pixels, > 0
    int height = 0;                 ///< pixels, > 0
    int spp = 1;                    ///< samples per pixel, > 0
    bool unwarp = false;            ///< leave the camera leg out of every sample's time
    /// Spread each sample's direct light over the paths of its share of the pixel (SensingPoint::du,
    /// dv): a pixel integrates its footprint in time, not spp instants. False: point samples, each
    /// sample's light at its own exact path (docs/scene.md).
    bool footprint = true;
    /// Read the second bounce (the light one link after its pulse) at each sample's own time rather
    /// than its patch centroid's (SecondBounceLight; docs/scene.md): what patch-to-patch
    /// links carry, without mirrors or glass; ignored with them.
    bool shift_second_bounce = true;
    /// The image's columns in reverse order, column 0 looking towards the right of the frame above: a
    /// Mitsuba camera whose to_world mirrors (a negative determinant, as some exporters write) sees
    /// the mirror image of what its rotation would (docs/mitsuba.md). No JSON key.
    bool mirrored = false;

    /// The intrinsics, given or made from fov_deg.
    Intrinsics pinhole() const;
};

/// A point light, isotropic or a spot: irradiance at x is intensity * profile * cos(theta) / r^2.
struct PointLight {
    Vec3 position = Vec3::Zero();   ///< metres
    Rgb intensity = Rgb::Zero();    ///< W/sr per channel, >= 0 (a spot's: inside its half angle)
    /// A spot (JSON type "spot"): full intensity within half_angle_deg of the unit axis `direction`,
    /// falling to 0 over falloff_deg more by a smoothstep, 0 beyond. False: isotropic.
    bool spot = false;
    Vec3 direction = Vec3::Zero();
    double half_angle_deg = 0.0;    ///< [0, 180)
    double falloff_deg = 0.0;       ///< >= 0, half_angle_deg + falloff_deg <= 180
};

/// Laser: deposits `power` at the first surface point it hits.
struct Laser {
    Vec3 origin = Vec3::Zero();     ///< metres
    Vec3 direction = Vec3::UnitX(); ///< unit vector, within 1e-9 (from `direction`, or normalize(target - origin))
    Rgb power = Rgb::Zero();        ///< W per channel, >= 0
};

using Light = std::variant<PointLight, Laser>;

/// A rectangle with corners origin, origin+u, origin+u+v, origin+v; front normal normalize(u x v).
struct RectangleShape {
    Vec3 origin = Vec3::Zero();
    Vec3 u = Vec3::UnitX();         ///< metres, non-zero
    Vec3 v = Vec3::UnitY();         ///< metres, non-zero, not parallel to u
};

/// A mesh file read through OpenMesh, with its transform (scale, then rotate, then translate).
struct MeshShape {
    std::filesystem::path file;                          ///< absolute, or relative to the working directory; readable
    /// Affine (last row 0 0 0 1) and not singular: maps file coordinates to metres. Messages name it as
    /// the scene file's `transform.matrix`.
    Eigen::Matrix4d transform = Eigen::Matrix4d::Identity();
};

/// What an object's surface does with light (docs/materials.md).
enum class MaterialType {
    Diffuse,  ///< Lambertian only (`albedo`)
    Mirror,   ///< perfect specular reflection of `reflectance` on the front side, plus `albedo` diffuse
    Glass,    ///< a thin sheet: `reflectance` mirrored on both sides, `transmittance` straight through
    Glossy,   ///< `albedo` Lambertian plus a GGX lobe of `roughness` with a constant Fresnel `reflectance`
    Plastic,  ///< a dielectric GGX coat of index `ior` and `roughness` over a Lambertian base of `albedo`
};

/// An object's material: its specular parts; the diffuse part is Object::albedo.
struct Material {
    MaterialType type = MaterialType::Diffuse;
    /// Specular reflectance per channel, in [0, 1] (a tinted mirror: a gold one reflects red more than
    /// blue). Zero for a diffuse object.
    Rgb reflectance = Rgb::Zero();
    /// Glass: straight-through transmittance per channel, in [0, 1], grey; else zero.
    Rgb transmittance = Rgb::Zero();
    /// Glossy and plastic: the GGX roughness alpha, in [0.01, 1].
    double roughness = 0.1;
    /// Plastic: the coat's refractive index, > 1.
    double ior = 1.5;
    /// Whether the object is a specular plane (a mirror or glass).
    bool specular() const { return type == MaterialType::Mirror || type == MaterialType::Glass; }
    /// Whether the object is glossy (a glossy or plastic material, scene/brdf.h).
    bool glossy() const { return type == MaterialType::Glossy || type == MaterialType::Plastic; }
};

/// One entry of `objects`.
struct Object {
    std::variant<RectangleShape, MeshShape> shape;
    /// Lambertian reflectance per channel, in [0, 1]; with a specular material, its diffuse part
    /// (reflectance + transmittance + albedo <= 1 per channel).
    Rgb albedo = Rgb::Constant(0.5);
    Material material;
    Rgb emission = Rgb::Zero();        ///< radiance L_e, W/(m^2 sr), from the front side, >= 0
    bool two_sided = false;
    std::string json_path;             ///< e.g. "objects[2]", for error messages; "" means objects[its index]
};

/// The optional `solver` block.
struct SolverSettings {
    int max_bounces = -1;               ///< >= 0, or -1: every bounce that arrives inside the window
    DelayMode delay = DelayMode::Linear;
    bool bounces = false;               ///< also write the per-bounce terms
    /// Most specular reflections (mirror or glass) on one leg between two diffuse points, on a camera
    /// or laser ray, or from a light (`solver.max_specular`, docs/materials.md); >= 0.
    int max_specular = 4;
};

/// How light is exchanged between patches (docs/links.md).
enum class LinkMethod {
    Flat,          ///< every facing, visible pair of patches: the reference
    Hierarchical,  ///< links between clusters of patches wherever the error stays under `tolerance`
};

/// Most pieces links.spread_pieces may ask for one patch link.
inline constexpr int kMaxSpreadPieces = 8;
/// The most rings of a glossy patch's directional cells (links.glossy_resolution).
inline constexpr int kMaxGlossyResolution = 8;
/// links.glossy_resolution "auto" (the default): glossy_rings decides.
inline constexpr int kGlossyAuto = -1;
/// "auto": the rings glossy patches get while glossy patches x patches stay within kAutoGlossyPairs (the
/// pairs whose links the cells add), and none beyond.
inline constexpr int kAutoGlossyRings = 3;
inline constexpr double kAutoGlossyPairs = 2.5e7;

/// The rings of the glossy patches' directional cells for the setting `setting` (links.glossy_resolution:
/// 0 to 8, or kGlossyAuto) in a scene of `patches` patches of which `glossy` are glossy: the setting
/// itself, or for "auto" kAutoGlossyRings while glossy x patches <= kAutoGlossyPairs, else 0. The one
/// rule of the patches (their albedo), the links and the resource estimate.
inline int glossy_rings(int setting, std::size_t glossy, std::size_t patches) {
    if (setting != kGlossyAuto) return setting;
    if (glossy == 0) return 0;
    return double(glossy) * double(patches) <= kAutoGlossyPairs ? kAutoGlossyRings : 0;
}

/// The optional `links` block.
struct LinkSettings {
    LinkMethod method = LinkMethod::Hierarchical;  ///< the default; flat is the reference (docs/links.md)
    double tolerance = 1e-3;               ///< > 0: largest accepted form-factor error of one cluster link
    /// >= 0: refine a cluster link whose form factor times its members' timing offset in bins exceeds
    /// time_bins x tolerance (HierarchyOptions::time_bins); 0: off (docs/links.md).
    double time_bins = 4.0;
    /// 0: every patch-to-patch link at its centroid delay; n in 1..8: spread over the paths from the
    /// receiver to the points of the sender, in at most n pieces (spread_patch_links)
    /// (docs/links.md).
    int spread_pieces = 0;
    /// Rings R of a glossy patch's directional cells (4 R^2 cells over its hemisphere) through which the
    /// transport passes its light on (transport/glossy_rows.h, docs/method.md); 0: glossy patches pass
    /// light on as Lambertian surfaces of their hemispherical albedo; kGlossyAuto ("auto"): glossy_rings.
    int glossy_resolution = kGlossyAuto;
};

/// A grid of points on a relay surface (docs/capture.md): point (a, b) is
/// origin + (a + 0.5) / nu * u + (b + 0.5) / nv * v, for a in [0, nu) and b in [0, nv).
struct CaptureGrid {
    Vec3 origin = Vec3::Zero();     ///< metres
    Vec3 u = Vec3::UnitX();         ///< metres, non-zero
    Vec3 v = Vec3::UnitZ();         ///< metres, non-zero, not parallel to u
    int nu = 0;                     ///< points along u, > 0
    int nv = 0;                     ///< points along v, > 0

    /// Grid point (a, b), metres.
    Vec3 point(int a, int b) const { return origin + (a + 0.5) / nu * u + (b + 0.5) / nv * v; }
    std::size_t size() const { return std::size_t(nu) * std::size_t(nv); }
};

/// How the laser and the sensor points are paired.
enum class CaptureType {
    Confocal,    ///< laser and sensor aim at the same grid point
    Exhaustive,  ///< every laser point of `laser_grid` with every sensor point of `sensor_grid`
};

/// The optional `capture` block: an NLOS scan of a relay wall (docs/capture.md).
struct Capture {
    CaptureType type = CaptureType::Confocal;
    Vec3 laser_position = Vec3::Zero();    ///< the laser device, metres; in front of the wall, in no object
    Rgb laser_power = Rgb::Ones();         ///< W per channel, >= 0
    Vec3 sensor_position = Vec3::Zero();   ///< the sensor device, metres
    /// Laser points (`grid`; for an exhaustive capture with only `sensor_grid`, that grid). Confocal:
    /// also the sensor points.
    CaptureGrid laser_grid;
    /// Sensor points (`sensor_grid`, or `grid` when it is absent); confocal: the laser grid.
    CaptureGrid sensor_grid;
    bool account_first_and_last_bounces = false;  ///< device legs in the time (false: the NLOS convention)
    int max_bounces = -1;                  ///< -1: all; >= 2 (3: laser spot -> hidden surface -> sensor point)
    /// The march of orders 4 and up (the exact orders 1 to 3 keep the scene's bins) runs on bins this
    /// many times wider, its light spread back over the scene's bins: >= 1, at most kMaxMarchBinFactor;
    /// above 1, no camera (its links would be marched on the scene's bins). docs/capture.md.
    int march_bin_factor = 1;
    static constexpr int kMaxMarchBinFactor = 64;
    /// Confocal only: the later bounces are marched at every S-th grid point along each side (and the
    /// last), and their light moved to the points between them; >= 1, at most kMaxMarchGridStep.
    /// docs/capture.md.
    int march_grid_step = 1;
    static constexpr int kMaxMarchGridStep = 64;
    std::string json_path = "capture";     ///< for error messages
    /// The keys the grids came from ("grid" or "sensor_grid"), for error messages.
    std::string laser_grid_key = "grid";
    std::string sensor_grid_key = "grid";

    /// (laser point, sensor point) pairs measured: the sensor points (confocal), or every laser point
    /// with every sensor point (exhaustive).
    std::size_t pairs() const {
        return type == CaptureType::Confocal ? sensor_grid.size() : laser_grid.size() * sensor_grid.size();
    }
};

/// A scene. Whatever builds one (a parser, a test, a binding) calls validate() (scene/validate.h)
/// before handing it to a later stage; each field's comment says what validate() requires, and every
/// number must be finite. Messages name the scene file's JSON paths: `time`, `camera`, `lights[i]`,
/// an object's json_path, `patches.max_edge`, `links.tolerance`, `solver.max_bounces`, the sensor's json_path.
struct Scene {
    std::filesystem::path file;         ///< the scene file (for messages and relative paths)
    TimeAxis time;
    std::optional<Camera> camera;
    std::vector<Light> lights;
    std::vector<Object> objects;
    double max_edge = 0.0;              ///< patches.max_edge, metres, > 0; 0 when absent (build_patches picks one)
    SolverSettings solver;
    LinkSettings links;
    std::optional<SensorSettings> sensor;  ///< the optional `sensor` block (named "sensor" when its json_path is "")
    std::optional<Capture> capture;        ///< the optional `capture` block; a scene without one needs a camera
    /// What reading the scene found to tell the user without refusing it (a -D name=value that no $name
    /// of a Mitsuba scene uses): a render and `tprf info` print each line as a warning.
    std::vector<std::string> warnings;

    /// Object i's name in messages: its json_path, or "objects[i]".
    std::string object_path(std::size_t i) const {
        const std::string& path = objects[i].json_path;
        return path.empty() ? "objects[" + std::to_string(i) + "]" : path;
    }
};

}  // namespace tprf
