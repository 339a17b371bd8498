// Glossy and plastic materials in a render: the scene keys, and the camera's direct light against the
// microfacet model written out here on its own (not through scene/brdf.h), so that a slip in the
// library's BRDF cannot hide in the test.

#include "tprf/imaging/camera.h"
#include "tprf/io/npy.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"

#include "test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace tprf {
namespace {

namespace fs = std::filesystem;

fs::path fresh_dir(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / ("tprf_glossy_" + name + "_" + std::to_string(std::random_device{}()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

// The microfacet model, as docs/materials.md states it. a: GGX alpha; c: cosines against the normal.
double ggx(double a, double c) {
    if (c <= 0.0) return 0.0;
    const double t2 = (1.0 - c * c) / (c * c);
    return a * a / (M_PI * std::pow(c, 4) * std::pow(a * a + t2, 2));
}
double masking(double a, double c) {
    if (c <= 0.0) return 0.0;
    return 2.0 / (1.0 + std::sqrt(1.0 + a * a * (1.0 - c * c) / (c * c)));
}
// Unpolarised Fresnel reflectance from air into index `eta` at incidence cosine c.
double fresnel(double c, double eta) {
    const double s2 = (1.0 - c * c) / (eta * eta);
    const double ct = std::sqrt(1.0 - s2);
    const double rs = (c - eta * ct) / (c + eta * ct), rp = (eta * c - ct) / (eta * c + ct);
    return 0.5 * (rs * rs + rp * rp);
}

struct Material {
    std::string type;  // "glossy" or "plastic"
    double albedo, reflectance, roughness, ior;
};

// f(wi, wo) for the floor's normal +z.
double brdf(const Material& m, const Vec3& wi, const Vec3& wo) {
    const double ci = wi.z(), co = wo.z();
    if (ci <= 0.0 || co <= 0.0) return 0.0;
    const Vec3 h = (wi + wo).normalized();
    const double lobe = ggx(m.roughness, h.z()) * masking(m.roughness, ci) * masking(m.roughness, co) / (4.0 * ci * co);
    if (m.type == "glossy") return m.albedo / M_PI + m.reflectance * lobe;
    return fresnel(wi.dot(h), m.ior) * lobe + (1.0 - fresnel(ci, m.ior)) * (1.0 - fresnel(co, m.ior)) * m.albedo / M_PI;
}

nlohmann::json material_json(const Material& m) {
    if (m.type == "glossy")
        return {{"type", "glossy"}, {"albedo", m.albedo}, {"reflectance", m.reflectance}, {"roughness", m.roughness}};
    return {{"type", "plastic"}, {"albedo", m.albedo}, {"roughness", m.roughness}, {"ior", m.ior}};
}

// A scene rendered into a fresh folder: the folder (removed by the caller) and the scene's camera.
struct Rendered {
    fs::path dir;
    Camera camera;
    NpyArray read(const std::string& name) const { return read_npy(dir / "out" / name); }
};

Rendered render_json(const nlohmann::json& j, const std::string& name) {
    const fs::path dir = fresh_dir(name);
    const fs::path file = dir / "scene.json";
    std::ofstream(file) << j.dump(2);
    RenderOptions options;
    options.output = dir / "out";
    render_file(file, options);
    return {dir, *load_scene(file).camera};
}

// A 4 x 4 m glossy floor at z = 0 under a point light, seen obliquely so that the highlight is in the
// image; one sample at each pixel's centre, no footprint: every pixel is one exact surface point.
constexpr int kSide = 32, kBins = 500;
constexpr double kBin = 0.01;
const Vec3 kLight(0.4, 0.1, 0.7);
constexpr double kIntensity = 2.0;

nlohmann::json floor_scene(const Material& m) {
    return {{"time", {{"bins", kBins}, {"bin_width", kBin}}},
            {"camera", {{"position", {-0.6, 0.0, 0.9}}, {"look_at", {0.3, 0.0, 0.0}}, {"up", {0, 0, 1}}, {"fov", 60},
                        {"width", kSide}, {"height", kSide}, {"spp", 1}, {"footprint", false}}},
            {"lights", {{{"type", "point"}, {"position", {kLight.x(), kLight.y(), kLight.z()}}, {"intensity", kIntensity}}}},
            {"objects", {{{"type", "rectangle"}, {"origin", {-2, -2, 0}}, {"u", {4, 0, 0}}, {"v", {0, 4, 0}},
                          {"material", material_json(m)}}}},
            {"patches", {{"max_edge", 0.25}}},
            // Direct light, what these tests check, is exact with or without directional cells; the cells'
            // own tests are tests/glossy_transport_test.cpp's.
            {"links", {{"glossy_resolution", 0}}}};
}

// Every pixel's steady value is f(wi, wo) I cos_i / r^2 (p99 of the relative error within 0.5%), and its
// first light is in the bin of its path, light -> point -> camera.
void expect_exact_direct_light(const Material& m) {
    const Rendered out = render_json(floor_scene(m), m.type);
    const NpyArray steady = out.read("steady.npy");
    const NpyArray cube = out.read("transient.npy");
    ASSERT_EQ(cube.shape, (std::vector<std::size_t>{kSide, kSide, kBins, 3}));
    const Camera& camera = out.camera;
    std::vector<double> errors;
    double brightest = 0.0, dimmest = 1e300;
    for (int r = 0; r < kSide; ++r)
        for (int c = 0; c < kSide; ++c) {
            const Vec3 d = camera_ray(camera, c + 0.5, r + 0.5);
            ASSERT_LT(d.z(), 0.0);
            const Vec3 x = camera.position + d * (-camera.position.z() / d.z());
            const std::size_t px = std::size_t(r) * kSide + std::size_t(c);
            if (std::abs(x.x()) > 2.0 || std::abs(x.y()) > 2.0) {  // past the floor's far edge: nothing
                EXPECT_EQ(steady.data[px * 3], 0.0f) << "pixel " << r << "," << c;
                continue;
            }
            const Vec3 to_light = kLight - x;
            const Vec3 wi = to_light.normalized(), wo = -d;
            const double expected = brdf(m, wi, wo) * kIntensity * wi.z() / to_light.squaredNorm();
            const double got = steady.data[px * 3];
            errors.push_back(std::abs(got - expected) / expected);
            brightest = std::max(brightest, expected);
            dimmest = std::min(dimmest, expected);
            const double path = to_light.norm() + (x - camera.position).norm();
            const double edge = path / kBin - std::floor(path / kBin);
            if (edge < 1e-3 || edge > 1.0 - 1e-3) continue;  // a path on a bin's edge: either bin is right
            int first = -1;
            for (int t = 0; t < kBins && first < 0; ++t)
                if (cube.data[(px * kBins + std::size_t(t)) * 3] != 0.0f) first = t;
            EXPECT_EQ(first, int(std::floor(path / kBin))) << m.type << " roughness " << m.roughness << " pixel " << r
                                                            << "," << c;
        }
    ASSERT_GT(errors.size(), std::size_t(kSide * kSide / 2));
    std::sort(errors.begin(), errors.end());
    const double p99 = errors[errors.size() * 99 / 100];
    EXPECT_LT(p99, 0.005) << m.type << " roughness " << m.roughness << ": median " << errors[errors.size() / 2];
    // The highlight is in the image: the lobe, not the Lambertian part, sets the brightest pixels.
    EXPECT_GT(brightest, 3.0 * dimmest) << m.type << " roughness " << m.roughness;
    fs::remove_all(out.dir);
}

TEST(Glossy, PointLightOverAGlossyFloorIsTheClosedFormAtEveryPixel) {
    for (const double roughness : {0.05, 0.2, 0.5}) expect_exact_direct_light({"glossy", 0.2, 0.7, roughness, 1.5});
}

TEST(Glossy, PointLightOverAPlasticFloorIsTheClosedFormAtEveryPixel) {
    for (const double roughness : {0.05, 0.2, 0.5}) expect_exact_direct_light({"plastic", 0.6, 0.0, roughness, 1.5});
}

// A glossy or plastic floor at z = 0 and a diffuse wall (albedo kWallAlbedo) at x = 0, 4 m wide, lit by
// a laser of kLaserPower from `origin` through `target`, seen from (2.5, 0, 1.2) looking at `look_at`
// (one sample at each pixel's centre, no footprint): the second bounce (transient_bounce_2.npy), paths up
// to 8 m.
constexpr double kLaserPower = 3.0, kWallAlbedo = 0.8;
constexpr int kLaserBins = 800;

struct LaserScene {
    Vec3 origin, target, look_at;
    std::string name;
};

struct LaserRender {
    Rendered out;
    NpyArray cube;
};

LaserRender render_laser_scene(const Material& m, const LaserScene& s) {
    nlohmann::json j = floor_scene(m);
    j["objects"] = {{{"type", "rectangle"}, {"origin", {0, -2, 0}}, {"u", {4, 0, 0}}, {"v", {0, 4, 0}},
                     {"material", material_json(m)}},
                    {{"type", "rectangle"}, {"origin", {0, -2, 0}}, {"u", {0, 4, 0}}, {"v", {0, 0, 2}},
                     {"albedo", kWallAlbedo}}};
    j["lights"] = {{{"type", "laser"}, {"origin", {s.origin.x(), s.origin.y(), s.origin.z()}},
                    {"target", {s.target.x(), s.target.y(), s.target.z()}}, {"power", kLaserPower}}};
    j["camera"] = {{"position", {2.5, 0.0, 1.2}}, {"look_at", {s.look_at.x(), s.look_at.y(), s.look_at.z()}},
                   {"up", {0, 0, 1}}, {"fov", 50}, {"width", kSide}, {"height", kSide}, {"spp", 1}, {"footprint", false}};
    j["solver"] = {{"bounces", true}, {"max_bounces", 2}};
    j["time"]["bins"] = kLaserBins;
    LaserRender r{render_json(j, s.name + "_" + m.type), {}};
    r.cube = r.out.read("transient_bounce_2.npy");
    EXPECT_EQ(r.cube.shape, (std::vector<std::size_t>{kSide, kSide, kLaserBins, 3}));
    return r;
}

// Pixel px's light summed over time, and (unless its path lies within 0.1% of a bin's edge, where either
// bin is right) that its first light is in the bin of `path`.
double expect_pixel(const NpyArray& cube, std::size_t px, double path, const std::string& what) {
    double got = 0.0;
    int first = -1;
    for (int t = 0; t < kLaserBins; ++t) {
        const float v = cube.data[(px * kLaserBins + std::size_t(t)) * 3];
        got += v;
        if (first < 0 && v != 0.0f) first = t;
    }
    const double edge = path / kBin - std::floor(path / kBin);
    if (edge > 1e-3 && edge < 1.0 - 1e-3) {
        EXPECT_EQ(first, int(std::floor(path / kBin))) << what;
    }
    return got;
}

// A laser spot on a diffuse wall, seen in a glossy floor: the spot is a Lambertian point source of
// radiant intensity a P cos(theta) / pi, so the floor's second bounce at each pixel is f(wi, wo) times
// that intensity, cos_i / r^2, to 1%, with its first light in the bin of the path laser -> spot -> floor
// point -> camera.
TEST(Glossy, ALaserSpotSeenInAGlossyFloorIsTheClosedForm) {
    const LaserScene scene{{2.0, 0.0, 1.0}, {0.0, 0.3, 0.6}, {0.6, 0.15, 0.0}, "laser"};
    const Vec3& spot = scene.target;
    for (const Material& m : {Material{"glossy", 0.1, 0.8, 0.1, 1.5}, Material{"plastic", 0.5, 0.0, 0.3, 1.5}}) {
        const LaserRender r = render_laser_scene(m, scene);
        const Camera& camera = r.out.camera;
        std::vector<double> errors;
        for (int row = 0; row < kSide; ++row)
            for (int c = 0; c < kSide; ++c) {
                const Vec3 d = camera_ray(camera, c + 0.5, row + 0.5);
                if (d.z() >= 0.0) continue;
                const Vec3 x = camera.position + d * (-camera.position.z() / d.z());
                if (x.x() < 0.02 || x.x() > 4.0 || std::abs(x.y()) > 2.0) continue;  // the floor, clear of the wall
                const Vec3 to_spot = spot - x;
                const Vec3 wi = to_spot.normalized();
                const double cos_spot = -wi.x();  // the wall's normal is +x
                const double intensity = kWallAlbedo * kLaserPower * cos_spot / M_PI;
                const double expected = brdf(m, wi, -d) * intensity * wi.z() / to_spot.squaredNorm();
                const double path = (spot - scene.origin).norm() + to_spot.norm() + (x - camera.position).norm();
                const double got = expect_pixel(r.cube, std::size_t(row) * kSide + std::size_t(c), path,
                                                m.type + " pixel " + std::to_string(row) + "," + std::to_string(c));
                errors.push_back(std::abs(got - expected) / expected);
            }
        ASSERT_GT(errors.size(), std::size_t(kSide * kSide / 3));
        std::sort(errors.begin(), errors.end());
        EXPECT_LT(errors.back(), 0.01) << m.type << ": median " << errors[errors.size() / 2];
        fs::remove_all(r.out.dir);
    }
}

// A laser spot on a glossy or plastic floor lights a diffuse wall through the floor's BRDF: the spot is a
// point source of radiant intensity P f(wi, wo) cos_o (wi back along the beam, wo towards the wall point),
// so each wall pixel's second bounce is wall_albedo / pi times that intensity, cos_wall / r^2, to 1%, with
// its first light in the bin of laser -> spot -> wall point -> camera. (As a Lambertian spot of the
// floor's albedo, the wall's highlight about the beam's mirror direction is missing.)
TEST(Glossy, ALaserSpotOnAGlossyFloorLightsAWallThroughItsBrdf) {
    const LaserScene scene{{2.0, 0.0, 1.0}, {0.6, 0.1, 0.0}, {0.0, 0.1, 0.6}, "laser_on"};
    const Vec3& spot = scene.target;
    const Vec3 wi = (scene.origin - spot).normalized();
    for (const Material& m : {Material{"glossy", 0.1, 0.8, 0.2, 1.5}, Material{"plastic", 0.5, 0.0, 0.3, 1.5}}) {
        const LaserRender r = render_laser_scene(m, scene);
        const Camera& camera = r.out.camera;
        std::vector<double> errors;
        double brightest = 0.0, dimmest = 1e300;
        for (int row = 0; row < kSide; ++row)
            for (int c = 0; c < kSide; ++c) {
                const Vec3 d = camera_ray(camera, c + 0.5, row + 0.5);
                if (d.x() >= 0.0) continue;
                const Vec3 x = camera.position + d * (-camera.position.x() / d.x());
                if (x.z() < 0.02 || x.z() > 2.0 || std::abs(x.y()) > 2.0) continue;  // the wall, clear of the floor
                const Vec3 to_wall = x - spot;
                const Vec3 wo = to_wall.normalized();
                const double intensity = kLaserPower * brdf(m, wi, wo) * wo.z();
                const double expected = kWallAlbedo / M_PI * intensity * (-wo.x()) / to_wall.squaredNorm();
                const double path = (spot - scene.origin).norm() + to_wall.norm() + (x - camera.position).norm();
                const double got = expect_pixel(r.cube, std::size_t(row) * kSide + std::size_t(c), path,
                                                m.type + " pixel " + std::to_string(row) + "," + std::to_string(c));
                errors.push_back(std::abs(got - expected) / expected);
                brightest = std::max(brightest, expected);
                dimmest = std::min(dimmest, expected);
            }
        ASSERT_GT(errors.size(), std::size_t(kSide * kSide / 3));
        std::sort(errors.begin(), errors.end());
        MEASURED("laser spot on a %s floor: wall pixels' relative error median %.2g, largest %.2g\n", m.type.c_str(),
                 errors[errors.size() / 2], errors.back());
        EXPECT_LT(errors.back(), 0.01) << m.type << ": median " << errors[errors.size() / 2];
        // The lobe is in view: the wall's highlight, not the Lambertian part, sets its brightest pixels.
        EXPECT_GT(brightest, 3.0 * dimmest) << m.type;
        fs::remove_all(r.out.dir);
    }
}

// A glossy floor under a uniformly emitting rectangle, seen at the emitter's reflection: each pixel's
// first bounce (transient_bounce_1.npy) against the integral over the emitter of f L_e cos cos / r^2,
// taken here on a fine grid with every point's path binned: steady within 1% median, the profiles
// within 3% median (L1 over time, rebinned by 4).
void expect_emitter_reflection(const Material& m) {
    const Vec3 corner(0.3, -0.15, 1.0), u(0.0, 0.3, 0.0), v(0.5, 0.0, 0.0);  // u x v points down
    const double radiance = 4.0;
    constexpr int side = 24, bins = 600;
    nlohmann::json j = floor_scene(m);
    j["objects"].push_back({{"type", "rectangle"}, {"origin", {corner.x(), corner.y(), corner.z()}},
                            {"u", {u.x(), u.y(), u.z()}}, {"v", {v.x(), v.y(), v.z()}}, {"albedo", 0.0},
                            {"emission", radiance}});
    j["lights"] = nlohmann::json::array();
    j["camera"] = {{"position", {-0.8, 0.0, 0.7}}, {"look_at", {0.2, 0.0, 0.0}}, {"up", {0, 0, 1}}, {"fov", 50},
                   {"width", side}, {"height", side}, {"spp", 1}, {"footprint", false}};
    j["time"]["bins"] = bins;
    j["solver"] = {{"bounces", true}, {"max_bounces", 1}};
    const Rendered out = render_json(j, "emitter_" + m.type);
    const NpyArray cube = out.read("transient_bounce_1.npy");
    ASSERT_EQ(cube.shape, (std::vector<std::size_t>{side, side, bins, 3}));
    const Camera& camera = out.camera;
    const Vec3 down = u.cross(v).normalized();
    constexpr int grid = 300;
    const double cell_area = u.cross(v).norm() / (grid * grid);
    std::vector<double> steady_errors, profile_errors;
    double brightest = 0.0, dimmest = 1e300;
    for (int r = 0; r < side; ++r)
        for (int c = 0; c < side; ++c) {
            const Vec3 d = camera_ray(camera, c + 0.5, r + 0.5);
            if (d.z() >= 0.0) continue;
            const Vec3 x = camera.position + d * (-camera.position.z() / d.z());
            if (std::abs(x.x()) > 2.0 || std::abs(x.y()) > 2.0) continue;
            const double leg = (x - camera.position).norm();
            std::vector<double> reference(bins / 4, 0.0);
            double expected = 0.0;
            for (int a = 0; a < grid; ++a)
                for (int b = 0; b < grid; ++b) {
                    const Vec3 y = corner + u * ((a + 0.5) / grid) + v * ((b + 0.5) / grid);
                    const Vec3 to = y - x;
                    const double r2 = to.squaredNorm(), dist = std::sqrt(r2);
                    const Vec3 wi = to / dist;
                    const double cos_y = -down.dot(wi);
                    if (cos_y <= 0.0 || wi.z() <= 0.0) continue;
                    const double light = brdf(m, wi, -d) * radiance * wi.z() * cos_y / r2 * cell_area;
                    expected += light;
                    const int t = int(std::floor((dist + leg) / kBin));
                    if (t < bins) reference[std::size_t(t / 4)] += light;
                }
            const std::size_t px = std::size_t(r) * side + std::size_t(c);
            std::vector<double> got(bins / 4, 0.0);
            double total = 0.0;
            for (int t = 0; t < bins; ++t) {
                got[std::size_t(t / 4)] += cube.data[(px * bins + std::size_t(t)) * 3];
                total += cube.data[(px * bins + std::size_t(t)) * 3];
            }
            double l1 = 0.0;
            for (std::size_t k = 0; k < got.size(); ++k) l1 += std::abs(got[k] - reference[k]);
            steady_errors.push_back(std::abs(total - expected) / expected);
            profile_errors.push_back(l1 / expected);
            brightest = std::max(brightest, expected);
            dimmest = std::min(dimmest, expected);
        }
    ASSERT_GT(steady_errors.size(), std::size_t(side * side / 2));
    std::sort(steady_errors.begin(), steady_errors.end());
    std::sort(profile_errors.begin(), profile_errors.end());
    const std::size_t mid = steady_errors.size() / 2;
    EXPECT_LT(steady_errors[mid], 0.01) << m.type << " roughness " << m.roughness << ": p90 " << steady_errors[mid * 9 / 5];
    EXPECT_LT(profile_errors[mid], 0.03) << m.type << " roughness " << m.roughness << ": p90 " << profile_errors[mid * 9 / 5];
    EXPECT_GT(brightest, 3.0 * dimmest) << m.type << " roughness " << m.roughness << ": the reflection is in view";
    fs::remove_all(out.dir);
}

TEST(Glossy, AGlossyFloorReflectsAnEmitterAsItsIntegralSays) {
    for (const double roughness : {0.05, 0.2, 0.5}) expect_emitter_reflection({"glossy", 0.1, 0.8, roughness, 1.5});
    expect_emitter_reflection({"plastic", 0.5, 0.0, 0.1, 1.5});
}

// Bad values exit 2 naming the JSON path (load_scene throws InputError with it).
void expect_refused(const nlohmann::json& material, const std::string& path, const std::string& what = "") {
    nlohmann::json j = floor_scene({"glossy", 0.2, 0.7, 0.2, 1.5});
    j["objects"][0]["material"] = material;
    const fs::path dir = fresh_dir("bad");
    const fs::path file = dir / "scene.json";
    std::ofstream(file) << j.dump(2);
    try {
        load_scene(file);
        ADD_FAILURE() << material.dump() << " was accepted";
    } catch (const std::exception& e) {
        EXPECT_NE(std::string(e.what()).find(path + ":"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
    fs::remove_all(dir);
}

TEST(Glossy, BadValuesNameTheirJsonPath) {
    expect_refused({{"type", "glossy"}, {"reflectance", 0.7}, {"roughness", 0.001}}, "objects[0].material.roughness");
    expect_refused({{"type", "glossy"}, {"reflectance", 0.7}, {"roughness", 1.5}}, "objects[0].material.roughness");
    expect_refused({{"type", "glossy"}, {"reflectance", 0.7}, {"albedo", 0.5}}, "objects[0].material", "at most 1");
    expect_refused({{"type", "glossy"}, {"reflectance", {0.5, 1.2, 0.5}}}, "objects[0].material.reflectance");
    expect_refused({{"type", "glossy"}}, "objects[0].material", "reflectance");
    expect_refused({{"type", "plastic"}, {"ior", 1.0}}, "objects[0].material.ior");
    expect_refused({{"type", "plastic"}, {"reflectance", 0.5}}, "objects[0].material.reflectance", "unknown key");
    expect_refused({{"type", "satin"}}, "objects[0].material.type");
}

}  // namespace
}  // namespace tprf
