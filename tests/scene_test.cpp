#include "tprf/core/error.h"
#include "tprf/scene/parse_json.h"

#include "test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using tprf::Vec3;

struct TempDir : tprf::test::MeshDir {
    TempDir() : tprf::test::MeshDir("tprf_scene_test_") {}
};

// The reference example, with a mesh file that the test writes.
json spec_scene() {
    return json::parse(R"({
      "time":    {"bins": 600, "bin_width": 0.01, "start": 0.0, "unit": "m"},
      "camera":  {"position": [2, 0.5, 0.5], "look_at": [0, 0.5, 0.3], "up": [0, 0, 1],
                  "fov": 40, "width": 64, "height": 48, "spp": 4},
      "lights":  [{"type": "point", "position": [0.6, 0.5, 0.6], "intensity": 1.0},
                  {"type": "laser", "origin": [2, 0.5, 1], "target": [0, 0.5, 0.5], "power": 1.0}],
      "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0],
                   "albedo": 0.5},
                  {"type": "mesh", "file": "meshes/tri.obj",
                   "transform": {"translate": [0.5, 0.5, 0], "scale": 0.3,
                                 "rotate": {"axis": [0, 0, 1], "angle": 90}},
                   "albedo": [0.7, 0.6, 0.5], "emission": [0, 0, 2], "two_sided": true}],
      "patches": {"max_edge": 0.05}
    })");
}

// A valid gates exposure for the reference scene's window (600 bins of 0.01 m), with `changes` applied.
json gates(const json& changes = json::object()) {
    json g = {{"type", "gates"}, {"start", 0.0}, {"width", 0.05}, {"step", 0.05}, {"count", 40}};
    g.update(changes);
    return g;
}

Vec3 apply(const Eigen::Matrix4d& m, const Vec3& p) { return (m * p.homogeneous()).head<3>(); }

}  // namespace

TEST(Scene, SpecExampleParsesToItsValues) {
    TempDir dir;
    json j = spec_scene();
    j["solver"] = {{"max_bounces", 3}, {"delay", "nearest"}, {"bounces", true}};
    // The reference sensor example.
    j["sensor"] = json::parse(R"({"pulse": {"shape": "gaussian", "fwhm": 0.03},
        "exposure": {"type": "gates", "start": 0.0, "width": 0.05, "step": 0.05, "count": 40},
        "noise": {"sigma": 0.001, "seed": 7}, "clamp": true})");
    const fs::path file = dir.path / "scene.json";
    std::ofstream(file) << j.dump(2);
    const tprf::Scene s = tprf::load_scene(file);

    EXPECT_EQ(s.file, file);
    EXPECT_EQ(s.time.bins, 600);
    EXPECT_EQ(s.time.bin_width, 0.01);
    EXPECT_EQ(s.time.unit, tprf::TimeUnit::Metres);
    EXPECT_EQ(s.time.bin_width_m(), 0.01);

    ASSERT_TRUE(s.camera.has_value());
    EXPECT_EQ(s.camera->position, Vec3(2, 0.5, 0.5));
    EXPECT_EQ(s.camera->look_at, Vec3(0, 0.5, 0.3));
    EXPECT_EQ(s.camera->up, Vec3(0, 0, 1));
    EXPECT_EQ(s.camera->fov_deg, 40.0);
    EXPECT_EQ(s.camera->width, 64);
    EXPECT_EQ(s.camera->height, 48);
    EXPECT_EQ(s.camera->spp, 4);
    EXPECT_FALSE(s.camera->unwarp);

    ASSERT_EQ(s.lights.size(), 2u);
    const auto& point = std::get<tprf::PointLight>(s.lights[0]);
    EXPECT_EQ(point.position, Vec3(0.6, 0.5, 0.6));
    EXPECT_TRUE((point.intensity == 1.0).all());
    const auto& laser = std::get<tprf::Laser>(s.lights[1]);
    EXPECT_EQ(laser.origin, Vec3(2, 0.5, 1));
    // target - origin = (-2, 0, -0.5), |.| = sqrt(4.25); 1e-15 is a few ulps of a unit vector.
    EXPECT_NEAR((laser.direction - Vec3(-2, 0, -0.5) / std::sqrt(4.25)).norm(), 0.0, 1e-15);
    EXPECT_TRUE((laser.power == 1.0).all());

    ASSERT_EQ(s.objects.size(), 2u);
    const tprf::Object& rect = s.objects[0];
    EXPECT_EQ(rect.json_path, "objects[0]");
    const auto& r = std::get<tprf::RectangleShape>(rect.shape);
    EXPECT_EQ(r.origin, Vec3(0, 0, 0));
    EXPECT_EQ(r.u, Vec3(1, 0, 0));
    EXPECT_EQ(r.v, Vec3(0, 1, 0));
    EXPECT_TRUE((rect.albedo == 0.5).all());
    EXPECT_TRUE((rect.emission == 0.0).all());
    EXPECT_FALSE(rect.two_sided);

    const tprf::Object& mesh = s.objects[1];
    EXPECT_EQ(mesh.json_path, "objects[1]");
    const auto& m = std::get<tprf::MeshShape>(mesh.shape);
    EXPECT_EQ(m.file, dir.path / "meshes" / "tri.obj");
    // Scale 0.3 takes (1,0,0) to (0.3,0,0); 90 degrees about z to (0,0.3,0); translate to (0.5,0.8,0).
    // cos(pi/2) is 6e-17 in doubles, hence 1e-12.
    EXPECT_NEAR((apply(m.transform, Vec3(1, 0, 0)) - Vec3(0.5, 0.8, 0)).norm(), 0.0, 1e-12);
    EXPECT_NEAR((apply(m.transform, Vec3(0, 0, 1)) - Vec3(0.5, 0.5, 0.3)).norm(), 0.0, 1e-12);
    EXPECT_EQ(m.transform.row(3), Eigen::RowVector4d(0, 0, 0, 1));
    EXPECT_EQ(mesh.albedo.matrix(), Vec3(0.7, 0.6, 0.5));
    EXPECT_EQ(mesh.emission.matrix(), Vec3(0, 0, 2));
    EXPECT_TRUE(mesh.two_sided);

    EXPECT_EQ(s.max_edge, 0.05);
    EXPECT_EQ(s.solver.max_bounces, 3);
    EXPECT_EQ(s.solver.delay, tprf::DelayMode::Nearest);
    EXPECT_TRUE(s.solver.bounces);
    ASSERT_TRUE(s.sensor.has_value());
    EXPECT_EQ(s.sensor->pulse.shape, tprf::PulseShape::Gaussian);
    EXPECT_EQ(s.sensor->pulse.fwhm, 0.03);
    EXPECT_EQ(s.sensor->exposure.type, tprf::ExposureType::Gates);
    ASSERT_EQ(s.sensor->exposure.windows.size(), 40u);
    EXPECT_DOUBLE_EQ(s.sensor->exposure.windows[39][0], 39 * 0.05);
    EXPECT_EQ(s.sensor->exposure.windows[39][1], 0.05);
    EXPECT_EQ(s.sensor->noise.sigma, 0.001);
    EXPECT_EQ(s.sensor->noise.seed, 7u);
    EXPECT_TRUE(s.sensor->clamp);
    EXPECT_EQ(s.sensor->json_path, "sensor");
}

TEST(Scene, OptionalBlocksTakeTheirDefaults) {
    TempDir dir;
    const tprf::Scene s = tprf::parse_scene(
        R"({"time": {"bins": 10, "bin_width": 0.1},
            "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]}]})",
        dir.path / "scene.json");
    EXPECT_EQ(s.time.start, 0.0);
    EXPECT_EQ(s.time.unit, tprf::TimeUnit::Metres);
    EXPECT_FALSE(s.camera.has_value());
    EXPECT_TRUE(s.lights.empty());
    ASSERT_EQ(s.objects.size(), 1u);
    EXPECT_TRUE((s.objects[0].albedo == 0.5).all());
    EXPECT_TRUE((s.objects[0].emission == 0.0).all());
    EXPECT_FALSE(s.objects[0].two_sided);
    EXPECT_EQ(s.max_edge, 0.0);
    EXPECT_EQ(s.solver.max_bounces, -1);
    EXPECT_EQ(s.solver.delay, tprf::DelayMode::Linear);
    EXPECT_FALSE(s.solver.bounces);
    EXPECT_FALSE(s.sensor.has_value());
}

TEST(Scene, CameraDefaultsToOneSampleAndNoUnwarp) {
    TempDir dir;
    json j = spec_scene();
    j["camera"].erase("spp");
    const tprf::Scene s = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    EXPECT_EQ(s.camera->spp, 1);
    EXPECT_FALSE(s.camera->unwarp);
    EXPECT_TRUE(s.camera->footprint);
    EXPECT_TRUE(s.camera->shift_second_bounce);
    j["camera"]["unwarp"] = true;
    j["camera"]["shift_second_bounce"] = false;
    const tprf::Scene t = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    EXPECT_TRUE(t.camera->unwarp);
    EXPECT_FALSE(t.camera->shift_second_bounce);
}

TEST(Scene, PicosecondsAreOpticalPathLength) {
    tprf::TimeAxis t;
    t.bins = 1;
    t.bin_width = 10.0;
    t.start = -5.0;
    t.unit = tprf::TimeUnit::Picoseconds;
    // 10 ps * c = 10e-12 s * 299792458 m/s = 0.00299792458 m; 1e-15 is rounding of the product.
    EXPECT_NEAR(t.bin_width_m(), 0.00299792458, 1e-15);
    EXPECT_NEAR(t.start_m(), -0.00149896229, 1e-15);
    EXPECT_NEAR(t.to_metres(1.0), 0.000299792458, 1e-16);

    TempDir dir;
    json j = spec_scene();
    j["time"] = {{"bins", 4}, {"bin_width", 10}, {"unit", "ps"}};
    const tprf::Scene s = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    EXPECT_EQ(s.time.unit, tprf::TimeUnit::Picoseconds);
    EXPECT_NEAR(s.time.bin_width_m(), 0.0029979, 1e-7);
}

TEST(Scene, RotateNinetyDegreesAboutZ) {
    TempDir dir;
    json j = spec_scene();
    j["objects"][1]["transform"] = {{"rotate", {{"axis", {0, 0, 2}}, {"angle", 90}}}};
    const tprf::Scene s = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    const auto& m = std::get<tprf::MeshShape>(s.objects[1].shape);
    // The axis is normalised, so its length 2 must not scale the result.
    EXPECT_NEAR((apply(m.transform, Vec3(1, 0, 0)) - Vec3(0, 1, 0)).norm(), 0.0, 1e-12);
    EXPECT_NEAR((apply(m.transform, Vec3(0, 0, 1)) - Vec3(0, 0, 1)).norm(), 0.0, 1e-12);
}

TEST(Scene, NonUniformScaleAndRowMajorMatrix) {
    TempDir dir;
    json j = spec_scene();
    j["objects"][1]["transform"] = {{"scale", {1, 2, 3}}, {"translate", {1, 0, 0}}};
    tprf::Scene s = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    EXPECT_EQ(apply(std::get<tprf::MeshShape>(s.objects[1].shape).transform, Vec3(1, 1, 1)), Vec3(2, 2, 3));

    // Scale before rotate: (1,0,0) -> (1,0,0) -> (0,1,0). Rotating first would give (0,2,0).
    j["objects"][1]["transform"] = {{"scale", {1, 2, 3}}, {"rotate", {{"axis", {0, 0, 1}}, {"angle", 90}}}};
    s = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    EXPECT_NEAR((apply(std::get<tprf::MeshShape>(s.objects[1].shape).transform, Vec3(1, 0, 0)) - Vec3(0, 1, 0)).norm(),
                0.0, 1e-12);

    j["objects"][1]["transform"] = {{"matrix", {2, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1, 3, 0, 0, 0, 1}}};
    s = tprf::parse_scene(j.dump(), dir.path / "scene.json");
    // Row-major: the translation is the last column, (1, 2, 3).
    EXPECT_EQ(apply(std::get<tprf::MeshShape>(s.objects[1].shape).transform, Vec3(1, 1, 1)), Vec3(3, 3, 4));
}

TEST(Scene, AbsoluteMeshPathIsKept) {
    TempDir dir;
    json j = spec_scene();
    const fs::path abs = dir.path / "meshes" / "tri.obj";
    j["objects"][1]["file"] = abs.string();
    const tprf::Scene s = tprf::parse_scene(j.dump(), "/nonexistent/elsewhere/scene.json");
    EXPECT_EQ(std::get<tprf::MeshShape>(s.objects[1].shape).file, abs);
}

TEST(Scene, UnreadableMeshFileIsAnError) {
    TempDir dir;
    const fs::path mesh = dir.path / "meshes" / "tri.obj";
    // Permission bits do not stop root (CI runs as root), but a write-only sysctl file cannot be read
    // by anyone: the mesh path becomes a link to it.
    const fs::path unreadable = "/proc/sys/vm/drop_caches";
    if (!fs::exists(unreadable) || std::ifstream(unreadable)) GTEST_SKIP() << unreadable << " is missing or readable here";
    fs::remove(mesh);
    fs::create_symlink(unreadable, mesh);
    try {
        tprf::parse_scene(spec_scene().dump(), dir.path / "scene.json");
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        EXPECT_NE(std::string(e.what()).find("objects[1].file: cannot read mesh file"), std::string::npos)
            << e.what();
        EXPECT_NE(std::string(e.what()).find(": Permission denied"), std::string::npos) << e.what();
    }
}

TEST(Scene, MeshPathThatIsAFolderIsAnError) {
    TempDir dir;
    const fs::path mesh = dir.path / "meshes" / "tri.obj";
    fs::remove(mesh);
    fs::create_directory(mesh);
    try {
        tprf::parse_scene(spec_scene().dump(), dir.path / "scene.json");
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        EXPECT_NE(std::string(e.what()).find("objects[1].file: "), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("is not a regular file"), std::string::npos) << e.what();
    }
}

TEST(Scene, MissingRelativeMeshFileNamesTheSceneFolder) {
    TempDir dir;
    json j = spec_scene();
    j["objects"][1]["file"] = "meshes/absent.obj";
    try {
        tprf::parse_scene(j.dump(), dir.path / "scene.json");
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        EXPECT_EQ(std::string(e.what()), (dir.path / "scene.json").string() +
                                             ": objects[1].file: mesh file meshes/absent.obj does not exist "
                                             "(relative to " + dir.path.string() + ")");
    }
    // An absolute name is given as it stands.
    j["objects"][1]["file"] = (dir.path / "absent.obj").string();
    try {
        tprf::parse_scene(j.dump(), "scene.json");
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        EXPECT_EQ(std::string(e.what()),
                  "scene.json: objects[1].file: mesh file " + (dir.path / "absent.obj").string() + " does not exist");
    }
}

TEST(Scene, MissingSceneFileIsAnError) {
    TempDir dir;
    const fs::path file = dir.path / "absent.json";
    try {
        tprf::load_scene(file);
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        EXPECT_EQ(std::string(e.what()), file.string() + ": cannot read scene file: No such file or directory");
    }
}

TEST(Scene, MessageIsFilePathWhat) {
    TempDir dir;
    json j = spec_scene();
    j["objects"][0]["albedo"] = 1.5;
    const fs::path file = dir.path / "scene.json";
    try {
        tprf::parse_scene(j.dump(), file);
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        EXPECT_EQ(std::string(e.what()), file.string() + ": objects[0].albedo: must be in [0, 1]");
    }
}

TEST(Scene, MalformedJsonGivesLineAndColumn) {
    try {
        tprf::parse_scene("{\n  \"time\": {\"bins\": 1,,\n}", "scene.json");
        FAIL() << "expected tprf::Error";
    } catch (const tprf::Error& e) {
        // The second comma is the 22nd character of line 2.
        EXPECT_NE(std::string(e.what()).find("scene.json: line 2, column 22: malformed JSON"), std::string::npos)
            << e.what();
    }
}

namespace {

struct BadCase {
    const char* name;
    std::function<void(json&)> edit;  // applied to spec_scene(); unused when `raw` is set
    const char* raw;                   // literal scene text, for JSON that nlohmann cannot hold
    std::vector<std::string> expect;   // substrings of the message
};

std::vector<BadCase> bad_cases() {
    auto edit = [](const char* name, std::function<void(json&)> f, std::vector<std::string> expect) {
        return BadCase{name, std::move(f), nullptr, std::move(expect)};
    };
    auto raw = [](const char* name, const char* text, std::vector<std::string> expect) {
        return BadCase{name, nullptr, text, std::move(expect)};
    };
    return {
        raw("malformed: trailing comma", "{\"time\": {\"bins\": 1,}}", {"line 1", "column", "malformed JSON"}),
        raw("malformed: truncated", "{\n\"time\": {", {"line 2", "column"}),
        raw("malformed: NaN literal", "{\"time\": {\"bins\": NaN}}", {"line 1", "column"}),
        raw("non-finite: 1e999", "{\"time\": {\"bins\": 1,\n \"bin_width\": 1e999}}", {"line 2", "column 15"}),
        raw("top level is an array", "[1, 2]", {"top level must be a JSON object"}),
        edit("unknown top-level key", [](json& s) { s["frobnicate"] = 1; }, {"frobnicate: unknown key"}),
        edit("unknown key in time", [](json& s) { s["time"]["bin"] = 1; }, {"time.bin: unknown key"}),
        edit("unknown key in camera", [](json& s) { s["camera"]["focal"] = 1; }, {"camera.focal: unknown key"}),
        edit("unknown key in point light", [](json& s) { s["lights"][0]["power"] = 1; },
             {"lights[0].power: unknown key"}),
        edit("unknown key in laser", [](json& s) { s["lights"][1]["intensity"] = 1; },
             {"lights[1].intensity: unknown key"}),
        edit("unknown key in rectangle", [](json& s) { s["objects"][0]["file"] = "x"; },
             {"objects[0].file: unknown key"}),
        edit("unknown key in mesh", [](json& s) { s["objects"][1]["u"] = {1, 0, 0}; }, {"objects[1].u: unknown key"}),
        edit("unknown key in transform", [](json& s) { s["objects"][1]["transform"]["shear"] = 1; },
             {"objects[1].transform.shear: unknown key"}),
        edit("unknown key in rotate", [](json& s) { s["objects"][1]["transform"]["rotate"]["degrees"] = 1; },
             {"objects[1].transform.rotate.degrees: unknown key"}),
        edit("unknown key in patches", [](json& s) { s["patches"]["max_area"] = 1; },
             {"patches.max_area: unknown key"}),
        edit("unknown key in solver", [](json& s) { s["solver"] = {{"bounce", 1}}; }, {"solver.bounce: unknown key"}),
        edit("string for a number", [](json& s) { s["time"]["bins"] = "600"; }, {"time.bins: expected a number"}),
        edit("vector of length 2", [](json& s) { s["camera"]["position"] = {1, 2}; },
             {"camera.position: expected an array of 3"}),
        edit("vector element not a number", [](json& s) { s["objects"][0]["u"] = {1, "0", 0}; },
             {"objects[0].u[1]: expected a number"}),
        edit("colour of length 4", [](json& s) { s["objects"][0]["albedo"] = {0.1, 0.2, 0.3, 0.4}; },
             {"objects[0].albedo: expected a number or an array of 3"}),
        edit("bool as number", [](json& s) { s["objects"][0]["two_sided"] = 1; },
             {"objects[0].two_sided: expected true or false"}),
        edit("unwarp as string", [](json& s) { s["camera"]["unwarp"] = "yes"; }, {"camera.unwarp: expected true"}),
        edit("shift as number", [](json& s) { s["camera"]["shift_second_bounce"] = 1; },
             {"camera.shift_second_bounce: expected true"}),
        edit("unit not a string", [](json& s) { s["time"]["unit"] = 1; }, {"time.unit: expected a string"}),
        edit("time not an object", [](json& s) { s["time"] = 5; }, {"time: expected an object"}),
        edit("lights not an array", [](json& s) { s["lights"] = json::object(); }, {"lights: expected an array"}),
        edit("light not an object", [](json& s) { s["lights"][0] = 3; }, {"lights[0]: expected an object"}),
        edit("objects not an array", [](json& s) { s["objects"] = 1; }, {"objects: expected an array"}),
        edit("objects empty", [](json& s) { s["objects"] = json::array(); }, {"objects: must hold at least one"}),
        edit("albedo above 1", [](json& s) { s["objects"][0]["albedo"] = 1.01; },
             {"objects[0].albedo: must be in [0, 1]"}),
        edit("albedo component below 0", [](json& s) { s["objects"][1]["albedo"] = {0.5, -0.1, 0.5}; },
             {"objects[1].albedo: must be in [0, 1]"}),
        edit("negative intensity", [](json& s) { s["lights"][0]["intensity"] = -1; },
             {"lights[0].intensity: must be >= 0"}),
        edit("negative power", [](json& s) { s["lights"][1]["power"] = {1, -1, 1}; }, {"lights[1].power: must be >= 0"}),
        edit("negative emission", [](json& s) { s["objects"][0]["emission"] = -0.5; },
             {"objects[0].emission: must be >= 0"}),
        edit("zero-length u", [](json& s) { s["objects"][0]["u"] = {0, 0, 0}; }, {"objects[0].u: has zero length"}),
        edit("zero-length v", [](json& s) { s["objects"][0]["v"] = {0, 0, 0}; }, {"objects[0].v: has zero length"}),
        edit("parallel u and v", [](json& s) { s["objects"][0]["v"] = {-2, 0, 0}; },
             {"objects[0].v: is parallel to u"}),
        edit("zero scale", [](json& s) { s["objects"][1]["transform"]["scale"] = 0; },
             {"objects[1].transform.scale: must not be 0"}),
        edit("zero scale component", [](json& s) { s["objects"][1]["transform"]["scale"] = {1, 0, 1}; },
             {"objects[1].transform.scale: must not be 0"}),
        edit("scale of wrong length", [](json& s) { s["objects"][1]["transform"]["scale"] = {1, 1}; },
             {"objects[1].transform.scale: expected an array of 3"}),
        edit("zero rotate axis", [](json& s) { s["objects"][1]["transform"]["rotate"]["axis"] = {0, 0, 0}; },
             {"objects[1].transform.rotate.axis: has zero length"}),
        edit("rotate without angle", [](json& s) { s["objects"][1]["transform"]["rotate"].erase("angle"); },
             {"objects[1].transform.rotate: missing key \"angle\""}),
        edit("matrix of 15 numbers",
             [](json& s) { s["objects"][1]["transform"] = {{"matrix", std::vector<double>(15, 1.0)}}; },
             {"objects[1].transform.matrix: expected an array of 16"}),
        edit("singular matrix",
             [](json& s) {
                 s["objects"][1]["transform"] = {{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1}}};
             },
             {"objects[1].transform.matrix: is singular"}),
        edit("matrix with projective last row",
             [](json& s) {
                 s["objects"][1]["transform"] = {{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1}}};
             },
             {"objects[1].transform.matrix: last row must be 0 0 0 1"}),
        edit("matrix combined with translate",
             [](json& s) {
                 s["objects"][1]["transform"] = {{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}},
                                                 {"translate", {0, 0, 1}}};
             },
             {"objects[1].transform: \"matrix\" cannot be combined"}),
        edit("missing mesh file", [](json& s) { s["objects"][1]["file"] = "meshes/absent.obj"; },
             {"objects[1].file: mesh file meshes/absent.obj does not exist (relative to /"}),
        edit("mesh file is a directory", [](json& s) { s["objects"][1]["file"] = "meshes"; },
             {"objects[1].file: mesh file", "not a regular file"}),
        edit("bins zero", [](json& s) { s["time"]["bins"] = 0; }, {"time.bins: must be > 0"}),
        edit("bins negative", [](json& s) { s["time"]["bins"] = -3; }, {"time.bins: must be > 0"}),
        edit("bins not an integer", [](json& s) { s["time"]["bins"] = 10.5; }, {"time.bins: expected an integer"}),
        // Whole numbers that do not fit an int are refused where they stand, not wrapped or clamped.
        edit("bins just above int", [](json& s) { s["time"]["bins"] = 2147483648.0; }, {"time.bins: integer out of range"}),
        edit("bins just below int", [](json& s) { s["time"]["bins"] = -2147483649.0; }, {"time.bins: integer out of range"}),
        edit("camera width above int", [](json& s) { s["camera"]["width"] = 1e10; }, {"camera.width: integer out of range"}),
        edit("camera height far above int", [](json& s) { s["camera"]["height"] = 1e300; },
             {"camera.height: integer out of range"}),
        edit("spp above int", [](json& s) { s["camera"]["spp"] = 4294967296.0; }, {"camera.spp: integer out of range"}),
        edit("max_bounces above int", [](json& s) { s["solver"] = {{"max_bounces", 1e10}}; },
             {"solver.max_bounces: integer out of range"}),
        edit("gate count above int", [](json& s) { s["sensor"] = {{"exposure", gates({{"count", 3e9}})}}; },
             {"sensor.exposure.count: integer out of range"}),
        edit("bin_width zero", [](json& s) { s["time"]["bin_width"] = 0; }, {"time.bin_width: must be > 0"}),
        edit("bin_width negative", [](json& s) { s["time"]["bin_width"] = -0.01; }, {"time.bin_width: must be > 0"}),
        edit("unknown time unit", [](json& s) { s["time"]["unit"] = "ns"; }, {"time.unit: unknown time unit \"ns\""}),
        edit("camera width zero", [](json& s) { s["camera"]["width"] = 0; }, {"camera.width: must be > 0"}),
        edit("camera height negative", [](json& s) { s["camera"]["height"] = -4; }, {"camera.height: must be > 0"}),
        edit("camera width not an integer", [](json& s) { s["camera"]["width"] = 64.5; },
             {"camera.width: expected an integer"}),
        edit("camera spp zero", [](json& s) { s["camera"]["spp"] = 0; }, {"camera.spp: must be > 0"}),
        edit("fov zero", [](json& s) { s["camera"]["fov"] = 0; }, {"camera.fov: must be in (0, 180)"}),
        edit("fov 180", [](json& s) { s["camera"]["fov"] = 180; }, {"camera.fov: must be in (0, 180)"}),
        edit("position equals look_at", [](json& s) { s["camera"]["look_at"] = {2, 0.5, 0.5}; },
             {"camera.look_at: equals camera.position"}),
        edit("up parallel to view", [](json& s) { s["camera"]["up"] = {-2, 0, -0.2}; },
             {"camera.up: is parallel to the view direction"}),
        edit("laser direction zero",
             [](json& s) {
                 s["lights"][1].erase("target");
                 s["lights"][1]["direction"] = {0, 0, 0};
             },
             {"lights[1].direction: has zero length"}),
        edit("laser target equals origin", [](json& s) { s["lights"][1]["target"] = {2, 0.5, 1}; },
             {"lights[1].target: equals origin"}),
        edit("laser with direction and target", [](json& s) { s["lights"][1]["direction"] = {1, 0, 0}; },
             {"lights[1]: give either"}),
        edit("laser with neither", [](json& s) { s["lights"][1].erase("target"); },
             {"lights[1]: missing key \"direction\" or \"target\""}),
        edit("max_edge zero", [](json& s) { s["patches"]["max_edge"] = 0; }, {"patches.max_edge: must be > 0"}),
        edit("max_edge negative", [](json& s) { s["patches"]["max_edge"] = -0.1; }, {"patches.max_edge: must be > 0"}),
        edit("negative time_bins", [](json& s) { s["links"] = {{"time_bins", -1}}; },
             {"links.time_bins: must be >= 0"}),
        edit("time_bins not a number", [](json& s) { s["links"] = {{"time_bins", "4"}}; },
             {"links.time_bins: expected a number"}),
        edit("spread_pieces above 8", [](json& s) { s["links"] = {{"spread_pieces", 9}}; },
             {"links.spread_pieces: must be an integer in [0, 8]"}),
        edit("negative spread_pieces", [](json& s) { s["links"] = {{"spread_pieces", -1}}; },
             {"links.spread_pieces: must be an integer in [0, 8]"}),
        edit("fractional spread_pieces", [](json& s) { s["links"] = {{"spread_pieces", 2.5}}; },
             {"links.spread_pieces: expected an integer"}),
        edit("unknown light type", [](json& s) { s["lights"][0]["type"] = "flash"; },
             {"lights[0].type: unknown light type \"flash\" (expected \"point\", \"spot\" or \"laser\")"}),
        edit("unknown object type", [](json& s) { s["objects"][0]["type"] = "sphere"; },
             {"objects[0].type: unknown object type \"sphere\""}),
        edit("missing object type", [](json& s) { s["objects"][0].erase("type"); },
             {"objects[0]: missing key \"type\""}),
        edit("missing u", [](json& s) { s["objects"][0].erase("u"); }, {"objects[0]: missing key \"u\""}),
        edit("missing mesh file key", [](json& s) { s["objects"][1].erase("file"); },
             {"objects[1]: missing key \"file\""}),
        edit("missing time", [](json& s) { s.erase("time"); }, {"scene.json: missing key \"time\""}),
        edit("missing objects", [](json& s) { s.erase("objects"); }, {"scene.json: missing key \"objects\""}),
        edit("missing bins", [](json& s) { s["time"].erase("bins"); }, {"time: missing key \"bins\""}),
        edit("missing fov", [](json& s) { s["camera"].erase("fov"); }, {"camera: missing key \"fov\""}),
        edit("missing light position", [](json& s) { s["lights"][0].erase("position"); },
             {"lights[0]: missing key \"position\""}),
        edit("missing power", [](json& s) { s["lights"][1].erase("power"); }, {"lights[1]: missing key \"power\""}),
        edit("max_bounces negative", [](json& s) { s["solver"] = {{"max_bounces", -1}}; },
             {"solver.max_bounces: must be >= 0"}),
        edit("max_bounces below -1", [](json& s) { s["solver"] = {{"max_bounces", -2}}; },
             {"solver.max_bounces: must be >= 0"}),
        edit("max_bounces not an integer", [](json& s) { s["solver"] = {{"max_bounces", 2.5}}; },
             {"solver.max_bounces: expected an integer"}),
        edit("unknown delay mode", [](json& s) { s["solver"] = {{"delay", "cubic"}}; },
             {"solver.delay: unknown delay mode \"cubic\""}),
        edit("bounces not a bool", [](json& s) { s["solver"] = {{"bounces", "yes"}}; },
             {"solver.bounces: expected true or false"}),
        edit("sensor not an object", [](json& s) { s["sensor"] = {1, 2}; }, {"sensor: expected an object"}),
        edit("sensor without exposure", [](json& s) { s["sensor"] = {{"clamp", true}}; },
             {"sensor: missing key \"exposure\""}),
        edit("sensor unknown key", [](json& s) { s["sensor"] = {{"exposure", gates()}, {"gain", 2}}; },
             {"sensor.gain: unknown key"}),
        edit("unknown pulse shape", [](json& s) { s["sensor"] = {{"exposure", gates()}, {"pulse", {{"shape", "sinc"}}}}; },
             {"sensor.pulse.shape: unknown pulse shape \"sinc\""}),
        edit("gaussian without fwhm", [](json& s) { s["sensor"] = {{"exposure", gates()}, {"pulse", {{"shape", "gaussian"}}}}; },
             {"sensor.pulse: missing key \"fwhm\""}),
        edit("box width zero",
             [](json& s) { s["sensor"] = {{"exposure", gates()}, {"pulse", {{"shape", "box"}, {"width", 0}}}}; },
             {"sensor.pulse.width: must be > 0"}),
        edit("pulse table missing",
             [](json& s) { s["sensor"] = {{"exposure", gates()}, {"pulse", {{"shape", "table"}, {"file", "nope.csv"}}}}; },
             {"sensor.pulse.file: cannot read pulse table"}),
        edit("gate width negative", [](json& s) { s["sensor"] = {{"exposure", gates({{"width", -1}})}}; },
             {"sensor.exposure.width: must be > 0"}),
        edit("gate count zero", [](json& s) { s["sensor"] = {{"exposure", gates({{"count", 0}})}}; },
             {"sensor.exposure.count: must be > 0"}),
        edit("gates outside the window", [](json& s) { s["sensor"] = {{"exposure", gates({{"start", 100.0}})}}; },
             {"sensor.exposure: every gate lies outside the render's time window"}),
        edit("unknown exposure", [](json& s) { s["sensor"] = {{"exposure", {{"type", "streak"}}}}; },
             {"sensor.exposure.type: unknown exposure type \"streak\""}),
        edit("window not a pair",
             [](json& s) { s["sensor"] = {{"exposure", {{"type", "windows"}, {"windows", {{0.1, 0.2, 0.3}}}}}}; },
             {"sensor.exposure.windows[0]: expected [start, width]"}),
        edit("amcw phases degenerate",
             [](json& s) {
                 s["sensor"] = {{"exposure", {{"type", "amcw"}, {"frequency_mhz", 20}, {"phases_deg", {0, 180}}}}};
             },
             {"sensor.exposure.phases_deg: needs at least 3 phases"}),
        edit("amcw frequency zero",
             [](json& s) { s["sensor"] = {{"exposure", {{"type", "amcw"}, {"frequency_mhz", 0}}}}; },
             {"sensor.exposure.frequency_mhz: must be > 0"}),
        edit("spad without photons", [](json& s) { s["sensor"] = {{"exposure", {{"type", "spad"}}}}; },
             {"sensor.exposure: missing key \"photons\""}),
        edit("spad with noise",
             [](json& s) {
                 s["sensor"] = {{"exposure", {{"type", "spad"}, {"photons", 10}}}, {"noise", {{"sigma", 1}}}};
             },
             {"sensor.noise: a SPAD counts photons"}),
        edit("noise sigma negative", [](json& s) { s["sensor"] = {{"exposure", gates()}, {"noise", {{"sigma", -1}}}}; },
             {"sensor.noise.sigma: must be >= 0"}),
        edit("noise seed negative",
             [](json& s) { s["sensor"] = {{"exposure", gates()}, {"noise", {{"sigma", 1}, {"seed", -3}}}}; },
             {"sensor.noise.seed: must be an integer"}),
        edit("pulse far longer than the window",
             [](json& s) { s["sensor"] = {{"exposure", gates()}, {"pulse", {{"shape", "gaussian"}, {"fwhm", 1000}}}}; },
             {"sensor.pulse.fwhm: reaches"}),
        edit("spad jitter far longer than the window",
             [](json& s) { s["sensor"] = {{"exposure", {{"type", "spad"}, {"photons", 1}, {"jitter_fwhm", 1e300}}}}; },
             {"sensor.exposure.jitter_fwhm: reaches"}),
        edit("clamp not a bool", [](json& s) { s["sensor"] = {{"exposure", gates()}, {"clamp", 1}}; },
             {"sensor.clamp: expected true or false"}),
    };
}

}  // namespace

TEST(Scene, BadInputNamesThePath) {
    TempDir dir;
    const fs::path file = dir.path / "scene.json";
    for (const BadCase& c : bad_cases()) {
        SCOPED_TRACE(c.name);
        std::string text;
        if (c.raw) {
            text = c.raw;
        } else {
            json j = spec_scene();
            c.edit(j);
            text = j.dump();
        }
        try {
            tprf::parse_scene(text, file);
            ADD_FAILURE() << "no error for: " << text;
        } catch (const tprf::Error& e) {
            const std::string msg = e.what();
            EXPECT_EQ(msg.rfind(file.string() + ": ", 0), 0u) << msg;
            for (const std::string& part : c.expect) EXPECT_NE(msg.find(part), std::string::npos) << msg;
        }
    }
}
