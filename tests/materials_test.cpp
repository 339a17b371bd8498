// Mirrors and thin glass (docs/materials.md), each checked against an answer
// fixed in advance: the paper's echo train (closed-form view factor of a plane and its mirror image),
// energy conservation in a closed box with a mirror wall, the explicitly unfolded scene, and Tr times
// the scene behind a glass sheet.

#include "test_scenes.h"

#include "tprf/core/error.h"
#include "tprf/geometry/mirror_images.h"
#include "tprf/geometry/patches.h"
#include "tprf/pipeline/info.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>
#include <string>

namespace {

using nlohmann::json;
using tprf::test::ff_parallel_rectangles;

tprf::RenderResult render(const json& scene, bool patch_profiles = false) {
    tprf::RenderOptions options;
    options.patch_profiles = patch_profiles;
    return tprf::render_scene(tprf::parse_scene(scene.dump(), "materials_test.json"), options);
}

const tprf::FloatArray& array(const tprf::RenderResult& r, const std::string& name) {
    const auto it = r.arrays.find(name);
    if (it == r.arrays.end()) throw std::runtime_error("no array " + name);
    return it->second;
}

json rect(std::array<double, 3> o, std::array<double, 3> u, std::array<double, 3> v, double albedo) {
    return {{"type", "rectangle"}, {"origin", o}, {"u", u}, {"v", v}, {"albedo", albedo}};
}

// A rectangle of a specular material, without a diffuse part.
json specular(std::array<double, 3> o, std::array<double, 3> u, std::array<double, 3> v, const json& material) {
    return {{"type", "rectangle"}, {"origin", o}, {"u", u}, {"v", v}, {"material", material}};
}

const json kPerfectMirror = {{"type", "mirror"}, {"reflectance", 1.0}};

std::string error_of(const json& scene) { return tprf::test::parse_error(scene.dump()); }

json small_scene() {
    return {{"time", {{"bins", 10}, {"bin_width", 0.1}}},
            {"camera", {{"position", {0, 0, 2}}, {"look_at", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov", 40}, {"width", 4}, {"height", 4}}},
            {"objects", json::array({rect({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, 0.5)})}};
}

TEST(Materials, BadMaterialsNameTheirJsonPath) {
    const auto with = [](json material) {
        json s = small_scene();
        s["objects"][0].erase("albedo");
        s["objects"][0]["material"] = material;
        return error_of(s);
    };
    EXPECT_NE(with({{"type", "glass"}, {"reflectance", 0.5}, {"transmittance", 0.4}, {"albedo", 0.2}})
                  .find("bad.json: objects[0].material: reflectance + transmittance + albedo is 1.1"),
              std::string::npos);
    EXPECT_NE(with({{"type", "mirror"}, {"reflectance", -0.1}}).find("objects[0].material.reflectance: must be in [0, 1]"),
              std::string::npos);
    EXPECT_EQ(with({{"type", "mirror"}, {"reflectance", {0.9, 0.5, 0.5}}}), "");  // a tinted mirror
    EXPECT_NE(with({{"type", "glass"}, {"reflectance", 0.1}, {"transmittance", {0.9, 0.5, 0.5}}})
                  .find("objects[0].material.transmittance: must be grey"),
              std::string::npos);
    EXPECT_NE(with({{"type", "mirror"}, {"reflectance", 0.9}, {"transmittance", 0.1}}).find("objects[0].material"),
              std::string::npos);
    EXPECT_NE(with({{"type", "chrome"}}).find("objects[0].material.type: unknown material type \"chrome\""),
              std::string::npos);
    EXPECT_NE(with({{"type", "glass"}, {"reflectance", 0.1}}).find("objects[0].material"), std::string::npos);
    json both = small_scene();
    both["objects"][0]["material"] = {{"type", "mirror"}, {"reflectance", 0.5}, {"albedo", 0.2}};
    EXPECT_NE(error_of(both).find("objects[0].material.albedo: the object gives an albedo too"), std::string::npos);
    json max = small_scene();
    max["solver"] = {{"max_specular", -1}};
    EXPECT_NE(error_of(max).find("solver.max_specular: must be in [0, 16]"), std::string::npos);
}

TEST(Materials, CurvedMirrorMeshIsRefusedNamingTheObject) {
    tprf::test::MeshDir dir("tprf_materials_");
    std::ofstream(dir.path / "bent.obj") << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0.2\nf 1 2 3\nf 1 3 4\n";
    json s = small_scene();
    s["objects"].push_back({{"type", "mesh"}, {"file", "bent.obj"}, {"material", {{"type", "mirror"}, {"reflectance", 1}}}});
    try {
        tprf::render_scene(tprf::parse_scene(s.dump(), dir.path / "scene.json"), {});
        FAIL() << "a curved mirror rendered";
    } catch (const tprf::Error& e) {
        EXPECT_NE(std::string(e.what()).find("objects[1]: a mirror or glass object must be planar"), std::string::npos)
            << e.what();
    }
}

TEST(Materials, ClipToWindowKeepsWhatTheApexSeesThroughIt) {
    // A unit square window at z = 0 seen from (0.5, 0.5, 1): the cone through it covers, at z = -1, the
    // square [-0.5, 1.5]^2 (twice the size); a big polygon there is clipped to exactly that.
    const std::vector<tprf::Vec3> window = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    const std::vector<tprf::Vec3> big = {{-5, -5, -1}, {5, -5, -1}, {5, 5, -1}, {-5, 5, -1}};
    const auto clipped = tprf::clip_to_window(big, {0.5, 0.5, 1}, window.data(), 4, true);
    ASSERT_EQ(clipped.size(), 4u);
    for (const tprf::Vec3& c : clipped) {
        EXPECT_NEAR(std::abs(c.x() - 0.5), 1.0, 1e-12);
        EXPECT_NEAR(std::abs(c.y() - 0.5), 1.0, 1e-12);
    }
    // From behind the window (apex at z = -2 looking up), the same window clips a polygon at z = 1.
    const std::vector<tprf::Vec3> top = {{-5, -5, 1}, {5, -5, 1}, {5, 5, 1}, {-5, 5, 1}};
    EXPECT_EQ(tprf::clip_to_window(top, {0.5, 0.5, -2}, window.data(), 4, false).size(), 4u);
}

// Paper 2, section 3.2 and Figure 2: glass A (reflectance R, transmittance Tr) parallel to a diffuser B
// at distance h. B glows uniformly at t = 0 (order 0); each echo is B lit by its own image at 2h.
json echo_scene(double bin) {
    const double h = 0.25, side = 0.5;
    const json glass = specular({0, 0, h}, {side, 0, 0}, {0, side, 0},
                                {{"type", "glass"}, {"reflectance", 0.5}, {"transmittance", 0.4}});
    json b = rect({0, 0, 0}, {side, 0, 0}, {0, side, 0}, 0.8);
    b["emission"] = 1.0;
    // The camera sees exactly B (its field of view spans B's side), through the glass.
    const double fov = 2.0 * std::atan(0.5 * side / 2.0) * 180.0 / M_PI;
    return {{"time", {{"bins", int(std::lround(4.0 / bin))}, {"bin_width", bin}}},
            {"camera", {{"position", {0.25, 0.25, 2.0}}, {"look_at", {0.25, 0.25, 0}}, {"up", {0, 1, 0}},
                        {"fov", fov}, {"width", 64}, {"height", 64}, {"footprint", false}}},  // point samples
            {"objects", json::array({b, glass})},
            {"patches", {{"max_edge", 0.025}}},
            {"solver", {{"bounces", true}}}};
}

// The image summed over pixels, per bin, of one array (H, W, T, 3), channel 0.
std::vector<double> image_profile(const tprf::FloatArray& a) {
    const std::size_t T = a.shape[2], pixels = a.shape[0] * a.shape[1];
    std::vector<double> p(T, 0.0);
    for (std::size_t px = 0; px < pixels; ++px)
        for (std::size_t t = 0; t < T; ++t) p[t] += a.data[(px * T + t) * 3];
    return p;
}

TEST(Materials, EchoTrainOfGlassInFrontOfADiffuserMatchesTheMirrorImageViewFactor) {
    const double h = 0.25, bin = 2 * h / 8;
    const tprf::RenderResult r = render(echo_scene(bin));
    const double expected_ratio = 0.8 * 0.5 * ff_parallel_rectangles(0.5, 0.5, 2 * h);
    std::vector<double> energy;
    for (int k = 0; k < 4; ++k) {
        const std::vector<double> p = image_profile(array(r, "transient_bounce_" + std::to_string(k)));
        energy.push_back(std::accumulate(p.begin(), p.end(), 0.0));
        // Echo k leaves B at k 2h; the nearest pixel's leg is 2 m: its onset is exactly that bin. Its
        // peak (the image's) follows within one bin for k <= 2; later echoes, k-fold convolutions of the
        // path spread 2h .. sqrt(4h^2 + 2 side^2), peak later still (echo 3: 2 bins of 2h / 8).
        const int expected = int(std::floor((2.0 + k * 2 * h) / bin + 1e-9));
        const auto first = std::find_if(p.begin(), p.end(), [&](double v) { return v > 0.0; });
        EXPECT_EQ(int(first - p.begin()), expected) << "echo " << k;
        const int peak = int(std::max_element(p.begin(), p.end()) - p.begin());
        if (k <= 2) {
            EXPECT_LE(std::abs(peak - expected), 1) << "echo " << k << " peaks at bin " << peak;
        }
    }
    // B glows uniformly, so the first echo holds albedo R F of it exactly; later ones, lit unevenly,
    // a little more (their light gathers towards B's centre).
    const double ratio = energy[1] / energy[0];
    MEASURED("echo ratios %.6f %.6f %.6f, closed form %.6f\n", ratio, energy[2] / energy[1], energy[3] / energy[2],
             expected_ratio);
    EXPECT_NEAR(ratio, expected_ratio, 0.02 * expected_ratio);
    EXPECT_NEAR(energy[2] / energy[1], expected_ratio, 0.02 * expected_ratio);
}

// `tprf info` counts the links through the glass before building them (within a factor 2), and the
// built summary names them.
TEST(Materials, InfoCountsTheLinksThroughMirrors) {
    const tprf::Scene scene = tprf::parse_scene(echo_scene(0.0625).dump(), "echo.json");
    const tprf::ResourceEstimate e = tprf::estimate_resources(scene, {}, false);
    const tprf::SceneSummary s = tprf::describe_scene(scene, {});
    MEASURED("echo scene: %zu links estimated, %zu built, %llu through the glass\n", e.links, s.links,
             static_cast<unsigned long long>(s.mirror_links));
    EXPECT_EQ(s.mirror_links, s.links);  // the diffuser and the glass' back never face each other directly
    EXPECT_GT(s.mirror_links, 0u);
    EXPECT_LT(double(e.links), 2.0 * double(s.links));
    EXPECT_GT(double(e.links), 0.5 * double(s.links));
}

// A closed unit box, inward walls of albedo a, one wall a perfect mirror, a glowing patch on the floor:
// every watt the diffuse walls send comes back to them (directly or by the mirror), so they send
// P / (1 - a) in all.
TEST(Materials, ClosedBoxWithAMirrorWallConservesEnergy) {
    const double a = 0.6;
    json walls = json::array({
        rect({0, 0, 1}, {0, 1, 0}, {1, 0, 0}, a),   // ceiling, facing -z
        rect({0, 0, 0}, {0, 0, 1}, {1, 0, 0}, a),   // y = 0, facing +y
        rect({0, 1, 0}, {1, 0, 0}, {0, 0, 1}, a),   // y = 1, facing -y
        rect({1, 0, 0}, {0, 0, 1}, {0, 1, 0}, a),   // x = 1, facing -x
        specular({0, 0, 0}, {0, 1, 0}, {0, 0, 1}, kPerfectMirror),  // x = 0, facing +x
        // The floor (facing +z) in five pieces, the middle one glowing: nothing in the box absorbs
        // but the walls' (1 - a).
        rect({0, 0, 0}, {1, 0, 0}, {0, 0.4, 0}, a),
        rect({0, 0.6, 0}, {1, 0, 0}, {0, 0.4, 0}, a),
        rect({0, 0.4, 0}, {0.4, 0, 0}, {0, 0.2, 0}, a),
        rect({0.6, 0.4, 0}, {0.4, 0, 0}, {0, 0.2, 0}, a),
        rect({0.4, 0.4, 0}, {0.2, 0, 0}, {0, 0.2, 0}, a),
    });
    walls[9]["emission"] = 1.0;
    const json scene = {{"time", {{"bins", 8}, {"bin_width", 0.5}}},
                        {"camera", {{"position", {0.5, 0.5, 0.5}}, {"look_at", {0, 0.5, 0.5}}, {"up", {0, 0, 1}},
                                    {"fov", 40}, {"width", 4}, {"height", 4}}},
                        {"objects", walls},
                        {"patches", {{"max_edge", 0.1}}}};
    const tprf::RenderResult r = render(scene, true);
    const tprf::FloatArray& steady = array(r, "patch_steady");
    const tprf::Scene s = tprf::parse_scene(scene.dump(), "box.json");
    const tprf::PatchSet patches = tprf::build_patches(s);
    double total = 0.0, emitted = 0.0;
    for (std::size_t i = 0; i < patches.size(); ++i) {
        total += patches.area[i] * steady.data[3 * i];
        emitted += patches.area[i] * M_PI * patches.emission[i][0];
    }
    MEASURED("mirror box: total %.6f, closed form %.6f\n", total, emitted / (1 - a));
    EXPECT_NEAR(total, emitted / (1 - a), 1e-3 * emitted / (1 - a));
}

}  // namespace

namespace {

json point_light(std::array<double, 3> p) { return {{"type", "point"}, {"position", p}, {"intensity", 1.0}}; }

json camera_at(std::array<double, 3> p, std::array<double, 3> look, int size) {
    return {{"position", p}, {"look_at", look}, {"up", {0, 0, 1}}, {"fov", 60}, {"width", size}, {"height", size}};
}

// The largest difference between two arrays of one shape, relative to the largest value of `b`.
double relative_difference(const tprf::FloatArray& a, const tprf::FloatArray& b) {
    EXPECT_EQ(a.shape, b.shape);
    double diff = 0.0, top = 0.0;
    for (std::size_t k = 0; k < a.data.size(); ++k) {
        diff = std::max(diff, double(std::abs(a.data[k] - b.data[k])));
        top = std::max(top, double(std::abs(b.data[k])));
    }
    return diff / top;
}

// Renders both scenes and expects the same cube and steady image, to 1e-4 of the peak; returns the first.
tprf::RenderResult expect_same_light(const json& first, const json& second, const char* what) {
    tprf::RenderResult a = render(first);
    const tprf::RenderResult b = render(second);
    const double transient = relative_difference(array(a, "transient"), array(b, "transient"));
    const double steady = relative_difference(array(a, "steady"), array(b, "steady"));
    MEASURED("%s: transient %.3g, steady %.3g of the peak\n", what, transient, steady);
    EXPECT_LT(transient, 1e-4) << what;
    EXPECT_LT(steady, 1e-4) << what;
    return a;
}

// A quad perpendicular to a big mirror (its image is coplanar with it, so it never lights itself through
// the mirror), a point light in front. Unfolded: the mirror replaced by the mirror image of the quad
// and of the light. The camera sees the same cube in both, its view of the mirror included.
TEST(Materials, APixelInAMirrorSeesWhatTheUnfoldedSceneShows) {
    json quad = rect({0.5, 0, -0.5}, {1, 0, 0}, {0, 0, 1}, 0.7);  // y = 0, facing -y
    quad["u"] = {0, 0, 1};
    quad["v"] = {1, 0, 0};  // z x x = +y: facing +y
    const json mirror = specular({0, 0, -2}, {0, 3, 0}, {0, 0, 4}, kPerfectMirror);  // x = 0, facing +x
    json image = rect({-1.5, 0, -0.5}, {0, 0, 1}, {1, 0, 0}, 0.7);  // the quad reflected: still facing +y
    const json base = {{"time", {{"bins", 160}, {"bin_width", 0.03}}},
                       {"camera", camera_at({1.2, 1.6, 0.3}, {-0.4, 0, 0}, 24)},
                       {"patches", {{"max_edge", 0.1}}}};
    json with_mirror = base, unfolded = base;
    with_mirror["objects"] = {quad, mirror};
    with_mirror["lights"] = {point_light({0.7, 0.5, 0.4})};
    unfolded["objects"] = {quad, image};
    unfolded["lights"] = {point_light({0.7, 0.5, 0.4}), point_light({-0.7, 0.5, 0.4})};
    const tprf::RenderResult a = expect_same_light(with_mirror, unfolded, "mirror pixel vs unfolded");
    // The mirror half of the image is lit: the test compares light, not two dark images.
    double mirrored = 0.0;
    const tprf::FloatArray& s = array(a, "steady");
    for (std::size_t r = 0; r < 24; ++r)
        for (std::size_t c = 0; c < 8; ++c) mirrored += s.data[(r * 24 + c) * 3];
    EXPECT_GT(mirrored, 0.0);
}

// A closed box with a perfect mirror wall at x = 0 is half of the box twice as long with the light
// mirrored: the camera, in the real half, sees the same steady image in both.
json box_walls(double x0, double length, double a) {
    return json::array({
        rect({x0, 0, 0}, {length, 0, 0}, {0, 1, 0}, a),  // floor, +z
        rect({x0, 0, 1}, {0, 1, 0}, {length, 0, 0}, a),  // ceiling, -z
        rect({x0, 0, 0}, {0, 0, 1}, {length, 0, 0}, a),  // y = 0, +y
        rect({x0, 1, 0}, {length, 0, 0}, {0, 0, 1}, a),  // y = 1, -y
        rect({1, 0, 0}, {0, 0, 1}, {0, 1, 0}, a),        // x = 1, -x
    });
}

TEST(Materials, SteadyImageOfAMirrorBoxMatchesTheUnfoldedBox) {
    const double a = 0.5;
    const json mirror = specular({0, 0, 0}, {0, 1, 0}, {0, 0, 1}, kPerfectMirror);  // x = 0, +x
    json with_mirror = {{"time", {{"bins", 40}, {"bin_width", 0.2}}},
                        {"camera", camera_at({0.95, 0.5, 0.5}, {0, 0.5, 0.5}, 32)},
                        {"patches", {{"max_edge", 0.1}}},
                        {"lights", {point_light({0.7, 0.4, 0.8})}}};
    json unfolded = with_mirror;
    with_mirror["objects"] = box_walls(0, 1, a);
    with_mirror["objects"].push_back(mirror);
    unfolded["objects"] = box_walls(-1, 2, a);
    unfolded["objects"].push_back(rect({-1, 0, 0}, {0, 1, 0}, {0, 0, 1}, a));  // x = -1, +x
    unfolded["lights"].push_back(point_light({-0.7, 0.4, 0.8}));
    const tprf::RenderResult m = render(with_mirror), u = render(unfolded);
    const tprf::FloatArray& sm = array(m, "steady");
    const tprf::FloatArray& su = array(u, "steady");
    double diff = 0.0, sum = 0.0, total_m = 0.0;
    for (std::size_t k = 0; k < su.data.size(); k += 3) {
        diff += std::abs(sm.data[k] - su.data[k]);
        sum += su.data[k];
        total_m += sm.data[k];
    }
    MEASURED("mirror box vs unfolded: mean |difference| %.4f, totals %.5f of the unfolded\n", diff / sum, total_m / sum);
    EXPECT_LT(diff / sum, 0.01);
    EXPECT_NEAR(total_m / sum, 1.0, 0.01);
}

// Glass that reflects nothing in front of a lit plate (the light behind it too): the camera sees the
// plate times the glass' transmittance, in every pixel and bin.
TEST(Materials, CameraThroughGlassSeesTransmittanceTimesTheScene) {
    json plate = rect({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, 0.6);
    const json glass =
        specular({-2, -2, 1}, {4, 0, 0}, {0, 4, 0}, {{"type", "glass"}, {"reflectance", 0.0}, {"transmittance", 0.35}});
    json clear = {{"time", {{"bins", 120}, {"bin_width", 0.05}}},
                  {"camera", {{"position", {0.2, 0.1, 2.5}}, {"look_at", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov", 50},
                              {"width", 16}, {"height", 16}}},
                  {"patches", {{"max_edge", 0.25}}},
                  {"lights", {point_light({0.3, -0.2, 0.5})}},
                  {"objects", {plate}}};
    json behind = clear;
    behind["objects"].push_back(glass);
    const tprf::RenderResult c = render(clear), g = render(behind);
    const tprf::FloatArray& tc = array(c, "transient");
    tprf::FloatArray scaled = tc;
    for (float& v : scaled.data) v *= 0.35f;
    const double diff = relative_difference(array(g, "transient"), scaled);
    MEASURED("through glass: %.3g of the peak from 0.35 x the clear view\n", diff);
    EXPECT_LT(diff, 1e-5);
}

}  // namespace

namespace {

// Two mirrors at right angles (a corner reflector) standing on a floor: the floor is lit by the light,
// by its image in each mirror and by its image through both (a chain of two reflections). Unfolded:
// the floor under the four lights. The floor's images are coplanar with it, so it never lights itself.
TEST(Materials, ACornerReflectorLightsTheFloorAsItsFourImagesDo) {
    const json mirror_a = specular({0, 0, 0}, {0, 2, 0}, {0, 0, 2}, kPerfectMirror);  // x = 0, facing +x
    const json mirror_b = specular({0, 0, 0}, {0, 0, 2}, {2, 0, 0}, kPerfectMirror);  // y = 0, facing +y
    const json floor = rect({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 0.6);
    const json base = {{"time", {{"bins", 300}, {"bin_width", 0.01}}},
                       {"camera", {{"position", {0.5, 0.5, 2.0}}, {"look_at", {0.5, 0.5, 0}}, {"up", {0, 1, 0}},
                                   {"fov", 16}, {"width", 16}, {"height", 16}}},
                       {"patches", {{"max_edge", 0.1}}}};
    json with_mirrors = base, unfolded = base;
    with_mirrors["objects"] = {floor, mirror_a, mirror_b};
    with_mirrors["lights"] = {point_light({0.3, 0.2, 0.5})};
    unfolded["objects"] = {floor};
    unfolded["lights"] = {point_light({0.3, 0.2, 0.5}), point_light({-0.3, 0.2, 0.5}), point_light({0.3, -0.2, 0.5}),
                          point_light({-0.3, -0.2, 0.5})};
    const tprf::RenderResult a = expect_same_light(with_mirrors, unfolded, "corner reflector vs four lights");
    // With one reflection at most (solver.max_specular 1), the image through both mirrors is gone: the
    // floor under three lights. The chain of two carried about a tenth of the light.
    json one = with_mirrors, three = unfolded;
    one["solver"] = {{"max_specular", 1}};
    three["lights"].erase(3);
    const tprf::RenderResult c = expect_same_light(one, three, "one reflection vs three lights");
    const tprf::FloatArray& sa = array(a, "steady");
    const tprf::FloatArray& sc = array(c, "steady");
    const double share = 1.0 - std::accumulate(sc.data.begin(), sc.data.end(), 0.0) /
                                   std::accumulate(sa.data.begin(), sa.data.end(), 0.0);
    MEASURED("the chain of two reflections carries %.3f of the light\n", share);
    EXPECT_GT(share, 0.05);
}

// A spot light aimed at a mirror lights the floor as its mirror image does: the image's cone is the
// reflected cone (its axis turned with it), in the direct light and in every bounce after it.
TEST(Materials, ASpotInAMirrorLightsTheFloorAsItsMirrorImage) {
    const json mirror = specular({0, 0, 0}, {0, 2, 0}, {0, 0, 2}, kPerfectMirror);  // x = 0, facing +x
    const json floor = rect({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 0.6);
    const auto spot = [](std::array<double, 3> at, std::array<double, 3> direction) {
        return json{{"type", "spot"}, {"position", at}, {"direction", direction}, {"intensity", 1.0},
                    {"half_angle", 15}, {"falloff", 10}};
    };
    const json base = {{"time", {{"bins", 300}, {"bin_width", 0.01}}},
                       {"camera", {{"position", {0.5, 0.5, 2.0}}, {"look_at", {0.5, 0.5, 0}}, {"up", {0, 1, 0}},
                                   {"fov", 24}, {"width", 16}, {"height", 16}}},  // the floor only, not the mirror
                       {"patches", {{"max_edge", 0.1}}}};
    json with_mirror = base, unfolded = base;
    with_mirror["objects"] = {floor, mirror};
    with_mirror["lights"] = {spot({0.3, 0.5, 0.5}, {-0.6, 0.1, -0.5})};  // at the mirror, down
    unfolded["objects"] = {floor};
    unfolded["lights"] = {spot({0.3, 0.5, 0.5}, {-0.6, 0.1, -0.5}), spot({-0.3, 0.5, 0.5}, {0.6, 0.1, -0.5})};
    const tprf::RenderResult a = expect_same_light(with_mirror, unfolded, "spot in a mirror vs its image");
    // The cones light part of the floor and leave part of it dark: the test compares light and shade.
    const tprf::FloatArray& s = array(a, "steady");
    const std::ptrdiff_t lit = std::count_if(s.data.begin(), s.data.end(), [](float v) { return v > 0.0f; });
    MEASURED("spot in a mirror: %td of %zu pixel channels lit\n", lit, s.data.size());
    EXPECT_GT(lit, std::ptrdiff_t(s.data.size() / 10));
    EXPECT_LT(lit, std::ptrdiff_t(s.data.size() * 9 / 10));
}

}  // namespace

namespace {

// Channel c of `tinted` against channel c of greys[c], relative to the largest value of the channel.
double channel_difference(const tprf::FloatArray& tinted, const std::array<const tprf::FloatArray*, 3>& greys, int c) {
    double diff = 0.0, top = 0.0;
    for (std::size_t k = std::size_t(c); k < tinted.data.size(); k += 3) {
        diff = std::max(diff, double(std::abs(tinted.data[k] - greys[std::size_t(c)]->data[k])));
        top = std::max(top, double(std::abs(greys[std::size_t(c)]->data[k])));
    }
    EXPECT_GT(top, 0.0);
    return diff / top;
}

// A render of `scene` whose specular object `object` has `material` with reflectance `tint` is, channel by
// channel, the render of the same scene with the grey reflectance of that channel: the channels of light
// never mix (links, lights' images, the camera's rays, the steady solve and the film each carry the tint).
void expect_channels_of_greys(json scene, std::size_t object, json material, const std::array<double, 3>& tint,
                              const char* what) {
    material["reflectance"] = tint;
    scene["objects"][object]["material"] = material;
    const tprf::RenderResult tinted = render(scene);
    std::array<tprf::RenderResult, 3> greys;
    for (std::size_t c = 0; c < 3; ++c) {
        material["reflectance"] = tint[c];
        scene["objects"][object]["material"] = material;
        greys[c] = render(scene);
    }
    for (const char* name : {"transient", "steady"}) {
        const std::array<const tprf::FloatArray*, 3> g{&array(greys[0], name), &array(greys[1], name), &array(greys[2], name)};
        double worst = 0.0;
        for (int c = 0; c < 3; ++c) worst = std::max(worst, channel_difference(array(tinted, name), g, c));
        MEASURED("%s, %s: channels %.3g of each channel's peak from the grey renders\n", what, name, worst);
        EXPECT_LT(worst, 1e-5) << what << " " << name;
    }
    // The test can fail: the greys differ from each other far more than the tolerance (a tint taken as
    // its mean reflectance would be off by about that much in the red and blue channels).
    const double spread = relative_difference(array(greys[0], "steady"), array(greys[2], "steady"));
    MEASURED("%s: the red and blue greys' steady images differ by %.3g of the peak\n", what, spread);
    EXPECT_GT(spread, 1e-2) << what;
}

// The closed box with a gold-like mirror wall: light through one and several reflections, lights' images,
// and a camera that sees the mirror.
TEST(Materials, ATintedMirrorRendersEachChannelAsAGreyMirrorOfThatChannelsReflectance) {
    json box = {{"time", {{"bins", 60}, {"bin_width", 0.1}}},
                {"camera", camera_at({0.95, 0.5, 0.5}, {0, 0.5, 0.5}, 12)},
                {"patches", {{"max_edge", 0.2}}},
                {"lights", {point_light({0.7, 0.4, 0.8})}}};
    box["objects"] = box_walls(0, 1, 0.5);
    box["objects"].push_back(specular({0, 0, 0}, {0, 1, 0}, {0, 0, 1}, kPerfectMirror));
    expect_channels_of_greys(box, 5, {{"type", "mirror"}}, {0.9, 0.55, 0.2}, "tinted mirror box");
}

// Tinted glass (reflectance only; its transmittance is grey) in front of a lit plate, the light between:
// the camera sees the plate through it and the light's and the plate's images in it.
TEST(Materials, TintedGlassReflectsEachChannelAsGreyGlassOfThatChannelsReflectance) {
    json scene = {{"time", {{"bins", 120}, {"bin_width", 0.05}}},
                  {"camera", {{"position", {0.2, 0.1, 2.5}}, {"look_at", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov", 50},
                              {"width", 12}, {"height", 12}}},
                  {"patches", {{"max_edge", 0.25}}},
                  {"lights", {point_light({0.3, -0.2, 0.5})}}};
    scene["objects"] = {rect({-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, 0.6),
                        specular({-2, -2, 1}, {4, 0, 0}, {0, 4, 0}, kPerfectMirror)};
    expect_channels_of_greys(scene, 1, {{"type", "glass"}, {"transmittance", 0.4}}, {0.5, 0.3, 0.1}, "tinted glass");
}

}  // namespace
