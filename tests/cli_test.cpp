// The command line's contract (SPEC.md, "Command line"): exit status 2 and one message for bad input,
// and nothing written for it.
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

}  // namespace
