// Glossy patches in the transport (links.glossy_resolution, transport/glossy_rows.h): answers fixed in
// advance: a wall's light reflected by a metal floor against the integral over the wall written here;
// and the method's own invariants. A lobe of reflectance 0 leaves a Lambertian surface of the same
// albedo (in a camera's render and in a capture); the time integral of the cube is the steady solve; the
// bounce cubes add up to the cube; flat and hierarchical links give the same light.

#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/imaging/camera.h"
#include "tprf/pipeline/info.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/brdf.h"
#include "tprf/scene/parse_json.h"
#include "tprf/transport/glossy_rows.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/light_sources.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/steady.h"

#include "test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>
#include <vector>

namespace {

using nlohmann::json;

// A floor and a back wall lit by a point light, the camera looking at the floor.
json corner(const json& floor_material, double floor_albedo, int rings, const std::string& method = "hierarchical") {
    json floor = {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", floor_albedo}};
    if (!floor_material.is_null()) floor["material"] = floor_material;
    return {{"time", {{"bins", 1600}, {"bin_width", 0.005}, {"start", 0.0}, {"unit", "m"}}},
            {"camera",
             {{"position", {0.5, -1.1, 0.9}}, {"look_at", {0.5, 0.55, 0.25}}, {"up", {0, 0, 1}}, {"fov", 45},
              {"width", 32}, {"height", 24}, {"spp", 4}, {"shift_second_bounce", false}}},
            {"lights", {{{"type", "point"}, {"position", {0.3, 0.45, 0.35}}, {"intensity", 1.0}}}},
            {"objects",
             {floor, {{"type", "rectangle"}, {"origin", {0, 1, 0}}, {"u", {1, 0, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.6}}}},
            {"patches", {{"max_edge", 0.1}}},
            {"links", {{"method", method}, {"glossy_resolution", rings}}}};
}

const tprf::FloatArray& array(const tprf::RenderResult& r, const std::string& name) {
    const auto it = r.arrays.find(name);
    if (it == r.arrays.end()) throw std::runtime_error("no array " + name);
    return it->second;
}

tprf::RenderResult render(const json& scene, bool patch_profiles = false) {
    tprf::RenderOptions options;
    options.patch_profiles = patch_profiles;
    return tprf::render_scene(tprf::parse_scene(scene.dump(), "glossy_transport_test.json"), options);
}

double total(const tprf::FloatArray& a) { return std::accumulate(a.data.begin(), a.data.end(), 0.0); }

double largest_difference(const tprf::FloatArray& a, const tprf::FloatArray& b) {
    EXPECT_EQ(a.shape, b.shape);
    double d = 0.0;
    for (std::size_t k = 0; k < a.data.size(); ++k) d = std::max(d, double(std::abs(a.data[k] - b.data[k])));
    return d;
}

double peak(const tprf::FloatArray& a) {
    double p = 0.0;
    for (float v : a.data) p = std::max(p, double(v));
    return p;
}

json metal(double reflectance, double roughness) {
    return {{"type", "glossy"}, {"reflectance", reflectance}, {"roughness", roughness}};
}

TEST(GlossyTransport, ALobeOfReflectanceZeroIsTheLambertianSurfaceOfItsAlbedo) {
    const auto lambertian = render(corner(nullptr, 0.5, 0));
    const auto glossy = render(corner({{"type", "glossy"}, {"reflectance", 0.0}, {"roughness", 0.3}}, 0.5, 4));
    // Direct light to the camera is the BRDF's either way; what is passed on is albedo / pi alone.
    EXPECT_LT(largest_difference(array(lambertian, "transient"), array(glossy, "transient")),
              1e-5 * peak(array(lambertian, "transient")));
    EXPECT_NEAR(total(array(glossy, "steady")), total(array(lambertian, "steady")), 1e-5 * total(array(lambertian, "steady")));
}

TEST(GlossyTransport, TheCubesTimeIntegralIsTheSteadySolveAndFlatLinksAgree) {
    const json scene = corner(metal(0.8, 0.2), 0.1, 4);
    const auto r = render(scene);
    const tprf::FloatArray& cube = array(r, "transient");
    const tprf::FloatArray& steady = array(r, "steady");
    const std::size_t bins = cube.shape[2];
    double sum_cube = 0.0, sum_steady = 0.0;
    for (std::size_t p = 0; p < steady.data.size() / 3; ++p)
        for (int c = 0; c < 3; ++c) {
            double s = 0.0;
            for (std::size_t t = 0; t < bins; ++t) s += cube.data[(p * bins + t) * 3 + std::size_t(c)];
            sum_cube += s;
            sum_steady += steady.data[p * 3 + std::size_t(c)];
        }
    // 8 m of window holds all but a few parts in 10^4 of the light in this open corner.
    EXPECT_NEAR(sum_cube, sum_steady, 2e-3 * sum_steady);
    const auto flat = render(corner(metal(0.8, 0.2), 0.1, 4, "flat"));
    EXPECT_NEAR(total(array(flat, "steady")), total(steady), 2e-3 * total(steady));
}

TEST(GlossyTransport, BounceCubesAddUpToTheCube) {
    json scene = corner(metal(0.8, 0.2), 0.1, 4);
    scene["solver"] = {{"max_bounces", 4}, {"bounces", true}};
    const auto r = render(scene);
    const tprf::FloatArray& cube = array(r, "transient");
    std::vector<double> sum(cube.data.size(), 0.0);
    double second = 0.0;
    for (int k = 0; k <= 4; ++k) {
        const tprf::FloatArray& b = array(r, "transient_bounce_" + std::to_string(k));
        for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += b.data[i];
        if (k == 2) second = total(b);
    }
    double worst = 0.0;
    for (std::size_t i = 0; i < sum.size(); ++i) worst = std::max(worst, std::abs(sum[i] - double(cube.data[i])));
    EXPECT_LT(worst, 1e-5 * peak(cube));
    // The floor's lobe passes the wall's light on: the second order is there, and it is light that a
    // lobe of reflectance 0 would not bring (the floor's albedo is 0.1).
    EXPECT_GT(second, 0.0);
}

// The GGX lobe as docs/materials.md states it, written out here on its own (normal +z).
double lobe(double a, const tprf::Vec3& wi, const tprf::Vec3& wo) {
    const double ci = wi.z(), co = wo.z();
    if (ci <= 0.0 || co <= 0.0) return 0.0;
    const tprf::Vec3 h = (wi + wo).normalized();
    const double ch = h.z(), t2 = (1.0 - ch * ch) / (ch * ch);
    const double d = a * a / (M_PI * std::pow(ch, 4) * std::pow(a * a + t2, 2));
    auto g1 = [&](double c) { return 2.0 / (1.0 + std::sqrt(1.0 + a * a * (1.0 - c * c) / (c * c))); };
    return d * g1(ci) * g1(co) / (4.0 * ci * co);
}

// A metal floor (albedo 0, reflectance 0.8) at z = 0 and a diffuse wall (albedo 0.8) at y = 1 that a
// point light lights; the camera looks down at the floor, the wall reflected in it. Light that reaches
// a floor pixel in two bounces went light -> wall -> floor -> camera: its radiance is the integral over
// the wall of 0.8 lobe(wi, wo) L_wall(y) cos_x cos_y / r^2, L_wall(y) = 0.8 / pi I cos / d^2.
struct WallInFloor {
    double roughness;
    int rings;
    double max_edge = 0.05;
};
const tprf::Vec3 kWallLight(0.0, 0.2, 1.2);

json wall_in_floor(const WallInFloor& w) {
    return {{"time", {{"bins", 700}, {"bin_width", 0.01}, {"start", 0.0}, {"unit", "m"}}},
            {"camera",
             {{"position", {0.0, -1.6, 0.9}}, {"look_at", {0.0, 0.2, 0.0}}, {"up", {0, 0, 1}}, {"fov", 50},
              {"width", 24}, {"height", 24}, {"spp", 1}, {"footprint", false}, {"shift_second_bounce", false}}},
            {"lights", {{{"type", "point"}, {"position", {kWallLight.x(), kWallLight.y(), kWallLight.z()}}, {"intensity", 1.0}}}},
            {"objects",
             {{{"type", "rectangle"}, {"origin", {-1, -1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 2, 0}}, {"albedo", 0.0},
               {"material", {{"type", "glossy"}, {"reflectance", 0.8}, {"roughness", w.roughness}}}},
              {{"type", "rectangle"}, {"origin", {-1, 1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.8}}}},
            {"patches", {{"max_edge", w.max_edge}}},
            {"links", {{"glossy_resolution", w.rings}}},
            {"solver", {{"max_bounces", 2}, {"bounces", true}}}};
}

// The second bounce at floor pixel x seen along -wo, integrated over 400 x 200 points of the wall.
double wall_reflection(double roughness, const tprf::Vec3& x, const tprf::Vec3& wo) {
    constexpr int nu = 400, nv = 200;
    const double da = (2.0 / nu) * (1.0 / nv);
    double sum = 0.0;
    for (int a = 0; a < nu; ++a)
        for (int b = 0; b < nv; ++b) {
            const tprf::Vec3 y(-1.0 + (a + 0.5) * 2.0 / nu, 1.0, (b + 0.5) / nv);
            const tprf::Vec3 to_light = kWallLight - y;
            const double l_wall = 0.8 / M_PI * (-to_light.normalized().y()) / to_light.squaredNorm();
            const tprf::Vec3 r = y - x;
            const double d2 = r.squaredNorm();
            const tprf::Vec3 wi = r / std::sqrt(d2);
            sum += 0.8 * lobe(roughness, wi, wo) * l_wall * wi.z() * wi.y() / d2 * da;
        }
    return sum;
}

// Per floor pixel whose reference is above 5% of the brightest: |got - expected| / expected.
struct WallErrors {
    std::vector<double> errors;
    std::vector<double> ratios;  // got / expected, the same pixels
    double seconds = 0.0;
    double median() {
        std::sort(errors.begin(), errors.end());
        return errors.empty() ? 1.0 : errors[errors.size() / 2];
    }
    double p90() { return errors.empty() ? 1.0 : errors[errors.size() * 9 / 10]; }
};

WallErrors wall_errors(const WallInFloor& w) {
    const json j = wall_in_floor(w);
    const tprf::Scene scene = tprf::parse_scene(j.dump(), "glossy_transport_test.json");
    const auto start = std::chrono::steady_clock::now();
    const auto r = tprf::render_scene(scene, {});
    WallErrors out;
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const tprf::FloatArray& second = array(r, "transient_bounce_2");
    const std::size_t side = 24, bins = second.shape[2];
    std::vector<double> expected(side * side, 0.0), got(side * side, 0.0);
    double top = 0.0;
    for (std::size_t row = 0; row < side; ++row)
        for (std::size_t col = 0; col < side; ++col) {
            const tprf::Vec3 d = tprf::camera_ray(*scene.camera, double(col) + 0.5, double(row) + 0.5);
            if (d.z() >= 0.0) continue;
            const tprf::Vec3 x = scene.camera->position + d * (-scene.camera->position.z() / d.z());
            if (std::abs(x.x()) > 0.95 || x.y() < -0.95 || x.y() > 0.95) continue;  // the floor, its edges left out
            const std::size_t px = row * side + col;
            expected[px] = wall_reflection(w.roughness, x, -d);
            for (std::size_t t = 0; t < bins; ++t) got[px] += second.data[(px * bins + t) * 3];
            top = std::max(top, expected[px]);
        }
    for (std::size_t px = 0; px < side * side; ++px)
        if (expected[px] > 0.05 * top) {
            out.errors.push_back(std::abs(got[px] - expected[px]) / expected[px]);
            out.ratios.push_back(got[px] / expected[px]);
        }
    return out;
}

// The wall seen in a floor of roughness 0.5 through 4 rings of cells: the interpolated out-cells about each
// pixel's view against the integral over the wall (measured: median 1.4%, p90 3.4%; the cells are 1/4
// of the disk across, the lobe about 1).
TEST(GlossyTransport, AWallSeenInARoughMetalFloorIsItsIntegralOverTheWall) {
    WallErrors e = wall_errors({0.5, 4});
    ASSERT_GT(e.errors.size(), 300u);
    const double median = e.median(), p90 = e.p90();
    EXPECT_LT(median, 0.03);
    EXPECT_LT(p90, 0.06);
}

// The table of docs/method.md: TPRF_GLOSSY_TABLE=1 prints the error against the resolution.
TEST(GlossyTransport, ErrorAgainstTheResolution) {
    if (!std::getenv("TPRF_GLOSSY_TABLE")) GTEST_SKIP() << "set TPRF_GLOSSY_TABLE=1 to print the table";
    const char* only = std::getenv("TPRF_GLOSSY_RINGS");
    for (double roughness : {0.2, 0.5})
        for (int rings : {2, 3, 4}) {
            if (only && std::atoi(only) != rings) continue;
            WallErrors e = wall_errors({roughness, rings});
            const double median = e.median(), p90 = e.p90();
            std::sort(e.ratios.begin(), e.ratios.end());
            std::printf("roughness %.1f  R %d  median %.4f  p90 %.4f  ratio p10 %.3f p50 %.3f p90 %.3f  seconds %.2f  (%zu pixels)\n",
                        roughness, rings, median, p90, e.ratios[e.ratios.size() / 10], e.ratios[e.ratios.size() / 2],
                        e.ratios[e.ratios.size() * 9 / 10], e.seconds, e.errors.size());
        }
}

TEST(GlossyTransport, TheEstimateCountsTheCellsRowsAndTheirMemory) {
    const tprf::Scene without = tprf::parse_scene(corner(metal(0.8, 0.2), 0.1, 0).dump(), "glossy_transport_test.json");
    const tprf::Scene with = tprf::parse_scene(corner(metal(0.8, 0.2), 0.1, 4).dump(), "glossy_transport_test.json");
    const tprf::ResourceEstimate a = tprf::estimate_resources(without, {});
    const tprf::ResourceEstimate b = tprf::estimate_resources(with, {});
    // The floor is half the patches (100 of 200 at max_edge 0.1): 2 x 64 rows each.
    EXPECT_EQ(a.glossy_rows, 0u);
    EXPECT_NEAR(double(b.glossy_rows), 2.0 * 64 * 100, 0.2 * 2.0 * 64 * 100);
    EXPECT_DOUBLE_EQ(b.glossy_lobe_fmas, double(b.glossy_rows) / 2.0 * 64);
    EXPECT_GT(b.solver_bytes, a.solver_bytes);
    EXPECT_GT(b.links, a.links);
    EXPECT_GT(b.seconds.solve, a.seconds.solve);
}

// links.glossy_resolution "auto" (the default): kAutoGlossyRings rings while glossy patches x patches
// stay within kAutoGlossyPairs, none beyond (the glossy patches then pass their light on as Lambertian
// surfaces of their hemispherical albedo); the patches, the links and the estimate take it from one rule.
TEST(GlossyTransport, AutoGivesCellsWhereTheirPairsAreAffordable) {
    json small = corner(metal(0.8, 0.2), 0.1, 0, "flat");
    small["links"].erase("glossy_resolution");
    const tprf::Scene a = tprf::parse_scene(small.dump(), "glossy_transport_test.json");
    EXPECT_EQ(a.links.glossy_resolution, tprf::kGlossyAuto);
    const tprf::PatchSet pa = tprf::build_patches(a);
    EXPECT_EQ(pa.glossy_rings_for(a.links.glossy_resolution), tprf::kAutoGlossyRings);
    const auto va = tprf::scene_visibility(a, pa);
    EXPECT_EQ(tprf::make_link_set(pa, *va, a.links, a.time.bin_width_m()).glossy.rings, tprf::kAutoGlossyRings);
    EXPECT_EQ(tprf::estimate_resources(a, {}).glossy_rings, tprf::kAutoGlossyRings);
    small["links"]["glossy_resolution"] = "auto";
    EXPECT_EQ(tprf::parse_scene(small.dump(), "glossy_transport_test.json").links.glossy_resolution, tprf::kGlossyAuto);

    // 6,400 glossy patches beside 6,400 diffuse ones: 8.2e7 pairs.
    json large = small;
    large["patches"]["max_edge"] = 0.0125;
    const tprf::Scene b = tprf::parse_scene(large.dump(), "glossy_transport_test.json");
    const tprf::PatchSet pb = tprf::build_patches(b);
    ASSERT_EQ(pb.glossy_patches(), 6400u);
    ASSERT_EQ(pb.size(), 12800u);
    EXPECT_EQ(pb.glossy_rings_for(b.links.glossy_resolution), 0);
    EXPECT_EQ(tprf::estimate_resources(b, {}).glossy_rings, 0);
    const std::uint32_t g = pb.object[0] == 0 ? 0 : std::uint32_t(pb.size() - 1);
    ASSERT_NE(pb.brdf(g), nullptr);
    EXPECT_EQ(pb.albedo[g][0], pb.brdf(g)->hemispherical_albedo()[0]);
    EXPECT_EQ(pb.glossy_rings_for(2), 2);  // an integer is taken as it is

    large["links"]["glossy_resolution"] = "fine";
    try {
        (void)tprf::parse_scene(large.dump(), "glossy_transport_test.json");
        FAIL() << "glossy_resolution \"fine\" was accepted";
    } catch (const std::exception& e) {
        EXPECT_NE(std::string(e.what()).find("links.glossy_resolution"), std::string::npos) << e.what();
    }
}

// A confocal capture: a diffuse relay wall at z = 0 and, 0.6 m in front of it, a hidden square facing
// it, glossy or Lambertian; every bounce up to the sixth.
json hidden_square(const json& material, double albedo, int rings) {
    json hidden = {{"type", "rectangle"}, {"origin", {-0.2, -0.2, 0.6}}, {"u", {0, 0.4, 0}}, {"v", {0.4, 0, 0}},
                   {"albedo", albedo}};
    if (!material.is_null()) hidden["material"] = material;
    json capture = {{"type", "confocal"},
                    {"laser", {{"position", {0, -1, 0.5}}, {"power", 1.0}}},
                    {"sensor", {{"position", {0, -1, 0.5}}}},
                    {"grid", {{"origin", {-0.4, -0.4, 0}}, {"u", {0.8, 0, 0}}, {"v", {0, 0.8, 0}}, {"nu", 4}, {"nv", 4}}},
                    {"max_bounces", 6}};
    return {{"time", {{"bins", 400}, {"bin_width", 0.01}, {"start", 0.0}, {"unit", "m"}}},
            {"objects",
             {{{"type", "rectangle"}, {"origin", {-0.5, -0.5, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", 0.8}},
              hidden}},
            {"patches", {{"max_edge", 0.1}}},
            {"links", {{"glossy_resolution", rings}}},
            {"capture", capture}};
}

TEST(GlossyTransport, ACaptureOfAHiddenSquareWithALobeOfReflectanceZeroIsTheLambertianOne) {
    const auto lambertian = render(hidden_square(nullptr, 0.5, 0));
    const auto glossy = render(hidden_square({{"type", "glossy"}, {"reflectance", 0.0}, {"roughness", 0.3}}, 0.5, 4));
    const tprf::FloatArray& a = array(lambertian, "capture");
    const tprf::FloatArray& b = array(glossy, "capture");
    EXPECT_GT(peak(a), 0.0);
    EXPECT_LT(largest_difference(a, b), 1e-5 * peak(a));
}

TEST(GlossyTransport, AGlossyHiddenSquareSendsItsLobeIntoTheCapturesLaterBounces) {
    // The same square as a metal of reflectance 0.5 (no diffuse part) and as a Lambertian square of albedo
    // 0.5: each one's light is its capture less the wall's alone. Every value is finite, the hidden light
    // is there, and the metal's differs from the Lambertian's (the BRDF, not albedo / pi).
    const json metal_scene = hidden_square({{"type", "glossy"}, {"reflectance", 0.5}, {"roughness", 0.3}}, 0.0, 4);
    json wall_scene = metal_scene;
    wall_scene["objects"].erase(1);
    const auto metal = render(metal_scene);
    const auto lambertian = render(hidden_square(nullptr, 0.5, 0));
    const auto wall = render(wall_scene);
    const tprf::FloatArray& c = array(metal, "capture");
    const tprf::FloatArray& l = array(lambertian, "capture");
    const tprf::FloatArray& w = array(wall, "capture");
    ASSERT_EQ(c.shape, w.shape);
    double metal_light = 0.0, lambertian_light = 0.0, apart = 0.0;
    for (std::size_t k = 0; k < c.data.size(); ++k) {
        ASSERT_TRUE(std::isfinite(c.data[k]));
        metal_light += c.data[k] - w.data[k];
        lambertian_light += l.data[k] - w.data[k];
        apart += std::abs(c.data[k] - l.data[k]);
    }
    EXPECT_GT(metal_light, 0.0);
    EXPECT_GT(lambertian_light, 0.0);
    EXPECT_GT(apart, 0.05 * lambertian_light);
}



// A closed 1 m box of six glossy walls (albedo 0.3, a metal lobe of reflectance 0.7 and roughness 0.3;
// 25 cm patches, R = 3) around a point light, or of five and a perfect mirror. Every watt the light
// sends is absorbed by the glossy walls, and each wall patch sends on what its BRDF says of what
// reaches it: its Lambertian part albedo times its irradiance, and through its lobe the irradiance of
// each in-cell times the lobe's directional albedo averaged over that cell (16 x 16 directions here,
// GlossyBrdf::directional_albedo: not the library's cell reflectance). The balance fails when a pair's
// form factor is not shared among the cells the other patch covers (light leaving a cell then reaches
// more or less than the cell's share of the hemisphere), and, with the mirror, when the cells' light does
// not go through it.
json glossy_box(const json& material, bool mirror_wall) {
    const auto wall = [&](std::vector<double> o, std::vector<double> u, std::vector<double> v) {
        return json{{"type", "rectangle"}, {"origin", o}, {"u", u}, {"v", v}, {"albedo", 0.3}, {"material", material}};
    };
    json walls = {wall({0, 0, 0}, {1, 0, 0}, {0, 1, 0}), wall({0, 0, 1}, {0, 1, 0}, {1, 0, 0}),
                  wall({0, 0, 0}, {0, 0, 1}, {1, 0, 0}), wall({0, 1, 0}, {1, 0, 0}, {0, 0, 1}),
                  wall({0, 0, 0}, {0, 1, 0}, {0, 0, 1}), wall({1, 0, 0}, {0, 0, 1}, {0, 1, 0})};
    if (mirror_wall) walls[5] = {{"type", "rectangle"}, {"origin", {1, 0, 0}}, {"u", {0, 0, 1}}, {"v", {0, 1, 0}},
                                 {"material", {{"type", "mirror"}, {"reflectance", 1.0}}}};
    return {{"time", {{"bins", 64}, {"bin_width", 0.05}, {"start", 0.0}, {"unit", "m"}}},
            {"camera",
             {{"position", {0.5, 0.1, 0.5}}, {"look_at", {0.5, 1.0, 0.5}}, {"up", {0, 0, 1}}, {"fov", 60},
              {"width", 8}, {"height", 8}}},
            {"lights", {{{"type", "point"}, {"position", {0.37, 0.52, 0.61}}, {"intensity", 1.0}}}},
            {"objects", walls},
            {"patches", {{"max_edge", 0.25}}},
            {"links", {{"method", "flat"}, {"glossy_resolution", 3}}}};
}

// The lobe's directional albedo per unit reflectance averaged over each cell, in projected solid angle.
std::vector<double> cell_lobe_albedo(const tprf::GlossyBrdf& brdf, const tprf::HemisphereCells& cells) {
    tprf::GlossyBrdf lobe = brdf;
    lobe.albedo = tprf::Rgb::Zero();
    lobe.reflectance = tprf::Rgb::Ones();
    constexpr int kSide = 16;
    std::vector<double> out(std::size_t(cells.count()), 0.0);
    for (int c = 0; c < cells.count(); ++c) {
        for (int a = 0; a < kSide; ++a)
            for (int b = 0; b < kSide; ++b)
                out[std::size_t(c)] += lobe.directional_albedo(cells.direction(c, (a + 0.5) / kSide, (b + 0.5) / kSide).z())[0];
        out[std::size_t(c)] /= kSide * kSide;
    }
    return out;
}

// Absorbed / emitted - 1 of the glossy box, and the worst glossy patch's lobe against its albedo's.
struct BoxBalance {
    double absorbed = 0.0, worst = 0.0;
};

BoxBalance glossy_box_balance(bool mirror_wall) {
    const tprf::Scene scene = tprf::parse_scene(glossy_box(metal(0.7, 0.3), mirror_wall).dump(), "glossy_box.json");
    const tprf::PatchSet patches = tprf::build_patches(scene);
    const auto visibility = tprf::scene_visibility(scene, patches);
    tprf::LinkOptions link_options;
    const double bin_m = scene.time.bin_width_m();
    tprf::LinkSet links = tprf::make_link_set(patches, *visibility, scene.links, bin_m, link_options);
    tprf::add_mirror_links(links, patches, *visibility, link_options, bin_m);
    const tprf::GlossyRows& rows = links.glossy;
    EXPECT_EQ(rows.glossy.size(), patches.size() - (mirror_wall ? 16 : 0));
    const tprf::LightSources sources = tprf::light_sources(scene, patches, *visibility);
    tprf::PatchSet unit = patches;  // glossy patches lit with albedo 1: their pulses are their direct irradiance
    for (std::uint32_t i : rows.glossy) unit.albedo[i] = tprf::Rgb::Ones();
    const tprf::Illumination direct = tprf::illuminate(sources, unit, *visibility, {});
    const std::vector<tprf::Rgb> b =
        tprf::solve_steady(patches, links, tprf::glossy_illumination(rows, patches, sources, direct));

    const tprf::HemisphereCells cells(rows.rings);
    const std::vector<double> rho = cell_lobe_albedo(*patches.brdf(rows.glossy[0]), cells);
    const std::size_t m = std::size_t(rows.cells());
    BoxBalance out;
    for (std::size_t g = 0; g < rows.glossy.size(); ++g) {
        const std::size_t i = rows.glossy[g];
        double from_light = 0.0, indirect = 0.0, lobe_in = 0.0, lobe_out = 0.0;
        for (std::uint64_t k = direct.row[i]; k < direct.row[i + 1]; ++k) {
            const tprf::Pulse& pulse = direct.pulses[k];
            from_light += pulse.energy[0];
            const tprf::Vec3 from = sources.points[std::size_t(pulse.point_source)].position;  // the light or its image
            lobe_in += pulse.energy[0] * rho[std::size_t(rows.cell_towards(patches, i, from - patches.centroid[i]))];
        }
        for (std::size_t c = 0; c < m; ++c) {
            const double in = b[rows.in_row(g, int(c))][0];
            indirect += in;
            lobe_in += in * rho[c];
            lobe_out += b[rows.out_row(g, int(c))][0] / double(m);
        }
        const double irradiance = from_light + indirect;
        // What leaves: the Lambertian part and the lobe's, each as the BRDF says.
        EXPECT_NEAR(b[i][0], 0.3 * irradiance, 1e-5 * irradiance) << "patch " << i;
        out.worst = std::max(out.worst, std::abs(lobe_out / (0.7 * lobe_in) - 1.0));
        out.absorbed += patches.area[i] * (irradiance - b[i][0] - lobe_out);
    }
    return out;
}

TEST(GlossyTransport, AClosedBoxOfGlossyWallsSendsOnWhatItsDirectionalAlbedoSays) {
    for (const bool mirror_wall : {false, true}) {
        const BoxBalance box = glossy_box_balance(mirror_wall);
        const double emitted = 4.0 * M_PI;
        MEASURED("closed glossy box%s: absorbed / emitted - 1 = %.3g; worst patch's lobe / its albedo's - 1 = %.3g\n",
                 mirror_wall ? " with a mirror wall" : "", box.absorbed / emitted - 1.0, box.worst);
        // Measured: -4e-5, with the mirror wall -1.6e-3 (a pair's form factor given whole to one cell:
        // +0.40; no cells' links through the mirror: -0.67). The same boxes of Lambertian walls of albedo
        // 0.9 balance to +1.1e-3 and +2.5e-4 (the direct light's sampling, +9.6e-4, and the form factors'
        // closure); the lobe's albedo per cell is the library's to 1.1e-3 (its 4 x 4 directions per cell
        // against 16 x 16 here).
        EXPECT_NEAR(box.absorbed, emitted, 2e-3 * emitted) << (mirror_wall ? "with a mirror wall" : "six glossy walls");
        EXPECT_LT(box.worst, 2e-3) << (mirror_wall ? "with a mirror wall" : "six glossy walls");
    }
}

}  // namespace
