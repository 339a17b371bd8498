// The command line's contract (docs/cli.md): exit status 2 and one message for bad input,
// and nothing written for it.
#include "test_process.h"
#include "tprf/io/npy.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <sys/wait.h>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

namespace fs = std::filesystem;
using tprf::test::Outcome;
using tprf::test::read_bytes;

Outcome run(const std::string& args) { return tprf::test::run_tprf(args); }

// Runs the command and returns its standard output (stderr is dropped).
std::string run_stdout(const std::string& args, int& status) {
    const fs::path out = fs::temp_directory_path() / ("tprf_cli_out_" + std::to_string(std::random_device{}()));
    const std::string command = std::string(TPRF_BINARY) + " " + args + " -q >" + out.string() + " 2>/dev/null";
    const int raw = std::system(command.c_str());
    status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
    std::ifstream in(out);
    std::string text((std::istreambuf_iterator<char>(in)), {});
    fs::remove(out);
    return text;
}

// The line of `text` that starts with `key`, without the key.
std::string line_after(const std::string& text, const std::string& key) {
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);)
        if (line.rfind(key, 0) == 0) return line.substr(key.size());
    return {};
}

class Cli : public ::testing::Test {
protected:
    void SetUp() override {
        m_dir = fs::temp_directory_path() / ("tprf_cli_" + std::to_string(std::random_device{}()));
        fs::create_directories(m_dir);
        std::ofstream(m_dir / "good.json") << R"({
          "time": {"bins": 16, "bin_width": 0.1},
          "camera": {"position": [2, 0.5, 0.5], "look_at": [0, 0.5, 0.3], "up": [0, 0, 1], "fov": 40,
                     "width": 8, "height": 8},
          "lights": [{"type": "point", "position": [0.6, 0.5, 0.6], "intensity": 1.0}],
          "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]}],
          "patches": {"max_edge": 0.5}})";
        std::ofstream(m_dir / "bad.json") << R"({"time": {"bins": 0, "bin_width": 0.1}, "objects": []})";
    }
    void TearDown() override { fs::remove_all(m_dir); }
    // good.json with 64 bins of 0.1 m (6.4 m of path), which hold its light: its 16 bins end at 1.6 m,
    // before any of it arrives (2.5 m).
    fs::path lit_scene() const {
        std::ifstream in(m_dir / "good.json");
        std::string scene((std::istreambuf_iterator<char>(in)), {});
        scene.replace(scene.find(R"("bins": 16)"), 10, R"("bins": 64)");
        std::ofstream(m_dir / "lit.json") << scene;
        return m_dir / "lit.json";
    }
    fs::path m_dir;
};

TEST_F(Cli, BadSceneExitsTwoWithThePathAndWritesNothing) {
    const Outcome r = run("render " + (m_dir / "bad.json").string() + " -o " + (m_dir / "out").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("time.bins"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(m_dir / "out"));
}

TEST_F(Cli, VersionPrintsTheProjectVersionAndExitsZero) {
    int status = -1;
    EXPECT_EQ(run_stdout("--version", status), "tprf " TPRF_VERSION "\n");
    EXPECT_EQ(status, 0);
}

TEST_F(Cli, MissingSceneFileExitsTwo) {
    const Outcome r = run("info " + (m_dir / "nope.json").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_EQ(r.err, "tprf: error: " + (m_dir / "nope.json").string() +
                         ": cannot read scene file: No such file or directory\n");
}

TEST_F(Cli, UnknownFlagExitsTwo) {
    EXPECT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string() + " --bogus").status, 2);
    EXPECT_FALSE(fs::exists(m_dir / "out"));
    EXPECT_EQ(run("render " + (m_dir / "good.json").string()).status, 2);  // -o is required
    EXPECT_EQ(run("frobnicate").status, 2);
}

TEST_F(Cli, UnwritableOutputDirectoryExitsTwo) {
    std::ofstream(m_dir / "file") << "x";
    const Outcome r = run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "file" / "out").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("cannot write"), std::string::npos) << r.err;
}

TEST_F(Cli, GoodSceneRendersAndInfoPrints) {
    EXPECT_EQ(run("info " + (m_dir / "good.json").string()).status, 0);
    const Outcome r = run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string() + " --threads 1");
    EXPECT_EQ(r.status, 0) << r.err;
    for (const char* f : {"transient.npy", "steady.npy", "steady.exr", "preview.png", "render.json"})
        EXPECT_TRUE(fs::is_regular_file(m_dir / "out" / f)) << f;
}

TEST_F(Cli, AovWritesTheGroundTruthMapsItNamesAndRefusesUnknownOnes) {
    const std::string scene = (m_dir / "good.json").string();
    const Outcome r = run("render " + scene + " -o " + (m_dir / "out").string() + " --aov depth,object");
    EXPECT_EQ(r.status, 0) << r.err;
    // float32 depth, int32 object labels, as numpy writes them; no map that was not asked for.
    EXPECT_NE(read_bytes(m_dir / "out" / "aov_depth.npy").find("'descr': '<f4', 'fortran_order': False, 'shape': (8, 8), }"),
              std::string::npos);
    EXPECT_NE(read_bytes(m_dir / "out" / "aov_object.npy").find("'descr': '<i4', 'fortran_order': False, 'shape': (8, 8), }"),
              std::string::npos);
    EXPECT_FALSE(fs::exists(m_dir / "out" / "aov_normal.npy"));
    const Outcome all = run("render " + scene + " -o " + (m_dir / "all").string() + " --aov all");
    EXPECT_EQ(all.status, 0) << all.err;
    for (const char* f : {"aov_depth.npy", "aov_normal.npy", "aov_position.npy", "aov_object.npy", "aov_albedo.npy"})
        EXPECT_TRUE(fs::is_regular_file(m_dir / "all" / f)) << f;
    const Outcome bad = run("render " + scene + " -o " + (m_dir / "bad").string() + " --aov depth,colour");
    EXPECT_EQ(bad.status, 2);
    EXPECT_NE(bad.err.find("--aov: unknown map \"colour\" (expected a comma-separated list of depth, normal, position, "
                           "object, albedo, or all)"),
              std::string::npos)
        << bad.err;
    EXPECT_FALSE(fs::exists(m_dir / "bad"));
}

TEST_F(Cli, InfoEstimateOnlyPrintsTheEstimateAndBuildsNoLinks) {
    int status = -1;
    const std::string out = run_stdout("info --estimate-only " + (m_dir / "good.json").string(), status);
    EXPECT_EQ(status, 0);
    EXPECT_NE(line_after(out, "estimate "), "") << out;
    EXPECT_EQ(line_after(out, "patches  "), "4 (counted; max_edge 0.5 m)") << out;
    EXPECT_NE(line_after(out, "time     "), "") << out;
    EXPECT_EQ(out.find("links    "), std::string::npos) << out;
}

TEST_F(Cli, SettingsProbablyInAnotherUnitAreWarnedOfByInfoAndRender) {
    // good.json's 1 m square (1.41 m across) with a fov of 0.78 (radians meant), bins of 5 m (mm meant) and
    // bins of 0.001 ps (3e-7 m): each a warning before the links, from info (--estimate-only too) and render;
    // none for good.json.
    const auto scene = [&](const std::string& name, const std::string& fov, const std::string& time) {
        std::ofstream(m_dir / name) << R"({"time": )" << time << R"(,
          "camera": {"position": [2, 0.5, 0.5], "look_at": [0, 0.5, 0.3], "up": [0, 0, 1], "fov": )" << fov << R"(,
                     "width": 8, "height": 8},
          "lights": [{"type": "point", "position": [0.6, 0.5, 0.6], "intensity": 1.0}],
          "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]}],
          "patches": {"max_edge": 0.5}})";
        return (m_dir / name).string();
    };
    const std::string units = scene("units.json", "0.78", R"({"bins": 16, "bin_width": 5})");
    const std::string fine = scene("fine.json", "40", R"({"bins": 16, "bin_width": 0.001, "unit": "ps"})");
    for (const std::string& command :
         std::vector<std::string>{"info ", "info --estimate-only ", "render -o " + (m_dir / "out").string() + " "}) {
        const Outcome r = run(command + units);
        EXPECT_EQ(r.status, 0) << command << r.err;
        EXPECT_NE(r.err.find("warning: camera.fov is 0.78 degrees: fov is in degrees (if 0.78 was meant in radians, it "
                             "is 44.69 degrees)"),
                  std::string::npos)
            << command << r.err;
        EXPECT_NE(r.err.find("warning: time.bin_width 5 m against a scene 1.41 m across"), std::string::npos)
            << command << r.err;
        if (command.rfind("render", 0) == 0) continue;  // (its march would keep 5 million bins a patch)
        const Outcome f = run(command + fine);
        EXPECT_NE(f.err.find("warning: time.bin_width 0.001 ps (3e-07 m of light travel) against a scene 1.41 m "
                             "across (its bounding box's diagonal): light takes over 10^5 bins to cross it"),
                  std::string::npos)
            << command << f.err;
        EXPECT_EQ(f.err.find("camera.fov"), std::string::npos) << f.err;
    }
    for (const char* command : {"info ", "info --estimate-only "})
        EXPECT_EQ(run(command + (m_dir / "good.json").string()).err.find("warning"), std::string::npos) << command;
    // Rendered with 64 bins of 0.1 m, which hold its light (16 bins end before any of it arrives, which
    // render warns of: AWindowThatMissesTheLightIsWarnedOf).
    const Outcome good = run("render -o " + (m_dir / "good").string() + " " + lit_scene().string());
    EXPECT_EQ(good.err.find("warning"), std::string::npos) << good.err;
}

TEST_F(Cli, AWindowThatMissesTheLightIsWarnedOf) {
    // good.json's 16 bins of 0.1 m end at 1.6 m of path; its light's shortest path is 2.5 m: all of it
    // falls after the window. With 64 bins (6.4 m) the open floor's single bounce is all inside.
    const Outcome dark = run("render -o " + (m_dir / "dark").string() + " " + (m_dir / "good.json").string());
    EXPECT_EQ(dark.status, 0) << dark.err;
    EXPECT_NE(dark.err.find("tprf: warning: 100.0% of the light the camera sees falls outside the time window [0, 1.6] m"),
              std::string::npos)
        << dark.err;
    std::ifstream dark_json(m_dir / "dark" / "render.json");
    EXPECT_DOUBLE_EQ(nlohmann::json::parse(dark_json).at("camera").at("light_outside_window").get<double>(), 1.0);
    const Outcome all = run("render -o " + (m_dir / "lit").string() + " " + lit_scene().string());
    EXPECT_EQ(all.err.find("warning"), std::string::npos) << all.err;
    std::ifstream lit_json(m_dir / "lit" / "render.json");
    EXPECT_LT(nlohmann::json::parse(lit_json).at("camera").at("light_outside_window").get<double>(), 1e-5);
}

TEST_F(Cli, AMeshInMillimetresIsNamedWithTheScaleThatFixesIt) {
    // A 0.1 m tetrahedron written in millimetres on a 1 m floor: info warns, naming it, its size and the
    // scale that fixes it; a render refused for size says so first.
    std::ofstream(m_dir / "tetra.obj") << "v 0 0 0\nv 100 0 0\nv 0 100 0\nv 0 0 100\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    std::ofstream(m_dir / "mm.json") << R"({
      "time": {"bins": 16, "bin_width": 0.1},
      "camera": {"position": [2, 0.5, 0.5], "look_at": [0, 0.5, 0.3], "up": [0, 0, 1], "fov": 40, "width": 8, "height": 8},
      "lights": [{"type": "point", "position": [0.6, 0.5, 0.6], "intensity": 1.0}],
      "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]},
                  {"type": "mesh", "file": "tetra.obj"}],
      "patches": {"max_edge": 0.05}})";
    const std::string why =
        "objects[1] ('tetra.obj') is 173.2 m across, 122 times the rest of the scene (1.414 m): is it in millimetres? "
        "A scale of 0.001 in its transform makes it 0.1732 m";
    const Outcome info = run("info --estimate-only " + (m_dir / "mm.json").string());
    EXPECT_EQ(info.status, 0) << info.err;
    EXPECT_NE(info.err.find("tprf: warning: " + why), std::string::npos) << info.err;
    const Outcome r = run("render " + (m_dir / "mm.json").string() + " -o " + (m_dir / "out").string() + " --max-memory 0.01");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("mm.json: " + why + "; estimated peak memory"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(m_dir / "out"));
}

TEST_F(Cli, AMitsubaSceneWithoutAPatchSizeSaysTheOneItGetsFirst) {
    const std::string xml = std::string(TPRF_SOURCE_DIR) + "/meshes/cornell-box.xml";
    // (Without -q: notes are not warnings, and --quiet leaves them out.)
    const auto loud = [](const std::string& args) { return tprf::test::shell(std::string(TPRF_BINARY) + " " + args + " >/dev/null"); };
    const Outcome r = loud("info --estimate-only " + xml);
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.err.substr(0, r.err.find('\n')),
              "tprf: note: patches of 0.05413 m: the scene sets no patch size, so its bounding box's diagonal (1.732 m) "
              "/ 32 (--max-edge sets it)");
    EXPECT_EQ(loud("info --estimate-only --max-edge 0.1 " + xml).err.find("note"), std::string::npos);
    EXPECT_EQ(run("info --estimate-only -q " + xml).err.find("note"), std::string::npos);
    int status = -1;
    EXPECT_EQ(line_after(run_stdout("info --estimate-only " + xml, status), "patches  "),
              "2325 (counted; max_edge 0.0541266 m)");
}

TEST_F(Cli, MaxEdgeReplacesTheScenesPatchSize) {
    // good.json: one 1 m square at max_edge 0.5 (4 patches); --max-edge 0.25 cuts it into 16, 0.1 into 100.
    int status = -1;
    EXPECT_EQ(line_after(run_stdout("info " + (m_dir / "good.json").string(), status), "patches  "),
              "4 (max_edge 0.5 m)");
    EXPECT_EQ(line_after(run_stdout("info --max-edge 0.25 " + (m_dir / "good.json").string(), status), "patches  "),
              "16 (max_edge 0.25 m)");
    EXPECT_EQ(status, 0);
    const Outcome r = run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string() +
                          " --max-edge 0.1");
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string record = read_bytes(m_dir / "out" / "render.json");
    EXPECT_NE(record.find("\"patches\": 100"), std::string::npos) << record;
    for (const char* bad : {"0", "-1", "inf", "nan", "abc", "1e999"}) {
        const Outcome b = run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out2").string() +
                              " --max-edge " + bad);
        EXPECT_EQ(b.status, 2) << bad;
        EXPECT_NE(b.err.find("--max-edge: must be a positive, finite number"), std::string::npos) << b.err;
    }
    EXPECT_FALSE(fs::exists(m_dir / "out2"));
}

TEST_F(Cli, InfoPrintsPatchesLinksAndTheTimeWindow) {
    // Two facing 1 m squares cut at 0.25 m: 16 + 16 patches; every patch of one sees every patch of the
    // other and none of its own, so 2 x 16 x 16 links. 100 bins of 10 ps: bins of
    // 10e-12 s x 299792458 m/s = 2.99792458 mm of path, a window of 0.299792458 m, 0 to 1 ns.
    std::ofstream(m_dir / "plates.json") << R"({
      "time": {"bins": 100, "bin_width": 10, "unit": "ps"},
      "camera": {"position": [0.5, 0.5, 0.5], "look_at": [0.5, 0.5, 0], "up": [0, 1, 0], "fov": 40,
                 "width": 8, "height": 8},
      "lights": [{"type": "point", "position": [0.5, 0.5, 0.5], "intensity": 1.0}],
      "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]},
                  {"type": "rectangle", "origin": [0, 0, 1], "u": [0, 1, 0], "v": [1, 0, 0]}],
      "patches": {"max_edge": 0.25}})";
    const auto entries = [&] {
        return std::distance(fs::recursive_directory_iterator(m_dir), fs::recursive_directory_iterator());
    };
    const auto before = entries();
    int status = -1;
    const std::string out = run_stdout("info " + (m_dir / "plates.json").string(), status);
    ASSERT_EQ(status, 0) << out;
    EXPECT_EQ(std::stoul(line_after(out, "patches")), 32u) << out;
    EXPECT_EQ(std::stoul(line_after(out, "links")), 512u) << out;
    const std::string time = line_after(out, "time");
    int bins = 0;
    double width = 0, from = 0, to = 0, from_ns = 0, to_ns = 0;
    ASSERT_EQ(std::sscanf(time.c_str(), " %d bins of %lf m from %lf m to %lf m of optical path (%lf ns to %lf ns)",
                          &bins, &width, &from, &to, &from_ns, &to_ns),
              6)
        << out;
    EXPECT_EQ(bins, 100);
    // Printed to 6 significant digits: half a unit of the 6th digit is at most 5e-6 relative.
    EXPECT_NEAR(width, 2.99792458e-3, 5e-6 * 2.99792458e-3);
    EXPECT_EQ(from, 0.0);
    EXPECT_NEAR(to, 0.299792458, 5e-6 * 0.299792458);
    EXPECT_EQ(from_ns, 0.0);
    EXPECT_NEAR(to_ns, 1.0, 5e-6);
    EXPECT_EQ(entries(), before) << "info wrote something";
}

// A scene of one mesh file (its text given), for the mesh tests of `tprf info`.
fs::path mesh_scene(const fs::path& dir, const std::string& mesh_name, const std::string& mesh_text) {
    std::ofstream(dir / mesh_name, std::ios::binary) << mesh_text;
    const fs::path scene = dir / (mesh_name + ".json");
    std::ofstream(scene) << R"({"time": {"bins": 16, "bin_width": 0.1},
      "camera": {"position": [0.5, 0.5, 3], "look_at": [0.5, 0.5, 0], "up": [0, 1, 0], "fov": 40, "width": 8, "height": 8},
      "lights": [{"type": "point", "position": [0.5, 0.5, 1], "intensity": 1.0}],
      "objects": [{"type": "mesh", "file": ")" + mesh_name + R"(", "transform": {"scale": 2, "translate": [1, 0, 0]}}]})";
    return scene;
}

TEST_F(Cli, InfoMeshesPrintsEachMeshAndWhatWasDroppedWithoutLinks) {
    // The unit square, a duplicate of its first triangle, a zero-area triangle and an unused vertex;
    // scaled by 2 and moved by +1 in x: the box (1, 0, 0) to (3, 2, 0).
    const fs::path scene = mesh_scene(m_dir, "sq.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 9 9 9\nv 2 0 0\n"
                                                       "f 1 2 3\nf 1 3 4\nf 2 3 1\nf 1 2 6\n");
    int status = -1;
    const std::string out = run_stdout("info --meshes " + scene.string(), status);
    ASSERT_EQ(status, 0) << out;
    EXPECT_NE(out.find("sq.obj': 4 vertices, 2 faces (cut into 2 triangles); box (1, 0, 0) to (3, 2, 0) m; "
                       "dropped 1 zero-area face, 1 duplicate face and 2 unreferenced vertices"),
              std::string::npos)
        << out;
    EXPECT_EQ(line_after(out, "links"), "") << "--meshes must not build links: " << out;
    EXPECT_EQ(line_after(out, "estimate"), "") << out;
    // The warning goes to stderr, once per mesh.
    const Outcome r = run("info --meshes " + scene.string());
    EXPECT_EQ(r.err.rfind("tprf: warning: mesh file '", 0), 0u) << r.err;
    EXPECT_NE(r.err.find("sq.obj' (objects[0].file): dropped 1 zero-area face"), std::string::npos)
        << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

TEST_F(Cli, BadMeshExitsTwoWithTheLine) {
    const fs::path scene = mesh_scene(m_dir, "bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
    for (const char* command : {"info --meshes ", "info ", "render "}) {
        const Outcome r = run(command + scene.string() + (std::string(command) == "render " ? " -o " + (m_dir / "out").string() : ""));
        EXPECT_EQ(r.status, 2) << command;
        EXPECT_NE(r.err.find("objects[0].file: mesh file '" + (m_dir / "bad.off").string() + "', line 6: face 1 refers to vertex 3, but the file has "
                             "3 vertices"),
                  std::string::npos)
            << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
    EXPECT_FALSE(fs::exists(m_dir / "out"));
}

TEST_F(Cli, SensorOnARenderMatchesTheSceneSensorBlock) {
    // The same gates through `tprf sensor` on a plain render and through the scene's own sensor block.
    const std::string gates = R"({"type": "gates", "start": 0.0, "width": 0.3, "step": 0.3, "count": 5})";
    std::ofstream(m_dir / "sensor.json") << R"({"exposure": )" << gates << "}";
    std::ifstream in(m_dir / "good.json");
    std::string scene((std::istreambuf_iterator<char>(in)), {});
    scene.insert(scene.rfind('}'), R"(, "sensor": {"exposure": )" + gates + "}");
    std::ofstream(m_dir / "with_sensor.json") << scene;

    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "a").string()).status, 0);
    const Outcome r = run("sensor " + (m_dir / "a").string() + " " + (m_dir / "sensor.json").string() + " --plot-pixel 2,3");
    ASSERT_EQ(r.status, 0) << r.err;
    const Outcome s = run("render " + (m_dir / "with_sensor.json").string() + " -o " + (m_dir / "b").string());
    ASSERT_EQ(s.status, 0) << s.err;
    // `tprf sensor` writes into OUTDIR/sensor-NAME (NAME the sensor file's stem); the render, beside its cube.
    const fs::path a_out = m_dir / "a" / "sensor-sensor", b_out = m_dir / "b";
    for (const char* f : {"measurements.npy", "sensor_plot.json", "sensor.json"}) {
        EXPECT_TRUE(fs::is_regular_file(a_out / f)) << f;
        EXPECT_TRUE(fs::is_regular_file(b_out / f)) << f;
        EXPECT_FALSE(fs::exists(m_dir / "a" / f)) << f;
    }
    // The PNG is drawn by Python with matplotlib; without one, the run says so instead (and succeeds).
    for (const auto& [dir, out] : {std::pair{a_out, r}, std::pair{b_out, s}}) {
        const bool warned = out.err.find("sensor_plot.png not drawn") != std::string::npos;
        EXPECT_NE(fs::is_regular_file(dir / "sensor_plot.png"), warned) << dir << ": " << out.err;
    }
    const tprf::NpyArray a = tprf::read_npy(a_out / "measurements.npy");
    const tprf::NpyArray b = tprf::read_npy(b_out / "measurements.npy");
    EXPECT_EQ(a.shape, (std::vector<std::size_t>{8, 8, 5, 3}));
    EXPECT_EQ(a.data, b.data);
    // A scene file with a sensor block serves as the sensor file too; the render's own outputs stay.
    const Outcome again = run("sensor " + (m_dir / "b").string() + " " + (m_dir / "with_sensor.json").string());
    ASSERT_EQ(again.status, 0) << again.err;
    EXPECT_EQ(tprf::read_npy(m_dir / "b" / "sensor-with_sensor" / "measurements.npy").data, a.data);
    EXPECT_EQ(tprf::read_npy(b_out / "measurements.npy").data, a.data);
    // The gates tile [0, 1.5 m), the first 15 of the 16 bins of 0.1 m: together they hold those bins.
    const tprf::NpyArray cube = tprf::read_npy(m_dir / "a" / "transient.npy");
    for (std::size_t p = 0; p < 64; ++p)
        for (std::size_t c = 0; c < 3; ++c) {
            double sum_cube = 0.0, sum_m = 0.0;
            for (std::size_t t = 0; t < 15; ++t) sum_cube += cube.data[(p * 16 + t) * 3 + c];
            for (std::size_t k = 0; k < 5; ++k) sum_m += a.data[(p * 5 + k) * 3 + c];
            EXPECT_NEAR(sum_m, sum_cube, 1e-5 * (1.0 + sum_cube));
        }
}

// Sets an environment variable for one test; the shell that run() starts inherits it.
class ScopedEnv {
public:
    ScopedEnv(const char* name, const std::string& value) : m_name(name) {
        if (const char* old = std::getenv(name)) m_old = old;
        ::setenv(name, value.c_str(), 1);
    }
    ~ScopedEnv() {
        if (m_old)
            ::setenv(m_name, m_old->c_str(), 1);
        else
            ::unsetenv(m_name);
    }
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

private:
    const char* m_name;
    std::optional<std::string> m_old;
};

TEST_F(Cli, SensorPlotWithoutMatplotlibKeepsItsDataAndSaysHowToDrawIt) {
    ASSERT_EQ(run("render " + lit_scene().string() + " -o " + (m_dir / "out").string()).status, 0);
    std::ofstream(m_dir / "gates.json") << R"({"exposure": {"type": "gates", "start": 0, "width": 0.3, "step": 0.3, "count": 5}})";
    const std::string sensor = "sensor " + (m_dir / "out").string() + " " + (m_dir / "gates.json").string() + " --plot-pixel 4,6";  // a pixel that sees the floor
    ASSERT_EQ(run(sensor).status, 0);  // with matplotlib where there is one: a sensor_plot.png to replace
    Outcome r;
    {
        const ScopedEnv no_python("TPRF_PYTHON", (m_dir / "no-such-python").string());
        r = run(sensor);
    }
    EXPECT_EQ(r.status, 0) << r.err;
    // One line: what was not drawn, how to install matplotlib, and the command that draws it later.
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    for (const char* part : {"sensor_plot.png not drawn", "apt-get install python3-matplotlib", "tprf_plots.py sensor "})
        EXPECT_NE(r.err.find(part), std::string::npos) << part << " in " << r.err;
    const fs::path folder = m_dir / "out" / "sensor-gates";
    EXPECT_FALSE(fs::exists(folder / "sensor_plot.png")) << "a plot of the earlier run beside this run's data";

    // The data is the pixel's: its TPRF's bins sum to the pixel's energy in transient.npy (channel mean),
    // and its measurements are the pixel's in measurements.npy.
    std::ifstream in(folder / "sensor_plot.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_EQ(j.at("pixel"), nlohmann::json({4, 6}));
    EXPECT_EQ(j.at("exposure"), "gates");
    EXPECT_EQ(j.at("units").at("time"), "m");
    const std::vector<double> edges = j.at("tprf").at("bin_edges"), density = j.at("tprf").at("density");
    ASSERT_EQ(edges.size(), 65u);  // 64 bins of 0.1 m
    ASSERT_EQ(density.size(), 64u);
    const tprf::NpyArray cube = tprf::read_npy(m_dir / "out" / "transient.npy");
    const std::size_t pixel = 6 * 8 + 4;
    double energy = 0.0, plotted = 0.0;
    for (std::size_t t = 0; t < 64; ++t) {
        for (std::size_t c = 0; c < 3; ++c) energy += cube.data[(pixel * 64 + t) * 3 + c] / 3.0;
        plotted += density[t] * (edges[t + 1] - edges[t]);
    }
    EXPECT_GT(energy, 0.0);
    EXPECT_NEAR(plotted, energy, 1e-9 * energy);  // 12 significant digits in the JSON
    const std::vector<double> values = j.at("measurements").at("value");
    const tprf::NpyArray m = tprf::read_npy(folder / "measurements.npy");
    ASSERT_EQ(values.size(), 5u);
    for (std::size_t k = 0; k < 5; ++k) {
        const double mean = (double(m.data[(pixel * 5 + k) * 3]) + m.data[(pixel * 5 + k) * 3 + 1] +
                             m.data[(pixel * 5 + k) * 3 + 2]) / 3.0;
        EXPECT_NEAR(values[k], mean, 1e-9 * (1.0 + std::abs(mean))) << "gate " << k;
    }
}

TEST_F(Cli, SensorRunsGoToTheirOwnFoldersAndReplaceOnlyTheirOwnOutputs) {
    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string() + " --aov depth").status, 0);
    std::ofstream(m_dir / "amcw.json") << R"({"exposure": {"type": "amcw", "frequency_mhz": 20}})";
    std::ofstream(m_dir / "gates.json") << R"({"exposure": {"type": "gates", "start": 0, "width": 0.5, "step": 0.5, "count": 3}})";
    const fs::path out = m_dir / "out";
    ASSERT_EQ(run("sensor " + out.string() + " " + (m_dir / "amcw.json").string()).status, 0);
    EXPECT_TRUE(fs::exists(out / "sensor-amcw" / "depth.npy"));
    EXPECT_EQ(tprf::read_npy(out / "sensor-amcw" / "raw.npy").shape, (std::vector<std::size_t>{8, 8, 1, 4}));
    ASSERT_EQ(run("sensor " + out.string() + " " + (m_dir / "gates.json").string()).status, 0);
    EXPECT_TRUE(fs::exists(out / "sensor-amcw" / "depth.npy")) << "another sensor's folder is left as it was";
    EXPECT_EQ(tprf::read_npy(out / "sensor-gates" / "measurements.npy").shape, (std::vector<std::size_t>{8, 8, 3, 3}));
    // The same name again replaces that folder's outputs: no AMCW depth beside gated measurements.
    ASSERT_EQ(run("sensor " + out.string() + " " + (m_dir / "gates.json").string() + " --name amcw").status, 0);
    EXPECT_FALSE(fs::exists(out / "sensor-amcw" / "depth.npy"));
    EXPECT_FALSE(fs::exists(out / "sensor-amcw" / "raw.npy"));
    EXPECT_EQ(tprf::read_npy(out / "sensor-amcw" / "measurements.npy").shape, (std::vector<std::size_t>{8, 8, 3, 3}));
    // A bounce cube: transient_bounce_1 measured into its own folder.
    std::ifstream in(m_dir / "good.json");
    std::string scene((std::istreambuf_iterator<char>(in)), {});
    scene.insert(scene.rfind('}'), R"(, "solver": {"bounces": true, "max_bounces": 2})");
    std::ofstream(m_dir / "bounces.json") << scene;
    const fs::path bounces = m_dir / "bounces";
    ASSERT_EQ(run("render " + (m_dir / "bounces.json").string() + " -o " + bounces.string()).status, 0);
    const Outcome b = run("sensor " + bounces.string() + " " + (m_dir / "gates.json").string() +
                          " --cube transient_bounce_1 --name first");
    ASSERT_EQ(b.status, 0) << b.err;
    EXPECT_TRUE(fs::exists(bounces / "sensor-first" / "measurements.npy"));
    const Outcome missing = run("sensor " + bounces.string() + " " + (m_dir / "gates.json").string() + " --cube capture");
    EXPECT_EQ(missing.status, 2);
    EXPECT_NE(missing.err.find("--cube capture: " + bounces.string() + " has no capture.npy (cubes there: transient, "
                               "transient_bounce_0, transient_bounce_1, transient_bounce_2)"),
              std::string::npos)
        << missing.err;
    const Outcome bad_name = run("sensor " + out.string() + " " + (m_dir / "gates.json").string() + " --name ../up");
    EXPECT_EQ(bad_name.status, 2);
    EXPECT_NE(bad_name.err.find("--name \"../up\""), std::string::npos) << bad_name.err;
    EXPECT_FALSE(fs::exists(out / "sensor-.."));
    // A render into the same directory replaces everything of the earlier one: its ground truth maps
    // and the sensors' folders, which measured the old cube.
    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + out.string()).status, 0);
    EXPECT_FALSE(fs::exists(out / "sensor-amcw"));
    EXPECT_FALSE(fs::exists(out / "sensor-gates"));
    EXPECT_FALSE(fs::exists(out / "aov_depth.npy"));
    EXPECT_TRUE(fs::exists(out / "transient.npy"));
}

TEST_F(Cli, BadSensorInputExitsTwoAndWritesNothing) {
    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string()).status, 0);
    std::ofstream(m_dir / "bad_sensor.json") << R"({"exposure": {"type": "gates", "start": 0, "width": -1, "step": 1, "count": 2}})";
    Outcome r = run("sensor " + (m_dir / "out").string() + " " + (m_dir / "bad_sensor.json").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("bad_sensor.json: exposure.width: must be > 0"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(m_dir / "out" / "sensor-bad_sensor"));

    std::ofstream(m_dir / "sensor.json") << R"({"sensor": {"exposure": {"type": "amcw", "frequency_mhz": 30}}})";
    r = run("sensor " + m_dir.string() + " " + (m_dir / "sensor.json").string());  // not a render directory
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("no render.json"), std::string::npos) << r.err;
    r = run("sensor " + (m_dir / "out").string() + " " + (m_dir / "sensor.json").string() + " --plot-pixel 8,0");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("outside the 8 x 8 image"), std::string::npos) << r.err;
    r = run("sensor " + (m_dir / "out").string() + " " + (m_dir / "sensor.json").string() + " --plot-pixel 3");
    EXPECT_EQ(r.status, 2);
    r = run("sensor " + (m_dir / "out").string() + " " + (m_dir / "sensor.json").string() +
            " --plot-pixel 99999999999,1");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("expected X,Y"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(m_dir / "out" / "sensor-sensor"));
}

}  // namespace
