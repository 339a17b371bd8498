// The command line's contract (SPEC.md, "Command line"): exit status 2 and one message for bad input,
// and nothing written for it.
#include "tprf/io/npy.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <sys/wait.h>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

namespace {

namespace fs = std::filesystem;

struct Outcome {
    int status = -1;
    std::string err;
};

Outcome run(const std::string& args) {
    const fs::path err = fs::temp_directory_path() / ("tprf_cli_err_" + std::to_string(std::random_device{}()));
    const std::string command = std::string(TPRF_BINARY) + " " + args + " -q >/dev/null 2>" + err.string();
    const int raw = std::system(command.c_str());
    Outcome r;
    r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
    std::ifstream in(err);
    r.err.assign(std::istreambuf_iterator<char>(in), {});
    fs::remove(err);
    return r;
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
    fs::path m_dir;
};

TEST_F(Cli, BadSceneExitsTwoWithThePathAndWritesNothing) {
    const Outcome r = run("render " + (m_dir / "bad.json").string() + " -o " + (m_dir / "out").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("time.bins"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(m_dir / "out"));
}

TEST_F(Cli, MissingSceneFileExitsTwo) {
    const Outcome r = run("info " + (m_dir / "nope.json").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("nope.json"), std::string::npos) << r.err;
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
    for (const char* f : {"measurements.npy", "sensor_plot.png", "sensor.json"}) {
        EXPECT_TRUE(fs::is_regular_file(m_dir / "a" / f)) << f;
        EXPECT_TRUE(fs::is_regular_file(m_dir / "b" / f)) << f;
    }
    const tprf::NpyArray a = tprf::read_npy(m_dir / "a" / "measurements.npy");
    const tprf::NpyArray b = tprf::read_npy(m_dir / "b" / "measurements.npy");
    EXPECT_EQ(a.shape, (std::vector<std::size_t>{8, 8, 5, 3}));
    EXPECT_EQ(a.data, b.data);
    // A scene file with a sensor block serves as the sensor file too.
    const Outcome again = run("sensor " + (m_dir / "b").string() + " " + (m_dir / "with_sensor.json").string());
    ASSERT_EQ(again.status, 0) << again.err;
    EXPECT_EQ(tprf::read_npy(m_dir / "b" / "measurements.npy").data, a.data);
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

TEST_F(Cli, SensorRunsReplaceEachOthersOutputs) {
    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string()).status, 0);
    std::ofstream(m_dir / "amcw.json") << R"({"exposure": {"type": "amcw", "frequency_mhz": 20}})";
    std::ofstream(m_dir / "gates.json") << R"({"exposure": {"type": "gates", "start": 0, "width": 0.5, "step": 0.5, "count": 3}})";
    ASSERT_EQ(run("sensor " + (m_dir / "out").string() + " " + (m_dir / "amcw.json").string()).status, 0);
    EXPECT_TRUE(fs::exists(m_dir / "out" / "depth.npy"));
    ASSERT_EQ(run("sensor " + (m_dir / "out").string() + " " + (m_dir / "gates.json").string()).status, 0);
    EXPECT_FALSE(fs::exists(m_dir / "out" / "depth.npy")) << "an AMCW depth beside gated measurements";
    EXPECT_EQ(tprf::read_npy(m_dir / "out" / "measurements.npy").shape, (std::vector<std::size_t>{8, 8, 3, 3}));
    // A render without a sensor block into the same directory leaves no measurements of the old cube.
    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string()).status, 0);
    EXPECT_FALSE(fs::exists(m_dir / "out" / "measurements.npy"));
    EXPECT_TRUE(fs::exists(m_dir / "out" / "transient.npy"));
}

TEST_F(Cli, BadSensorInputExitsTwoAndWritesNothing) {
    ASSERT_EQ(run("render " + (m_dir / "good.json").string() + " -o " + (m_dir / "out").string()).status, 0);
    std::ofstream(m_dir / "bad_sensor.json") << R"({"exposure": {"type": "gates", "start": 0, "width": -1, "step": 1, "count": 2}})";
    Outcome r = run("sensor " + (m_dir / "out").string() + " " + (m_dir / "bad_sensor.json").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("bad_sensor.json: exposure.width: must be > 0"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(m_dir / "out" / "measurements.npy"));

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
    EXPECT_FALSE(fs::exists(m_dir / "out" / "measurements.npy"));
    EXPECT_FALSE(fs::exists(m_dir / "out" / "depth.npy"));
}

}  // namespace
