// validate() checks a Scene however it was built. A Scene built in C++ with one mistake gets exactly the
// message the JSON parser gives for the same mistake written in a scene file; what JSON cannot write
// (NaN, infinity, a direction that is not a unit vector) is caught too, naming the path.
#include "tprf/scene/validate.h"

#include "tprf/core/error.h"
#include "tprf/scene/parse_json.h"

#include "test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using tprf::Rgb;
using tprf::Scene;
using tprf::Vec3;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

struct TempDir : tprf::test::MeshDir {
    TempDir() : tprf::test::MeshDir("tprf_validate_test_") {}
};

// One scene written as JSON ...
json base_json() {
    return json::parse(R"({
      "time":    {"bins": 100, "bin_width": 0.01, "start": 0.0, "unit": "m"},
      "camera":  {"position": [2, 0.5, 0.5], "look_at": [0, 0.5, 0.5], "up": [0, 0, 1],
                  "fov": 40, "width": 8, "height": 6, "spp": 2},
      "lights":  [{"type": "point", "position": [0.6, 0.5, 0.6], "intensity": 1.0},
                  {"type": "laser", "origin": [2, 0.5, 1], "direction": [-1, 0, 0], "power": [1, 2, 3]}],
      "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "albedo": 0.5},
                  {"type": "mesh", "file": "meshes/tri.obj",
                   "transform": {"matrix": [1, 0, 0, 0.5, 0, 1, 0, 0.5, 0, 0, 1, 0, 0, 0, 0, 1]},
                   "albedo": [0.7, 0.6, 0.5], "emission": [0, 0, 2]}],
      "patches": {"max_edge": 0.1},
      "solver":  {"max_bounces": 3},
      "sensor":  {"pulse": {"shape": "gaussian", "fwhm": 0.03},
                  "exposure": {"type": "gates", "start": 0.0, "width": 0.05, "step": 0.05, "count": 4},
                  "noise": {"sigma": 0.001, "seed": 7}}
    })");
}

// ... and built by hand, in `dir` (where the JSON's scene file would be).
Scene base_scene(const fs::path& dir) {
    Scene s;
    s.file = dir / "scene.json";
    s.time.bins = 100;
    s.time.bin_width = 0.01;
    tprf::Camera c;
    c.position = Vec3(2, 0.5, 0.5);
    c.look_at = Vec3(0, 0.5, 0.5);
    c.up = Vec3(0, 0, 1);
    c.fov_deg = 40;
    c.width = 8;
    c.height = 6;
    c.spp = 2;
    s.camera = c;
    s.lights.push_back(tprf::PointLight{Vec3(0.6, 0.5, 0.6), Rgb::Constant(1.0)});
    s.lights.push_back(tprf::Laser{Vec3(2, 0.5, 1), Vec3(-1, 0, 0), Rgb(1, 2, 3)});
    tprf::Object rect;
    rect.shape = tprf::RectangleShape{Vec3::Zero(), Vec3(1, 0, 0), Vec3(0, 1, 0)};
    rect.json_path = "objects[0]";
    tprf::MeshShape mesh{dir / "meshes" / "tri.obj", Eigen::Matrix4d::Identity()};
    mesh.transform(0, 3) = 0.5;
    mesh.transform(1, 3) = 0.5;
    tprf::Object m;
    m.shape = mesh;
    m.albedo = Rgb(0.7, 0.6, 0.5);
    m.emission = Rgb(0, 0, 2);
    m.json_path = "objects[1]";
    s.objects = {rect, m};
    s.max_edge = 0.1;
    s.solver.max_bounces = 3;
    tprf::SensorSettings sensor;
    sensor.pulse.shape = tprf::PulseShape::Gaussian;
    sensor.pulse.fwhm = 0.03;
    for (int k = 0; k < 4; ++k) sensor.exposure.windows.push_back({0.0 + k * 0.05, 0.05});
    sensor.noise = {0.001, 7};
    sensor.file = s.file;
    sensor.json_path = "sensor";
    s.sensor = sensor;
    return s;
}

// The message of the tprf::Error that `f` throws, or a note that it threw none.
std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const tprf::Error& e) {
        return e.what();
    }
    return "(no error)";
}

tprf::Exposure& exposure(Scene& s) { return s.sensor->exposure; }

// Both forms of a SPAD exposure (10 photons per unit, no noise block).
void make_spad(Scene& s) {
    s.sensor->exposure = tprf::Exposure{};
    exposure(s).type = tprf::ExposureType::Spad;
    exposure(s).photons = 10;
    s.sensor->noise = {};
}
void make_spad(json& j) {
    j["sensor"]["exposure"] = {{"type", "spad"}, {"photons", 10}};
    j["sensor"].erase("noise");
}

// Both forms of a CW-ToF exposure at 20 MHz with the default phases.
void make_amcw(Scene& s) {
    s.sensor->exposure = tprf::Exposure{};
    exposure(s).type = tprf::ExposureType::Amcw;
    exposure(s).frequency_mhz = 20;
    exposure(s).phases_deg = {0, 90, 180, 270};
}
void make_amcw(json& j) { j["sensor"]["exposure"] = {{"type", "amcw"}, {"frequency_mhz", 20}}; }

// One mistake made in both forms, and the start of the message both must give after "FILE: ".
struct Twin {
    const char* name;
    std::function<void(Scene&)> scene;
    std::function<void(json&)> json;
    std::string expect;
};

// Mistakes of the scene outside its sensor block.
std::vector<Twin> scene_twins() {
    const Eigen::Matrix4d singular = Eigen::Vector4d(1, 1, 0, 1).asDiagonal();
    return {
        {"bins zero", [](Scene& s) { s.time.bins = 0; }, [](json& j) { j["time"]["bins"] = 0; }, "time.bins: must be > 0"},
        {"bins negative", [](Scene& s) { s.time.bins = -3; }, [](json& j) { j["time"]["bins"] = -3; }, "time.bins: must be > 0"},
        {"bin_width zero", [](Scene& s) { s.time.bin_width = 0; }, [](json& j) { j["time"]["bin_width"] = 0; },
         "time.bin_width: must be > 0"},
        {"bin_width negative", [](Scene& s) { s.time.bin_width = -0.01; }, [](json& j) { j["time"]["bin_width"] = -0.01; },
         "time.bin_width: must be > 0"},
        {"fov zero", [](Scene& s) { s.camera->fov_deg = 0; }, [](json& j) { j["camera"]["fov"] = 0; },
         "camera.fov: must be in (0, 180) degrees"},
        {"fov 180", [](Scene& s) { s.camera->fov_deg = 180; }, [](json& j) { j["camera"]["fov"] = 180; },
         "camera.fov: must be in (0, 180) degrees"},
        {"width zero", [](Scene& s) { s.camera->width = 0; }, [](json& j) { j["camera"]["width"] = 0; },
         "camera.width: must be > 0"},
        {"height negative", [](Scene& s) { s.camera->height = -4; }, [](json& j) { j["camera"]["height"] = -4; },
         "camera.height: must be > 0"},
        {"spp zero", [](Scene& s) { s.camera->spp = 0; }, [](json& j) { j["camera"]["spp"] = 0; }, "camera.spp: must be > 0"},
        {"look_at equals position", [](Scene& s) { s.camera->look_at = s.camera->position; },
         [](json& j) { j["camera"]["look_at"] = j["camera"]["position"]; }, "camera.look_at: equals camera.position"},
        {"up zero", [](Scene& s) { s.camera->up = Vec3::Zero(); }, [](json& j) { j["camera"]["up"] = {0, 0, 0}; },
         "camera.up: has zero length"},
        {"up parallel to the view", [](Scene& s) { s.camera->up = Vec3(-3, 0, 0); },
         [](json& j) { j["camera"]["up"] = {-3, 0, 0}; }, "camera.up: is parallel to the view direction"},
        {"negative intensity", [](Scene& s) { std::get<tprf::PointLight>(s.lights[0]).intensity = Rgb::Constant(-1); },
         [](json& j) { j["lights"][0]["intensity"] = -1; }, "lights[0].intensity: must be >= 0"},
        {"negative power channel", [](Scene& s) { std::get<tprf::Laser>(s.lights[1]).power = Rgb(1, -1, 1); },
         [](json& j) { j["lights"][1]["power"] = {1, -1, 1}; }, "lights[1].power: must be >= 0"},
        {"laser direction zero", [](Scene& s) { std::get<tprf::Laser>(s.lights[1]).direction = Vec3::Zero(); },
         [](json& j) { j["lights"][1]["direction"] = {0, 0, 0}; }, "lights[1].direction: has zero length"},
        {"u zero", [](Scene& s) { std::get<tprf::RectangleShape>(s.objects[0].shape).u = Vec3::Zero(); },
         [](json& j) { j["objects"][0]["u"] = {0, 0, 0}; }, "objects[0].u: has zero length"},
        {"v zero", [](Scene& s) { std::get<tprf::RectangleShape>(s.objects[0].shape).v = Vec3::Zero(); },
         [](json& j) { j["objects"][0]["v"] = {0, 0, 0}; }, "objects[0].v: has zero length"},
        {"v parallel to u", [](Scene& s) { std::get<tprf::RectangleShape>(s.objects[0].shape).v = Vec3(-2, 0, 0); },
         [](json& j) { j["objects"][0]["v"] = {-2, 0, 0}; }, "objects[0].v: is parallel to u"},
        {"albedo above 1", [](Scene& s) { s.objects[0].albedo = Rgb::Constant(1.01); },
         [](json& j) { j["objects"][0]["albedo"] = 1.01; }, "objects[0].albedo: must be in [0, 1]"},
        {"albedo channel below 0", [](Scene& s) { s.objects[1].albedo = Rgb(0.5, -0.1, 0.5); },
         [](json& j) { j["objects"][1]["albedo"] = {0.5, -0.1, 0.5}; }, "objects[1].albedo: must be in [0, 1]"},
        {"negative emission", [](Scene& s) { s.objects[0].emission = Rgb::Constant(-0.5); },
         [](json& j) { j["objects"][0]["emission"] = -0.5; }, "objects[0].emission: must be >= 0"},
        {"no objects", [](Scene& s) { s.objects.clear(); }, [](json& j) { j["objects"] = json::array(); },
         "objects: must hold at least one object"},
        {"missing mesh file",
         [](Scene& s) { std::get<tprf::MeshShape>(s.objects[1].shape).file = s.file.parent_path() / "meshes" / "absent.obj"; },
         [](json& j) { j["objects"][1]["file"] = "meshes/absent.obj"; }, "objects[1].file: mesh file "},
        {"mesh file is a directory",
         [](Scene& s) { std::get<tprf::MeshShape>(s.objects[1].shape).file = s.file.parent_path() / "meshes"; },
         [](json& j) { j["objects"][1]["file"] = "meshes"; }, "objects[1].file: mesh file "},
        {"singular transform", [singular](Scene& s) { std::get<tprf::MeshShape>(s.objects[1].shape).transform = singular; },
         [](json& j) { j["objects"][1]["transform"]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1}; },
         "objects[1].transform.matrix: is singular"},
        {"projective transform", [](Scene& s) { std::get<tprf::MeshShape>(s.objects[1].shape).transform(3, 2) = 1; },
         [](json& j) { j["objects"][1]["transform"]["matrix"][14] = 1; },
         "objects[1].transform.matrix: last row must be 0 0 0 1"},
        {"max_edge negative", [](Scene& s) { s.max_edge = -0.1; }, [](json& j) { j["patches"]["max_edge"] = -0.1; },
         "patches.max_edge: must be > 0"},
        {"max_bounces -2", [](Scene& s) { s.solver.max_bounces = -2; }, [](json& j) { j["solver"]["max_bounces"] = -2; },
         "solver.max_bounces: must be >= 0"},
    };
}

// Mistakes of the sensor block, on its own and against the time axis.
std::vector<Twin> sensor_twins() {
    return {
        {"gaussian fwhm zero", [](Scene& s) { s.sensor->pulse.fwhm = 0; },
         [](json& j) { j["sensor"]["pulse"]["fwhm"] = 0; }, "sensor.pulse.fwhm: must be > 0"},
        {"box width negative", [](Scene& s) { s.sensor->pulse = {tprf::PulseShape::Box, 0.0, -1.0, {}, {}}; },
         [](json& j) { j["sensor"]["pulse"] = {{"shape", "box"}, {"width", -1}}; }, "sensor.pulse.width: must be > 0"},
        {"pulse far longer than the window", [](Scene& s) { s.sensor->pulse.fwhm = 1000; },
         [](json& j) { j["sensor"]["pulse"]["fwhm"] = 1000; }, "sensor.pulse.fwhm: reaches "},
        {"gate width negative", [](Scene& s) { for (auto& w : exposure(s).windows) w[1] = -0.05; },
         [](json& j) { j["sensor"]["exposure"]["width"] = -0.05; }, "sensor.exposure.width: must be > 0"},
        {"no gates", [](Scene& s) { exposure(s).windows.clear(); }, [](json& j) { j["sensor"]["exposure"]["count"] = 0; },
         "sensor.exposure.count: must be > 0"},
        {"too many gates", [](Scene& s) { exposure(s).windows.assign(tprf::kMaxSensorMeasurements + 1, {0.0, 0.05}); },
         [](json& j) { j["sensor"]["exposure"]["count"] = tprf::kMaxSensorMeasurements + 1; },
         "sensor.exposure.count: more than 1048576 gates"},
        {"last gate beyond the largest number", [](Scene& s) { exposure(s).windows = {{1e308, 1e308}}; },
         [](json& j) { j["sensor"]["exposure"].update({{"start", 1e308}, {"width", 1e308}, {"count", 1}}); },
         "sensor.exposure: the last gate ends beyond the largest number"},
        {"gates outside the window", [](Scene& s) { for (auto& w : exposure(s).windows) w[0] += 100; },
         [](json& j) { j["sensor"]["exposure"]["start"] = 100.0; },
         "sensor.exposure: every gate lies outside the render's time window"},
        {"no windows", [](Scene& s) { exposure(s) = {tprf::ExposureType::Windows, {}, 0, {}, 1, 0, 0, 0}; },
         [](json& j) { j["sensor"]["exposure"] = {{"type", "windows"}, {"windows", json::array()}}; },
         "sensor.exposure.windows: must hold at least one [start, width]"},
        {"window width zero", [](Scene& s) { exposure(s) = {tprf::ExposureType::Windows, {{0.1, 0.0}}, 0, {}, 1, 0, 0, 0}; },
         [](json& j) { j["sensor"]["exposure"] = {{"type", "windows"}, {"windows", {{0.1, 0}}}}; },
         "sensor.exposure.windows[0][1]: must be > 0"},
        {"window beyond the largest number",
         [](Scene& s) { exposure(s) = {tprf::ExposureType::Windows, {{0.1, 0.2}, {1e308, 1e308}}, 0, {}, 1, 0, 0, 0}; },
         [](json& j) { j["sensor"]["exposure"] = {{"type", "windows"}, {"windows", {{0.1, 0.2}, {1e308, 1e308}}}}; },
         "sensor.exposure.windows[1]: ends beyond the largest number"},
        {"amcw frequency zero", [](Scene& s) { make_amcw(s); exposure(s).frequency_mhz = 0; },
         [](json& j) { make_amcw(j); j["sensor"]["exposure"]["frequency_mhz"] = 0; },
         "sensor.exposure.frequency_mhz: must be > 0"},
        {"amcw phases that miss the sine", [](Scene& s) { make_amcw(s); exposure(s).phases_deg = {0, 180, 360}; },
         [](json& j) { make_amcw(j); j["sensor"]["exposure"]["phases_deg"] = {0, 180, 360}; },
         "sensor.exposure.phases_deg: needs at least 3 phases"},
        {"spad photons zero", [](Scene& s) { make_spad(s); exposure(s).photons = 0; },
         [](json& j) { make_spad(j); j["sensor"]["exposure"]["photons"] = 0; }, "sensor.exposure.photons: must be > 0"},
        {"spad photons above 1e20", [](Scene& s) { make_spad(s); exposure(s).photons = 1e21; },
         [](json& j) { make_spad(j); j["sensor"]["exposure"]["photons"] = 1e21; },
         "sensor.exposure.photons: must be at most 1e20"},
        {"spad jitter negative", [](Scene& s) { make_spad(s); exposure(s).jitter_fwhm = -1; },
         [](json& j) { make_spad(j); j["sensor"]["exposure"]["jitter_fwhm"] = -1; },
         "sensor.exposure.jitter_fwhm: must be >= 0"},
        {"spad jitter far longer than the window", [](Scene& s) { make_spad(s); exposure(s).jitter_fwhm = 1e300; },
         [](json& j) { make_spad(j); j["sensor"]["exposure"]["jitter_fwhm"] = 1e300; },
         "sensor.exposure.jitter_fwhm: reaches "},
        {"spad dark rate negative", [](Scene& s) { make_spad(s); exposure(s).dark_rate = -1; },
         [](json& j) { make_spad(j); j["sensor"]["exposure"]["dark_rate"] = -1; },
         "sensor.exposure.dark_rate: must be >= 0"},
        {"spad dark rate above 1e30", [](Scene& s) { make_spad(s); exposure(s).dark_rate = 1e31; },
         [](json& j) { make_spad(j); j["sensor"]["exposure"]["dark_rate"] = 1e31; },
         "sensor.exposure.dark_rate: must be at most 1e30"},
        {"spad with noise", [](Scene& s) { make_spad(s); s.sensor->noise.sigma = 0.5; },
         [](json& j) { make_spad(j); j["sensor"]["noise"] = {{"sigma", 0.5}}; }, "sensor.noise: a SPAD counts photons"},
        {"noise sigma negative", [](Scene& s) { s.sensor->noise.sigma = -1; },
         [](json& j) { j["sensor"]["noise"]["sigma"] = -1; }, "sensor.noise.sigma: must be >= 0"},
    };
}

void expect_twins_agree(const std::vector<Twin>& twins) {
    TempDir dir;
    const fs::path file = dir.path / "scene.json";
    for (const Twin& t : twins) {
        SCOPED_TRACE(t.name);
        Scene scene = base_scene(dir.path);
        t.scene(scene);
        json j = base_json();
        t.json(j);
        const std::string from_scene = error_of([&] { tprf::validate(scene); });
        const std::string from_json = error_of([&] { tprf::parse_scene(j.dump(), file); });
        EXPECT_EQ(from_scene, from_json);
        EXPECT_EQ(from_scene.rfind(file.string() + ": " + t.expect, 0), 0u) << from_scene;
    }
}

}  // namespace

TEST(Validate, HandBuiltSceneIsTheJsonSceneAndPasses) {
    TempDir dir;
    const Scene hand = base_scene(dir.path);
    EXPECT_NO_THROW(tprf::validate(hand));
    const Scene parsed = tprf::parse_scene(base_json().dump(), dir.path / "scene.json");
    EXPECT_NO_THROW(tprf::validate(parsed));
    // The twins below differ by one field only if the two bases are the same scene.
    EXPECT_EQ(parsed.time.bins, hand.time.bins);
    EXPECT_EQ(parsed.time.bin_width, hand.time.bin_width);
    EXPECT_EQ(parsed.camera->position, hand.camera->position);
    EXPECT_EQ(parsed.camera->look_at, hand.camera->look_at);
    EXPECT_EQ(parsed.camera->up, hand.camera->up);
    EXPECT_EQ(std::get<tprf::Laser>(parsed.lights[1]).direction, std::get<tprf::Laser>(hand.lights[1]).direction);
    EXPECT_EQ(std::get<tprf::MeshShape>(parsed.objects[1].shape).file, std::get<tprf::MeshShape>(hand.objects[1].shape).file);
    EXPECT_EQ(std::get<tprf::MeshShape>(parsed.objects[1].shape).transform,
              std::get<tprf::MeshShape>(hand.objects[1].shape).transform);
    EXPECT_EQ(parsed.objects[1].albedo.matrix(), hand.objects[1].albedo.matrix());
    EXPECT_EQ(parsed.sensor->exposure.windows, hand.sensor->exposure.windows);
    EXPECT_EQ(parsed.sensor->noise.sigma, hand.sensor->noise.sigma);
}

TEST(Validate, DefaultsThatMeanAbsentPass) {
    TempDir dir;
    Scene s = base_scene(dir.path);
    s.max_edge = 0.0;           // build_patches picks a size
    s.solver.max_bounces = -1;  // every bounce
    s.camera.reset();
    s.lights.clear();
    s.sensor.reset();
    EXPECT_NO_THROW(tprf::validate(s));
}

TEST(Validate, SceneMistakesGiveTheJsonParsersMessage) { expect_twins_agree(scene_twins()); }

TEST(Validate, SensorMistakesGiveTheJsonParsersMessage) { expect_twins_agree(sensor_twins()); }

TEST(Validate, NonFiniteNumbersAreRefusedByPath) {
    using tprf::Laser;
    using tprf::MeshShape;
    using tprf::PointLight;
    using tprf::RectangleShape;
    struct Case {
        std::function<void(Scene&)> edit;
        std::string expect;  // the message after "FILE: "
    };
    const std::string finite = ": expected a finite number";
    const std::vector<Case> cases = {
        {[](Scene& s) { s.time.bin_width = kNaN; }, "time.bin_width" + finite},
        {[](Scene& s) { s.time.start = -kInf; }, "time.start" + finite},
        {[](Scene& s) { s.camera->position.y() = kNaN; }, "camera.position[1]" + finite},
        {[](Scene& s) { s.camera->look_at.z() = kInf; }, "camera.look_at[2]" + finite},
        {[](Scene& s) { s.camera->up.x() = kNaN; }, "camera.up[0]" + finite},
        {[](Scene& s) { s.camera->fov_deg = kNaN; }, "camera.fov" + finite},
        {[](Scene& s) { std::get<PointLight>(s.lights[0]).position.x() = kInf; }, "lights[0].position[0]" + finite},
        {[](Scene& s) { std::get<PointLight>(s.lights[0]).intensity[1] = kNaN; }, "lights[0].intensity[1]" + finite},
        {[](Scene& s) { std::get<Laser>(s.lights[1]).origin.z() = kNaN; }, "lights[1].origin[2]" + finite},
        {[](Scene& s) { std::get<Laser>(s.lights[1]).direction = Vec3(kNaN, 0, 0); }, "lights[1].direction[0]" + finite},
        {[](Scene& s) { std::get<Laser>(s.lights[1]).power[0] = kInf; }, "lights[1].power[0]" + finite},
        {[](Scene& s) { std::get<RectangleShape>(s.objects[0].shape).origin.x() = kNaN; }, "objects[0].origin[0]" + finite},
        {[](Scene& s) { std::get<RectangleShape>(s.objects[0].shape).u.y() = kInf; }, "objects[0].u[1]" + finite},
        {[](Scene& s) { std::get<RectangleShape>(s.objects[0].shape).v.z() = kNaN; }, "objects[0].v[2]" + finite},
        {[](Scene& s) { s.objects[0].albedo[0] = kNaN; }, "objects[0].albedo[0]" + finite},
        {[](Scene& s) { s.objects[1].emission[2] = kInf; }, "objects[1].emission[2]" + finite},
        // Row 0, column 3 is element 3 of the row-major 16 numbers.
        {[](Scene& s) { std::get<MeshShape>(s.objects[1].shape).transform(0, 3) = kInf; },
         "objects[1].transform.matrix[3]" + finite},
        {[](Scene& s) { s.max_edge = kNaN; }, "patches.max_edge" + finite},
        {[](Scene& s) { s.sensor->pulse.fwhm = kInf; }, "sensor.pulse.fwhm" + finite},
        {[](Scene& s) { s.sensor->exposure.windows[2][0] = kNaN; }, "sensor.exposure.start" + finite},
        {[](Scene& s) { s.sensor->exposure.windows[0][1] = kNaN; }, "sensor.exposure.width" + finite},
        {[](Scene& s) { s.sensor->noise.sigma = kNaN; }, "sensor.noise.sigma" + finite},
        {[](Scene& s) { make_amcw(s); s.sensor->exposure.phases_deg[1] = kNaN; },
         "sensor.exposure.phases_deg[1]" + finite},
        {[](Scene& s) { make_spad(s); s.sensor->exposure.photons = kNaN; }, "sensor.exposure.photons" + finite},
        {[](Scene& s) { make_spad(s); s.sensor->exposure.dark_rate = kInf; }, "sensor.exposure.dark_rate" + finite},
    };
    TempDir dir;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.expect);
        Scene s = base_scene(dir.path);
        c.edit(s);
        EXPECT_EQ(error_of([&] { tprf::validate(s); }), s.file.string() + ": " + c.expect);
    }
}

TEST(Validate, WhatOnlyAHandBuiltSceneCanGetWrong) {
    TempDir dir;
    const Scene base = base_scene(dir.path);
    const std::string prefix = base.file.string() + ": ";
    auto message = [&](const std::function<void(Scene&)>& edit) {
        Scene s = base;
        edit(s);
        return error_of([&] { tprf::validate(s); });
    };
    // A parser normalises a laser's direction; a hand-built one must be a unit vector already.
    EXPECT_EQ(message([](Scene& s) { std::get<tprf::Laser>(s.lights[1]).direction = Vec3(-2, 0, 0); }),
              prefix + "lights[1].direction: must be a unit vector");
    // Paths that the Scene does not carry are derived from position.
    EXPECT_EQ(message([](Scene& s) { s.objects[0].json_path.clear(); s.objects[0].albedo = Rgb::Constant(2); }),
              prefix + "objects[0].albedo: must be in [0, 1]");
    EXPECT_EQ(message([](Scene& s) { s.sensor->json_path.clear(); s.sensor->file.clear(); s.sensor->pulse.fwhm = -1; }),
              prefix + "sensor.pulse.fwhm: must be > 0");
    // A table pulse as a parser would leave it after reading its CSV.
    auto table = [&](std::vector<double> t, std::vector<double> v) {
        return message([&](Scene& s) { s.sensor->pulse = {tprf::PulseShape::Table, 0, 0, t, v}; });
    };
    EXPECT_EQ(table({0, 1}, {1, 1}), "(no error)");
    EXPECT_EQ(table({0}, {1}), prefix + "sensor.pulse.file: pulse table needs at least two rows");
    EXPECT_EQ(table({0, 1}, {1}), prefix + "sensor.pulse.file: pulse table has 2 times but 1 values");
    EXPECT_EQ(table({0, 1, 1}, {1, 1, 1}), prefix + "sensor.pulse.file: pulse table, row 2: times must increase strictly");
    EXPECT_EQ(table({0, 1}, {1, -1}), prefix + "sensor.pulse.file: pulse table, row 1: value must be >= 0");
    EXPECT_EQ(table({0, kNaN}, {1, 1}), prefix + "sensor.pulse.file: pulse table, row 1: expected finite numbers");
    EXPECT_EQ(table({0, 1}, {0, 0}),
              prefix + "sensor.pulse.file: pulse table has zero area, or times too far apart to integrate");
}

TEST(Validate, SensorFileMistakesGiveTheParsersMessage) {
    // A sensor file (`tprf sensor`): the block is the document, so paths have no "sensor." prefix.
    const fs::path file = "sensor.json";
    const json block = {{"exposure", {{"type", "gates"}, {"start", 0}, {"width", -1}, {"step", 1}, {"count", 2}}}};
    tprf::SensorSettings s;
    s.exposure.windows = {{0, -1}, {1, -1}};
    s.file = file;
    EXPECT_EQ(error_of([&] { tprf::validate_sensor(s); }), "sensor.json: exposure.width: must be > 0");
    EXPECT_EQ(error_of([&] { tprf::parse_sensor_block(block.dump(), file, ""); }),
              "sensor.json: exposure.width: must be > 0");
    s.exposure.windows = {{0, 1}, {1, 1}};
    EXPECT_EQ(error_of([&] { tprf::validate_sensor(s); }), "(no error)");
}
