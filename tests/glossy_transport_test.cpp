// Glossy patches in the transport (links.glossy_resolution, transport/glossy_rows.h): answers fixed in
// advance by the method's own invariants. A lobe of reflectance 0 leaves a Lambertian surface of the
// same albedo; the time integral of the cube is the steady solve; the bounce cubes add up to the cube;
// flat and hierarchical links give the same light.

#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <numeric>
#include <string>

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

TEST(GlossyTransport, ACaptureRefusesGlossyCells) {
    json scene = corner(metal(0.8, 0.2), 0.1, 4);
    scene.erase("camera");
    scene.erase("lights");
    scene["capture"] = {{"type", "confocal"},
                        {"laser", {{"position", {0.5, -1, 0.5}}, {"power", 1.0}}},
                        {"sensor", {{"position", {0.5, -1, 0.5}}}},
                        {"grid", {{"origin", {0.1, 1, 0.1}}, {"u", {0.8, 0, 0}}, {"v", {0, 0, 0.8}}, {"nu", 2}, {"nv", 2}}}};
    try {
        (void)tprf::parse_scene(scene.dump(), "glossy_transport_test.json");
        FAIL() << "a capture with glossy cells was accepted";
    } catch (const std::exception& e) {
        EXPECT_NE(std::string(e.what()).find("links.glossy_resolution"), std::string::npos) << e.what();
    }
}

}  // namespace
