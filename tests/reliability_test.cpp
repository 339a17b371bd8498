// Runs that are interrupted, that meet a full disk or a memory limit, or that race another run for
// the same output directory (docs/reliability.md). Each starts the real `tprf` binary, and each
// checks what docs/cli.md promises: the exit status, one message naming the cause, and an output
// directory that holds exactly the earlier run's files, byte for byte, with no staging folder left.
#include "test_process.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;
using tprf::test::Outcome;
using tprf::test::read_bytes;
using tprf::test::shell;

// Every file under `dir` (hidden ones included) with its bytes.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
    std::map<std::string, std::string> files;
    for (const auto& e : fs::recursive_directory_iterator(dir))
        files[fs::relative(e.path(), dir).string()] = e.is_regular_file() ? read_bytes(e.path()) : "<dir>";
    return files;
}

void expect_same_files(const std::map<std::string, std::string>& before, const fs::path& dir) {
    const std::map<std::string, std::string> after = snapshot(dir);
    for (const auto& [name, bytes] : after) {
        const auto it = before.find(name);
        if (it == before.end())
            ADD_FAILURE() << dir / name << " was left behind";
        else
            EXPECT_TRUE(it->second == bytes) << dir / name << " changed";
    }
    for (const auto& [name, bytes] : before) EXPECT_TRUE(after.count(name)) << dir / name << " was removed";
}

// The two-plane corner (meshes/corner.json) at patch size `max_edge`, a small image and `bins` bins.
json corner(double max_edge, int bins, int width = 32, int height = 24) {
    std::ifstream in(fs::path(TPRF_SOURCE_DIR) / "meshes" / "corner.json");
    json scene = json::parse(in);
    scene["patches"]["max_edge"] = max_edge;
    scene["time"]["bins"] = bins;
    scene["camera"]["width"] = width;
    scene["camera"]["height"] = height;
    scene["camera"]["spp"] = 1;
    return scene;
}

// `tprf render SCENE -o OUT --progress-lines ARGS` as a child whose stderr is read line by line, so
// that a test can act when a stage starts.
class Render {
public:
    Render(const fs::path& scene, const fs::path& out, const std::vector<std::string>& args = {}) {
        int fds[2];
        if (::pipe(fds) != 0) throw std::runtime_error("pipe");
        std::vector<std::string> argv = {TPRF_BINARY, "render", scene.string(), "-o", out.string(), "--progress-lines",
                                         "--threads", "2"};
        argv.insert(argv.end(), args.begin(), args.end());
        m_pid = ::fork();
        if (m_pid == 0) {
            ::dup2(fds[1], 2);
            ::close(fds[0]);
            ::close(fds[1]);
            const int null = ::open("/dev/null", O_WRONLY);
            ::dup2(null, 1);
            std::vector<char*> raw;
            for (std::string& a : argv) raw.push_back(a.data());
            raw.push_back(nullptr);
            ::execv(raw[0], raw.data());
            ::_exit(127);
        }
        ::close(fds[1]);
        m_err = ::fdopen(fds[0], "r");
    }
    ~Render() {
        if (m_pid > 0 && !m_reaped) {
            ::kill(m_pid, SIGKILL);
            ::waitpid(m_pid, nullptr, 0);
        }
        if (m_err) std::fclose(m_err);
    }

    // Reads stderr until a line starts with `prefix`; false at its end (the child exited first).
    bool wait_for_line(const std::string& prefix) {
        char line[4096];
        while (std::fgets(line, sizeof line, m_err)) {
            m_text += line;
            if (std::string(line).rfind(prefix, 0) == 0) return true;
        }
        return false;
    }

    void signal(int sig) {
        m_signalled = Clock::now();
        ::kill(m_pid, sig);
    }

    // The child's exit status (-1 when it did not exit normally, e.g. killed by a signal's default
    // action), after at most `limit`: a child that hangs is killed and the test fails.
    int wait(std::chrono::seconds limit = std::chrono::seconds(60)) {
        int status = 0;
        const auto deadline = Clock::now() + limit;
        while (::waitpid(m_pid, &status, WNOHANG) == 0) {
            if (Clock::now() > deadline) {
                ADD_FAILURE() << "tprf did not stop within " << limit.count() << " s of the signal";
                ::kill(m_pid, SIGKILL);
                ::waitpid(m_pid, &status, 0);
                break;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        m_reaped = true;
        m_seconds = std::chrono::duration<double>(Clock::now() - m_signalled).count();
        char line[4096];
        while (std::fgets(line, sizeof line, m_err)) m_text += line;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }

    const std::string& text() const { return m_text; }
    double seconds_after_signal() const { return m_seconds; }

private:
    pid_t m_pid = -1;
    bool m_reaped = false;
    FILE* m_err = nullptr;
    std::string m_text;
    Clock::time_point m_signalled = Clock::now();
    double m_seconds = 0.0;
};

class Reliability : public ::testing::Test {
protected:
    void SetUp() override {
        m_dir = fs::temp_directory_path() / ("tprf_reliability_" + std::to_string(::getpid()) + "_" +
                                             ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }

    fs::path write_scene(const std::string& name, const json& scene) const {
        const fs::path file = m_dir / (name + ".json");
        std::ofstream(file) << scene.dump(2);
        return file;
    }

    // A finished render of a small corner into `out`: the earlier outputs that later runs must keep.
    std::map<std::string, std::string> earlier_render(const fs::path& out) const {
        const Outcome r = tprf::test::run_tprf("render " + write_scene("small", corner(0.1, 64)).string() + " -o " +
                                               out.string());
        EXPECT_EQ(r.status, 0) << r.err;
        return snapshot(out);
    }

    // A scene whose link stage takes seconds (5,000 patches, flat links), so that a signal lands inside it.
    fs::path slow_links() const {
        json scene = corner(0.02, 64);
        scene["links"] = {{"method", "flat"}};
        return write_scene("slow_links", scene);
    }

    // Stops a run at the start of stage `stage` with `sig`; returns its exit status.
    int interrupt(Render& run, const std::string& stage, int sig) {
        EXPECT_TRUE(run.wait_for_line("tprf: " + stage + " ")) << run.text();
        run.signal(sig);
        const int status = run.wait();
        std::printf("stopped %.3f s after the signal, in the %s stage\n", run.seconds_after_signal(), stage.c_str());
        return status;
    }

    fs::path m_dir;
};

TEST_F(Reliability, SigintDuringTheLinkStageStopsTheRunAndKeepsEarlierOutputs) {
    const fs::path out = m_dir / "out";
    const auto before = earlier_render(out);
    Render run(slow_links(), out);
    EXPECT_EQ(interrupt(run, "links", SIGINT), 130) << run.text();
    EXPECT_NE(run.text().find("cancelled by SIGINT in the links stage"), std::string::npos) << run.text();
    expect_same_files(before, out);
}

TEST_F(Reliability, SigtermWhileWritingStopsTheRunAndKeepsEarlierOutputs) {
    const fs::path out = m_dir / "out";
    const auto before = earlier_render(out);
    // 3,000 frames: seconds of writing after the "write" line.
    Render run(write_scene("frames", corner(0.1, 3000)), out, {"--frames"});
    EXPECT_EQ(interrupt(run, "write", SIGTERM), 143) << run.text();
    EXPECT_NE(run.text().find("cancelled by SIGTERM in the write stage"), std::string::npos) << run.text();
    expect_same_files(before, out);
}

TEST_F(Reliability, ASecondRunIntoTheSameDirectoryIsRefusedWhileTheFirstRuns) {
    const fs::path out = m_dir / "out";
    const auto before = earlier_render(out);
    Render first(slow_links(), out);
    ASSERT_TRUE(first.wait_for_line("tprf: links ")) << first.text();
    const Outcome second = tprf::test::run_tprf("render " + write_scene("small", corner(0.1, 64)).string() + " -o " +
                                                out.string());
    EXPECT_EQ(second.status, 2);
    EXPECT_NE(second.err.find("another tprf run is writing into this output directory"), std::string::npos)
        << second.err;
    first.signal(SIGTERM);
    EXPECT_EQ(first.wait(), 143) << first.text();
    expect_same_files(before, out);
}

TEST_F(Reliability, AKilledRunsStagingFolderIsRemovedByTheNextRun) {
    const fs::path out = m_dir / "out";
    earlier_render(out);
    Render killed(slow_links(), out);
    ASSERT_TRUE(killed.wait_for_line("tprf: links ")) << killed.text();
    killed.signal(SIGKILL);  // no handler runs: the staging folder stays behind
    EXPECT_EQ(killed.wait(), -1);
    bool left = false;
    for (const auto& e : fs::directory_iterator(out)) left |= e.path().filename().string().rfind(".tprf-staging-", 0) == 0;
    EXPECT_TRUE(left) << "SIGKILL left no staging folder: this test no longer tests the clean-up";
    const auto after = earlier_render(out);
    for (const auto& [name, bytes] : after) EXPECT_EQ(name.rfind(".tprf-staging-", 0), std::string::npos) << name;
}

TEST_F(Reliability, AFileSizeLimitFailsNamingTheFileAndKeepsEarlierOutputs) {
    const fs::path out = m_dir / "out";
    const auto before = earlier_render(out);
    // 64 KiB: the cube (32 x 24 x 800 x 12 bytes) cannot be created; write() past the limit fails with
    // EFBIG (tprf ignores SIGXFSZ, which would otherwise kill it).
    const Outcome r = shell("ulimit -f 64; " + std::string(TPRF_BINARY) + " render " +
                            write_scene("big", corner(0.1, 800)).string() + " -o " + out.string() + " -q");
    EXPECT_EQ(r.status, 1) << r.err;
    EXPECT_NE(r.err.find((out / "transient.npy").string() + ": cannot"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("File too large"), std::string::npos) << r.err;
    expect_same_files(before, out);
}

TEST_F(Reliability, AFullFileSystemFailsNamingTheFileAndKeepsEarlierOutputs) {
    // A 2 MiB tmpfs: the earlier render (0.6 MB) fits, the second (1.6 MB with its frames) does not.
    const fs::path mount = m_dir / "small";
    fs::create_directories(mount);
    if (std::system(("mount -t tmpfs -o size=2M tmpfs " + mount.string() + " 2>/dev/null").c_str()) != 0)
        GTEST_SKIP() << "cannot mount a small tmpfs here (needs root)";
    const fs::path out = mount / "out";
    const auto before = earlier_render(out);
    const Outcome r = tprf::test::run_tprf("render " + write_scene("frames", corner(0.1, 120)).string() + " -o " +
                                           out.string() + " --frames");
    EXPECT_EQ(r.status, 1) << r.err;
    EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(out.string() + "/"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find(".tprf-staging"), std::string::npos) << "the message names staging paths: " << r.err;
    expect_same_files(before, out);
    EXPECT_EQ(std::system(("umount " + mount.string()).c_str()), 0);
}

#ifndef TPRF_TESTS_SANITIZED  // AddressSanitizer reserves terabytes of address space: no ulimit -v
TEST_F(Reliability, AnAddressSpaceLimitIsRefusedUpFrontOrAClearOutOfMemoryError) {
    const fs::path out = m_dir / "out";
    const auto before = earlier_render(out);
    const std::string render = std::string(TPRF_BINARY) + " render " +
                               write_scene("big", corner(0.03, 800, 96, 64)).string() + " -o " + out.string() + " -q";
    // The limit counts toward the memory available: the render is refused before it allocates.
    const Outcome refused = shell("ulimit -v 300000; " + render);
    EXPECT_EQ(refused.status, 2) << refused.err;
    EXPECT_NE(refused.err.find("ulimit -v"), std::string::npos) << refused.err;
    // Told to ignore the estimate, the render meets the limit: one message, exit 1, not an abort.
    const Outcome failed = shell("ulimit -v 300000; " + render + " --max-memory 100");
    EXPECT_EQ(failed.status, 1) << failed.err;
    EXPECT_NE(failed.err.find("tprf: error: "), std::string::npos) << failed.err;
    EXPECT_TRUE(failed.err.find("out of memory") != std::string::npos ||
                failed.err.find("Cannot allocate memory") != std::string::npos)
        << failed.err;
    expect_same_files(before, out);
}
#endif

}  // namespace
