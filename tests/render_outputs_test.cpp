// Full renders through the command line (`tprf render`, `tprf sensor`), each output checked against a
// number that geometry or physics fixes in advance: arrival bins from path lengths, closed-form view
// factors, energy conservation, and the shapes and orientation docs/outputs.md gives. Scenes are small (a few
// hundred patches, images of at most 64 x 64), except the Cornell box.
#include "test_process.h"
#include "test_scenes.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/io/npy.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <ImathBox.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using tprf::Vec3;
using tprf::test::Outcome;
using tprf::test::read_bytes;
using tprf::test::run_tprf;
using tprf::test::shell;

// A path known from geometry is compared with a bin only when it lies at least this far from the bin's
// edges: Embree intersects in float and the film carries the camera leg as a float, so a rendered path
// is known to about 1e-6 of its length (3e-6 m over 3 m), and a path this close to an edge may round
// into either bin.
constexpr double kEdge = 1e-4;

/// The bin that holds an optical path (metres) on an axis of `width` from `start`, or nothing when the
/// path lies within kEdge of a bin edge.
std::optional<int> bin_of(double path, double width, double start = 0.0) {
    const double x = (path - start) / width;
    const double k = std::floor(x);
    if ((x - k) * width < kEdge || (k + 1 - x) * width < kEdge) return std::nullopt;
    return int(k);
}

json vec(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

bool have_program(const std::string& name) {
    return std::system(("command -v " + name + " >/dev/null 2>&1").c_str()) == 0;
}

// transient.npy and its kind, (H, W, T, 3) float32.
struct Cube {
    tprf::NpyArray a;
    int H() const { return int(a.shape[0]); }
    int W() const { return int(a.shape[1]); }
    int T() const { return int(a.shape[2]); }
    float at(int r, int c, int t, int ch = 0) const {
        const std::size_t pixel = std::size_t(r) * a.shape[1] + std::size_t(c);
        return a.data[(pixel * a.shape[2] + std::size_t(t)) * 3 + std::size_t(ch)];
    }
    /// The first bin of pixel (r, c) that holds any light, or -1.
    int first_bin(int r, int c, int ch = 0) const {
        for (int t = 0; t < T(); ++t)
            if (at(r, c, t, ch) != 0.0f) return t;
        return -1;
    }
    /// The sum of pixel (r, c)'s bins [from, to), in double.
    double sum(int r, int c, int ch, int from = 0, int to = std::numeric_limits<int>::max()) const {
        double s = 0.0;
        for (int t = from; t < std::min(to, T()); ++t) s += at(r, c, t, ch);
        return s;
    }
};

Cube read_cube(const fs::path& file) {
    Cube c{tprf::read_npy(file)};
    EXPECT_EQ(c.a.shape.size(), 4u) << file;
    if (c.a.shape.size() != 4) c.a.shape = {0, 0, 0, 3};
    return c;
}

// steady.npy, (H, W, 3).
struct Image {
    tprf::NpyArray a;
    float at(int r, int c, int ch = 0) const {
        return a.data[(std::size_t(r) * a.shape[1] + std::size_t(c)) * 3 + std::size_t(ch)];
    }
};

Image read_image(const fs::path& file) {
    Image im{tprf::read_npy(file)};
    EXPECT_EQ(im.a.shape.size(), 3u) << file;
    return im;
}

// An OpenEXR file read through OpenEXR itself, as 32-bit floats: width x height x RGB, row 0 first.
struct Exr {
    int width = 0;
    int height = 0;
    std::vector<float> rgb;
    float at(int x, int y, int ch = 0) const {
        return rgb[(std::size_t(y) * std::size_t(width) + std::size_t(x)) * 3 + std::size_t(ch)];
    }
};

Exr read_exr(const fs::path& file) {
    Imf::InputFile in(file.c_str());
    const Imath::Box2i dw = in.header().dataWindow();
    Exr im;
    im.width = dw.max.x - dw.min.x + 1;
    im.height = dw.max.y - dw.min.y + 1;
    im.rgb.assign(std::size_t(im.width) * std::size_t(im.height) * 3, std::numeric_limits<float>::quiet_NaN());
    Imf::FrameBuffer fb;
    const char* names[3] = {"R", "G", "B"};
    const std::ptrdiff_t origin = (std::ptrdiff_t(dw.min.y) * im.width + dw.min.x) * 3;
    for (int ch = 0; ch < 3; ++ch) {
        const Imf::Channel* channel = in.header().channels().findChannel(names[ch]);
        EXPECT_TRUE(channel && channel->type == Imf::FLOAT) << file << ": channel " << names[ch] << " is not FLOAT";
        fb.insert(names[ch], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(im.rgb.data() + ch - origin),
                                        3 * sizeof(float), 3 * sizeof(float) * std::size_t(im.width)));
    }
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    return im;
}

// The pinhole camera of docs/scene.md: vertical fov in degrees, row 0 the top of the image; column 0 its left
// (right = forward x up). Written here from the spec, not taken from the library.
struct Pinhole {
    Vec3 position, forward, right, up;
    double tan_half = 0.0;
    int width = 0, height = 0;

    explicit Pinhole(const json& cam) {
        const auto v = [&](const char* key) { return Vec3(cam[key][0], cam[key][1], cam[key][2]); };
        position = v("position");
        forward = (v("look_at") - position).normalized();
        right = forward.cross(v("up")).normalized();
        up = right.cross(forward);
        tan_half = std::tan(0.5 * double(cam["fov"]) * M_PI / 180.0);
        width = cam["width"];
        height = cam["height"];
    }
    /// The unit ray through the image point (column, row), in pixels from the top left corner.
    Vec3 ray(double column, double row) const {
        const double x = (2.0 * column / width - 1.0) * tan_half * width / height;
        const double y = (1.0 - 2.0 * row / height) * tan_half;
        return (forward + x * right + y * up).normalized();
    }
};

// Distance along the unit ray (o, d) to the plane through p with normal n; infinity when it never gets there.
double to_plane(const Vec3& o, const Vec3& d, const Vec3& p, const Vec3& n) {
    const double denom = d.dot(n);
    if (denom == 0.0) return std::numeric_limits<double>::infinity();
    const double t = (p - o).dot(n) / denom;
    return t > 0 ? t : std::numeric_limits<double>::infinity();
}

// Whether x (on the rectangle's plane) lies inside the rectangle origin + [0,1] u + [0,1] v (u, v orthogonal).
bool inside(const Vec3& x, const Vec3& origin, const Vec3& u, const Vec3& v) {
    const double a = (x - origin).dot(u) / u.squaredNorm(), b = (x - origin).dot(v) / v.squaredNorm();
    return a > 0 && a < 1 && b > 0 && b < 1;
}

// Radiance a Lambertian point of albedo rho sends to the camera under an isotropic point light
// (docs/scene.md: irradiance I cos / r^2, radiance B / pi).
double lambert_point(double rho, double intensity, const Vec3& light, const Vec3& x, const Vec3& normal) {
    const Vec3 d = light - x;
    return rho / M_PI * intensity * std::max(0.0, normal.dot(d) / d.norm()) / d.squaredNorm();
}

class RenderOutputs : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        m_dir = fs::temp_directory_path() /
                ("tprf_outputs_" + std::string(info->name()) + "_" + std::to_string(std::random_device{}()));
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }

    fs::path write_json(const std::string& name, const json& j) const {
        const fs::path file = m_dir / (name + ".json");
        std::ofstream(file) << j.dump(2);
        return file;
    }

    /// Renders `scene` into m_dir/name; an empty path (and a failure) when tprf does not exit 0.
    fs::path render(const std::string& name, const json& scene, const std::string& flags = "", int threads = 2) {
        const fs::path out = m_dir / name;
        const Outcome r = run_tprf("render " + write_json(name, scene).string() + " -o " + out.string() +
                                   " --threads " + std::to_string(threads) + " " + flags);
        if (r.status != 0) {
            ADD_FAILURE() << "tprf render " << name << " exited " << r.status << ": " << r.err;
            return {};
        }
        return out;
    }

    fs::path m_dir;
};

// A plane z = 0 (4 x 4 m) under a point light, seen from straight above.
json lit_plane(int bins, double bin_width, int width, int height, int spp = 1) {
    return {{"time", {{"bins", bins}, {"bin_width", bin_width}}},
            {"camera", {{"position", {0, 0, 1.5}}, {"look_at", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov", 60},
                        {"width", width}, {"height", height}, {"spp", spp}}},
            {"lights", {{{"type", "point"}, {"position", {0.3, -0.2, 0.8}}, {"intensity", 2.0}}}},
            {"objects", {{{"type", "rectangle"}, {"origin", {-2, -2, 0}}, {"u", {4, 0, 0}}, {"v", {0, 4, 0}},
                          {"albedo", 0.6}}}},
            {"patches", {{"max_edge", 0.5}}}};
}

// The two-plane corner of render_test.cpp (floor z = 0 and wall x = 0, 1 x 1 m) under a point light.
json corner(int bins, double bin_width) {
    return {{"time", {{"bins", bins}, {"bin_width", bin_width}}},
            {"camera", {{"position", {1.6, 0.5, 0.6}}, {"look_at", {0.3, 0.5, 0.3}}, {"up", {0, 0, 1}}, {"fov", 60},
                        {"width", 24}, {"height", 20}}},
            {"lights", {{{"type", "point"}, {"position", {0.6, 0.3, 0.7}}, {"intensity", 1.0}}}},
            {"objects",
             {{{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", 0.6}},
              {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {0, 1, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.5}}}},
            {"patches", {{"max_edge", 0.1}}}};
}

// What the corner's camera sees at pixel (r, c)'s centre: the point, its distance and which plane
// (0 floor, 1 wall); nothing past the corner's edges.
struct CornerHit {
    Vec3 x;
    double leg = 0.0;
    int plane = -1;
};

std::optional<CornerHit> corner_hit(const Pinhole& cam, int r, int c) {
    const Vec3 d = cam.ray(c + 0.5, r + 0.5);
    std::optional<CornerHit> best;
    const double tf = to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ());
    const Vec3 xf = cam.position + tf * d;
    if (std::isfinite(tf) && inside(xf, Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY())) best = CornerHit{xf, tf, 0};
    const double tw = to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitX());
    const Vec3 xw = cam.position + tw * d;
    if (std::isfinite(tw) && inside(xw, Vec3::Zero(), Vec3::UnitY(), Vec3::UnitZ()) && (!best || tw < best->leg))
        best = CornerHit{xw, tw, 1};
    return best;
}

// ---------------------------------------------------------------------------------------------------

TEST_F(RenderOutputs, VideoHasOneFramePerBinAndStaysDarkUntilTheFirstArrival) {
    // 32 x 24 (even: yuv420p needs no padding), 40 bins of 0.1 m.
    const int W = 32, H = 24, T = 40;
    const double w = 0.1;
    const json scene = lit_plane(T, w, W, H);
    if (!have_program("ffmpeg")) {
        // tprf refuses --video up front without ffmpeg (README) and writes nothing.
        const Outcome r = run_tprf("render " + write_json("plane", scene).string() + " -o " + (m_dir / "out").string() +
                                   " --video");
        EXPECT_EQ(r.status, 2) << r.err;
        EXPECT_NE(r.err.find("needs ffmpeg"), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(m_dir / "out"));
        GTEST_SKIP() << "ffmpeg is not installed (Debian: apt-get install ffmpeg); scripts/setup.sh does not install "
                        "it, so CI checks only that --video is refused without it";
    }
    const fs::path out = render("plane", scene, "--video");
    ASSERT_FALSE(out.empty());
    const fs::path mp4 = out / "light_in_flight.mp4";
    const std::string bytes = read_bytes(mp4);
    ASSERT_GT(bytes.size(), 12u) << mp4;
    EXPECT_EQ(bytes.substr(4, 4), "ftyp") << "an MP4 (ISO base media) file starts with its ftyp box";
    EXPECT_TRUE(fs::is_regular_file(out / "transient.npy"));
    EXPECT_FALSE(fs::exists(out / ".video-frames"));

    if (!have_program("ffprobe")) GTEST_SKIP() << "ffprobe is not installed: cannot count the video's frames";
    const fs::path probe = m_dir / "probe.json";
    const Outcome p = shell("ffprobe -v error -count_frames -select_streams v:0 -show_entries "
                            "stream=codec_name,width,height,nb_read_frames -of json '" +
                            mp4.string() + "' >" + probe.string());
    ASSERT_EQ(p.status, 0) << p.err;
    const json j = json::parse(std::ifstream(probe));
    ASSERT_EQ(j["streams"].size(), 1u) << j.dump();
    const json& s = j["streams"][0];
    EXPECT_EQ(s["codec_name"], "h264");
    EXPECT_EQ(s["width"], W);
    EXPECT_EQ(s["height"], H);
    EXPECT_EQ(std::stoi(s["nb_read_frames"].get<std::string>()), T) << "one frame per time bin";

    // Decoded to 8-bit grey: frame t is bin t. No light reaches the camera before the shortest path
    // light -> plane -> camera over the pixel centres; before that bin every frame is black. A black
    // frame encodes to black; 2 levels allow for H.264's rounding (measured: exactly 0).
    const Pinhole cam(scene["camera"]);
    const Vec3 light(0.3, -0.2, 0.8);
    double shortest = std::numeric_limits<double>::infinity();
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c) {
            const Vec3 d = cam.ray(c + 0.5, r + 0.5);
            const double t = to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ());
            shortest = std::min(shortest, t + (light - (cam.position + t * d)).norm());
        }
    const std::optional<int> first = bin_of(shortest, w);
    ASSERT_TRUE(first && *first > 5 && *first < T) << shortest;
    const fs::path raw = m_dir / "frames.gray";
    const Outcome d =
        shell("ffmpeg -v error -i '" + mp4.string() + "' -f rawvideo -pix_fmt gray '" + raw.string() + "'");
    ASSERT_EQ(d.status, 0) << d.err;
    const std::string grey = read_bytes(raw);
    ASSERT_EQ(grey.size(), std::size_t(T) * W * H);
    const auto frame_max = [&](int t) {
        int m = 0;
        for (int i = 0; i < W * H; ++i)
            m = std::max(m, int(static_cast<unsigned char>(grey[std::size_t(t * W * H + i)])));
        return m;
    };
    for (int t = 0; t < *first; ++t) EXPECT_LE(frame_max(t), 2) << "frame " << t << " shows light before it can arrive";
    // The cube's brightest bin is above the 99.5th percentile that sets the video's exposure, so it is
    // white in its frame (200 of 255 leaves room for the codec).
    const Cube cube = read_cube(out / "transient.npy");
    std::size_t brightest = 0;
    for (std::size_t i = 0; i < cube.a.data.size(); ++i)
        if (cube.a.data[i] > cube.a.data[brightest]) brightest = i;
    EXPECT_GE(frame_max(int(brightest / 3 % std::size_t(T))), 200);
}

TEST_F(RenderOutputs, FramesAndStreaksAreSlicesOfTheCubeWithRowZeroAtTheTop) {
    // A wall (the plane x = 0, facing +x, y in [-1.5, 1.5], z in [0, 2]) seen from x = 3 and lit from
    // its upper left: first arrivals grow towards the bottom and the right of the image, so a flipped
    // or mirrored image cannot match. The top and bottom rows look past the wall. A window of 64 bins
    // of 5 cm from 3.5 m holds every path (3.82 to 6.49 m).
    const int W = 32, H = 24, T = 64;
    const double w = 0.05, start = 3.5;
    const Vec3 light(0.6, -1.0, 1.8), corner0(0, -1.5, 0), u(0, 3, 0), v(0, 0, 2);
    const json scene = {
        {"time", {{"bins", T}, {"bin_width", w}, {"start", start}}},
        {"camera", {{"position", {3, 0, 1}}, {"look_at", {0, 0, 1}}, {"up", {0, 0, 1}}, {"fov", 40},
                    {"width", W}, {"height", H}, {"footprint", false}}},  // point samples: exact first bins
        {"lights", {{{"type", "point"}, {"position", vec(light)}, {"intensity", 1.0}}}},
        {"objects", {{{"type", "rectangle"}, {"origin", vec(corner0)}, {"u", vec(u)}, {"v", vec(v)}, {"albedo", 0.5}}}},
        {"patches", {{"max_edge", 0.25}}}};
    const fs::path out = render("wall", scene, "--frames --streaks");
    ASSERT_FALSE(out.empty());
    const Cube cube = read_cube(out / "transient.npy");
    ASSERT_EQ(cube.a.shape, (std::vector<std::size_t>{std::size_t(H), std::size_t(W), std::size_t(T), 3}));

    // Each pixel's first lit bin from geometry (-1: it sees nothing; -2: its path lies on a bin edge).
    const Pinhole cam(scene["camera"]);
    std::vector<int> expected(std::size_t(W * H), -1);
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c) {
            const Vec3 d = cam.ray(c + 0.5, r + 0.5);
            const double t = to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitX());
            const Vec3 x = cam.position + t * d;
            if (!inside(x, corner0, u, v)) continue;
            expected[std::size_t(r * W + c)] = bin_of(t + (light - x).norm(), w, start).value_or(-2);
        }
    // The test can fail: flipping the image either way changes most lit pixels' first bins.
    int lit = 0, differ_vertically = 0, differ_horizontally = 0;
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c) {
            const int e = expected[std::size_t(r * W + c)];
            if (e < 0) continue;
            ++lit;
            differ_vertically += e != expected[std::size_t((H - 1 - r) * W + c)];
            differ_horizontally += e != expected[std::size_t(r * W + (W - 1 - c))];
        }
    ASSERT_GT(lit, W * H / 2);
    ASSERT_GT(differ_vertically, lit / 2);
    ASSERT_GT(differ_horizontally, lit / 2);

    // frames/frame_NNNNN.exr is bin NNNNN of the cube, row 0 at the top, bit for bit.
    std::vector<int> first_in_frames(std::size_t(W * H), -1);
    ASSERT_EQ(std::distance(fs::directory_iterator(out / "frames"), fs::directory_iterator()), T);
    for (int t = 0; t < T; ++t) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%05d.exr", t);
        const Exr frame = read_exr(out / "frames" / name);
        ASSERT_EQ(frame.width, W) << name;
        ASSERT_EQ(frame.height, H) << name;
        int mismatches = 0;
        for (int r = 0; r < H; ++r)
            for (int c = 0; c < W; ++c) {
                for (int ch = 0; ch < 3; ++ch)
                    mismatches += frame.at(c, r, ch) != cube.at(r, c, t, ch);
                int& first = first_in_frames[std::size_t(r * W + c)];
                if (frame.at(c, r) != 0.0f && first < 0) first = t;
            }
        EXPECT_EQ(mismatches, 0) << name << " is not bin " << t << " of transient.npy";
    }
    // streaks/row_NNNN.exr is image row NNNN: W columns, T rows, time downward.
    std::vector<int> first_in_streaks(std::size_t(W * H), -1);
    ASSERT_EQ(std::distance(fs::directory_iterator(out / "streaks"), fs::directory_iterator()), H);
    for (int r = 0; r < H; ++r) {
        char name[32];
        std::snprintf(name, sizeof name, "row_%04d.exr", r);
        const Exr streak = read_exr(out / "streaks" / name);
        ASSERT_EQ(streak.width, W) << name;
        ASSERT_EQ(streak.height, T) << name;
        int mismatches = 0;
        for (int t = 0; t < T; ++t)
            for (int c = 0; c < W; ++c) {
                for (int ch = 0; ch < 3; ++ch)
                    mismatches += streak.at(c, t, ch) != cube.at(r, c, t, ch);
                int& first = first_in_streaks[std::size_t(r * W + c)];
                if (streak.at(c, t) != 0.0f && first < 0) first = t;
            }
        EXPECT_EQ(mismatches, 0) << name << " is not row " << r << " of transient.npy";
    }
    // Read from the EXRs alone, every pixel's first light is where geometry puts it.
    int checked = 0;
    for (int i = 0; i < W * H; ++i) {
        const int e = expected[std::size_t(i)];
        if (e == -2) continue;
        EXPECT_EQ(first_in_frames[std::size_t(i)], e) << "frames, pixel row " << i / W << " column " << i % W;
        EXPECT_EQ(first_in_streaks[std::size_t(i)], e) << "streaks, pixel row " << i / W << " column " << i % W;
        ++checked;
    }
    EXPECT_GT(checked, W * H * 9 / 10);
}

// Every kind of source (point light, laser, emissive rectangle), a mesh file (quads and triangles),
// supersampling by the R2 sequence (spp 3), bounce terms, patch profiles, frames, streaks and a sensor
// with a pulse and seeded noise: README, "--threads N: results are identical for any N", and from
// run to run (issue 17). Only render.json's timings and peak memory may differ.
void expect_identical_renders(const fs::path& one, const fs::path& two);

TEST_F(RenderOutputs, OneAndTwoThreadsWriteIdenticalFiles) {
    json scene = corner(48, 0.05);
    scene["objects"].push_back({{"type", "mesh"}, {"file", std::string(TPRF_SOURCE_DIR) + "/meshes/block.obj"},
                                {"albedo", 0.7}, {"transform", {{"scale", 0.2}, {"translate", {0.5, 0.5, 0}}}}});
    scene["objects"].push_back({{"type", "mesh"}, {"file", std::string(TPRF_SOURCE_DIR) + "/meshes/tetra.ply"},
                                {"albedo", 0.4}, {"transform", {{"scale", 0.1}, {"translate", {0.3, 0.2, 0.15}}}}});
    scene["camera"]["width"] = 16;
    scene["camera"]["height"] = 12;
    scene["camera"]["spp"] = 3;
    scene["lights"].push_back(
        {{"type", "laser"}, {"origin", {1.2, 0.8, 0.9}}, {"target", {0, 0.6, 0.4}}, {"power", 0.5}});
    scene["objects"].push_back({{"type", "rectangle"}, {"origin", {0.3, 0.4, 0.9}}, {"u", {0, 0.2, 0}},
                                {"v", {0.2, 0, 0}}, {"albedo", 0.2}, {"emission", {2, 1.5, 1}}});
    scene["solver"] = {{"bounces", true}};
    scene["sensor"] = {{"pulse", {{"shape", "gaussian"}, {"fwhm", 0.1}}},
                       {"exposure", {{"type", "gates"}, {"start", 0.5}, {"width", 0.2}, {"step", 0.2}, {"count", 8}}},
                       {"noise", {{"sigma", 0.001}, {"seed", 3}}}};
    scene["links"] = {{"method", "flat"}};
    const std::string flags = "--frames --streaks --patch-profiles";
    const fs::path one = render("one", scene, flags, 1);
    const fs::path two = render("two", scene, flags, 2);
    const fs::path again = render("again", scene, flags, 2);
    ASSERT_FALSE(one.empty());
    ASSERT_FALSE(two.empty());
    ASSERT_FALSE(again.empty());
    expect_identical_renders(one, two);
    expect_identical_renders(two, again);
    // The same with hierarchical links (cluster links, push and pull in the solver).
    scene["links"] = {{"method", "hierarchical"}, {"tolerance", 0.01}};
    const fs::path h1 = render("h1", scene, flags, 1), h2 = render("h2", scene, flags, 2);
    ASSERT_FALSE(h1.empty());
    ASSERT_FALSE(h2.empty());
    expect_identical_renders(h1, h2);
}

// tprf::render_scene (the Python module's render) keeps in memory exactly the arrays that `tprf render`
// writes: every .npy, bit for bit, on a scene with a point light, a laser, an emissive rectangle, a
// mesh, per-bounce cubes, patch profiles and a sensor block; tprf::measure applies the block again to
// the result as `tprf sensor` would.
TEST_F(RenderOutputs, InMemoryRenderHoldsTheFilesArraysBitForBit) {
    json scene = corner(48, 0.05);
    scene["objects"].push_back({{"type", "mesh"}, {"file", std::string(TPRF_SOURCE_DIR) + "/meshes/block.obj"},
                                {"albedo", 0.7}, {"transform", {{"scale", 0.2}, {"translate", {0.5, 0.5, 0}}}}});
    scene["camera"]["width"] = 16;
    scene["camera"]["height"] = 12;
    scene["lights"].push_back(
        {{"type", "laser"}, {"origin", {1.2, 0.8, 0.9}}, {"target", {0, 0.6, 0.4}}, {"power", 0.5}});
    scene["objects"].push_back({{"type", "rectangle"}, {"origin", {0.3, 0.4, 0.9}}, {"u", {0, 0.2, 0}},
                                {"v", {0.2, 0, 0}}, {"albedo", 0.2}, {"emission", {2, 1.5, 1}}});
    scene["solver"] = {{"bounces", true}, {"max_bounces", 3}};
    scene["sensor"] = {{"exposure", {{"type", "amcw"}, {"frequency_mhz", 30}, {"phases_deg", {0, 90, 180, 270}}}},
                       {"noise", {{"sigma", 0.001}, {"seed", 3}}}};
    const fs::path out = render("files", scene, "--patch-profiles");
    ASSERT_FALSE(out.empty());
    tprf::RenderOptions options;
    options.patch_profiles = true;
    options.threads = 2;
    const tprf::RenderResult r = tprf::render_scene(tprf::load_scene(write_json("memory", scene)), options);
    std::set<std::string> names;
    for (const auto& e : fs::directory_iterator(out))
        if (e.path().extension() == ".npy") names.insert(e.path().stem().string());
    EXPECT_EQ(names.size(), 11u);  // transient, steady, 4 bounce cubes, 2 patch arrays, measurements, depth, raw
    EXPECT_EQ(names.size(), r.arrays.size());
    for (const std::string& name : names) {
        const auto it = r.arrays.find(name);
        ASSERT_NE(it, r.arrays.end()) << name;
        const tprf::NpyArray file = tprf::read_npy(out / (name + ".npy"));
        EXPECT_EQ(it->second.shape, file.shape) << name;
        EXPECT_TRUE(it->second.data == file.data) << name << " differs from " << name << ".npy";
    }
    EXPECT_EQ(json::parse(r.record)["patches"], json::parse(std::ifstream(out / "render.json"))["patches"]);
    const auto measured = tprf::measure(tprf::load_scene(write_json("memory", scene)).sensor.value(), r, 1);
    ASSERT_EQ(measured.count("depth"), 1u);
    EXPECT_TRUE(measured.at("measurements").data == r.arrays.at("measurements").data);
    EXPECT_TRUE(measured.at("depth").data == r.arrays.at("depth").data);
}

void expect_identical_renders(const fs::path& one, const fs::path& two) {
    const auto listing = [](const fs::path& root) {
        std::set<std::string> names;
        for (const auto& e : fs::recursive_directory_iterator(root))
            if (e.is_regular_file()) names.insert(fs::relative(e.path(), root).string());
        return names;
    };
    const std::set<std::string> files = listing(one);
    ASSERT_EQ(files, listing(two));
    // 48 frames, 12 streaks, transient, steady (npy, exr, png), 5 bounce cubes, 3 patch files,
    // measurements, sensor.json, render.json at least.
    EXPECT_GE(files.size(), 48u + 12u + 16u);
    for (const char* f : {"transient_bounce_4.npy", "patch_transient.npy", "measurements.npy", "frames/frame_00047.exr",
                          "streaks/row_0011.exr"})
        EXPECT_EQ(files.count(f), 1u) << f;
    for (const std::string& f : files) {
        if (f == "render.json") {
            json a = json::parse(std::ifstream(one / f)), b = json::parse(std::ifstream(two / f));
            for (json* j : {&a, &b}) {
                j->erase("seconds");
                j->erase("peak_rss_mb");
                j->erase("scene");  // the same scene under two names
            }
            EXPECT_EQ(a, b);
            continue;
        }
        EXPECT_TRUE(read_bytes(one / f) == read_bytes(two / f)) << f << " differs between " << one << " and " << two;
    }
}

TEST_F(RenderOutputs, SupersampledPixelsConvergeToTheFootprintAverage) {
    // A plane z = 0 under a point light, seen from above: every sample's direct light is exact, so a
    // pixel with spp = g x g is the midpoint rule on its footprint, whose error falls as 1/g^2. Bins of
    // 5 cm; paths from 2.3 m to 4 m.
    const int W = 24, H = 24, T = 80;
    const double w = 0.05, rho = 0.6, intensity = 2.0;
    const Vec3 light(0.3, -0.2, 0.8);
    std::map<int, Image> steady;
    std::map<int, Cube> cubes;
    for (int spp : {1, 4, 16}) {
        json scene = lit_plane(T, w, W, H, spp);
        scene["camera"]["footprint"] = false;  // point samples: the first light is the earliest sample's
        const fs::path out = render("spp" + std::to_string(spp), scene);
        ASSERT_FALSE(out.empty());
        steady.emplace(spp, read_image(out / "steady.npy"));
        cubes.emplace(spp, read_cube(out / "transient.npy"));
    }
    const Pinhole cam(lit_plane(T, w, W, H)["camera"]);
    const auto seen = [&](double col, double row) -> Vec3 {  // a Vec3, not an Eigen expression of the local d
        const Vec3 d = cam.ray(col, row);
        return cam.position + to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ()) * d;
    };
    const auto radiance = [&](double col, double row) {
        return lambert_point(rho, intensity, light, seen(col, row), Vec3::UnitZ());
    };
    // The footprint average by a 32 x 32 midpoint rule: its own error is 1/1024 of the pixel centre's.
    std::vector<double> footprint(std::size_t(W * H));
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c) {
            double sum = 0.0;
            for (int i = 0; i < 32; ++i)
                for (int k = 0; k < 32; ++k) sum += radiance(c + (i + 0.5) / 32, r + (k + 0.5) / 32);
            footprint[std::size_t(r * W + c)] = sum / 1024;
        }
    std::map<int, double> worst;
    for (int g : {1, 2, 4}) {
        const int spp = g * g;
        for (int r = 0; r < H; ++r)
            for (int c = 0; c < W; ++c) {
                // docs/scene.md: a square spp samples the g x g grid of sub-pixel positions. The mean of
                // the exact radiance there, to float precision (1e-5 also covers Embree's float hit points).
                double grid = 0.0, shortest = std::numeric_limits<double>::infinity();
                for (int s = 0; s < spp; ++s) {
                    const double col = c + (s % g + 0.5) / g, row = r + (s / g + 0.5) / g;
                    grid += radiance(col, row) / spp;
                    const Vec3 x = seen(col, row);
                    shortest = std::min(shortest, (x - cam.position).norm() + (light - x).norm());
                }
                const double value = steady.at(spp).at(r, c);
                EXPECT_NEAR(value, grid, 1e-5 * grid) << "spp " << spp << " pixel " << r << "," << c;
                const double avg = footprint[std::size_t(r * W + c)];
                worst[g] = std::max(worst[g], std::abs(value / avg - 1));
                // The pixel's first light is its earliest sample's path.
                if (const auto b = bin_of(shortest, w)) {
                    EXPECT_EQ(cubes.at(spp).first_bin(r, c), *b) << "spp " << spp << " pixel " << r << "," << c;
                }
            }
    }
    // The centre alone misses the footprint average by 0.2% here (the test can fail); 4 and 16 samples
    // cut that by 4 and 16, within 20% for the higher-order terms (measured: 0.994 and 0.982 of it).
    EXPECT_GT(worst[1], 1e-3);
    EXPECT_LE(worst[2], 1.2 * worst[1] / 4);
    EXPECT_LE(worst[4], 1.2 * worst[1] / 16);
}

TEST_F(RenderOutputs, AFootprintSpreadsEachPixelOverThePathsOfItsSquare) {
    // The plane under a point light of SupersampledPixels, in bins of 1 cm. A pixel's true time profile
    // is its square's light binned by path: by a 64 x 64 midpoint rule, each point's exact radiance at
    // its exact path. With camera.footprint (the default), each sample spreads its light over the paths
    // of its cell to first order; without, each sample is one instant.
    const int W = 16, H = 16, T = 450, dense = 64;  // paths from 2.3 m to 4.1 m
    const double w = 0.01, rho = 0.6, intensity = 2.0;
    const Vec3 light(0.3, -0.2, 0.8);
    const Pinhole cam(lit_plane(T, w, W, H)["camera"]);
    std::vector<double> truth(std::size_t(W * H * T), 0.0), earliest(std::size_t(W * H), 1e30);
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c)
            for (int i = 0; i < dense; ++i)
                for (int k = 0; k < dense; ++k) {
                    const Vec3 d = cam.ray(c + (i + 0.5) / dense, r + (k + 0.5) / dense);
                    const Vec3 x = cam.position + to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ()) * d;
                    const double path = (x - cam.position).norm() + (light - x).norm();
                    const double value = lambert_point(rho, intensity, light, x, Vec3::UnitZ()) / (dense * dense);
                    ASSERT_LT(path, T * w);
                    truth[std::size_t((r * W + c) * T) + std::size_t(std::floor(path / w))] += value;
                }
    // The square's earliest path: on a lattice that holds its corners and edges, where it lies but for
    // pixels that hold the point nearest to both camera and light (there the path is flat to first order).
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c)
            for (int i = 0; i <= dense; ++i)
                for (int k = 0; k <= dense; ++k) {
                    const Vec3 d = cam.ray(c + double(i) / dense, r + double(k) / dense);
                    const Vec3 x = cam.position + to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ()) * d;
                    const double path = (x - cam.position).norm() + (light - x).norm();
                    earliest[std::size_t(r * W + c)] = std::min(earliest[std::size_t(r * W + c)], path);
                }
    // Median over pixels of the relative L1 of the time profile against the truth.
    const auto error = [&](const Cube& cube) {
        std::vector<double> e;
        for (int r = 0; r < H; ++r)
            for (int c = 0; c < W; ++c) {
                double diff = 0.0, sum = 0.0;
                for (int t = 0; t < T; ++t) {
                    const double want = truth[std::size_t((r * W + c) * T + t)];
                    diff += std::abs(cube.at(r, c, t) - want);
                    sum += want;
                }
                e.push_back(diff / sum);
            }
        std::nth_element(e.begin(), e.begin() + long(e.size() / 2), e.end());
        return e[e.size() / 2];
    };
    std::map<std::pair<int, bool>, double> median;
    std::map<std::pair<int, bool>, Image> steady;
    int checked = 0;
    const auto m = [&](int spp, bool footprint) { return median.at(std::pair(spp, footprint)); };
    for (const int spp : {1, 4, 16})
        for (const bool footprint : {true, false}) {
            json scene = lit_plane(T, w, W, H, spp);
            scene["camera"]["footprint"] = footprint;
            const fs::path out = render("fp" + std::to_string(spp) + (footprint ? "on" : "off"), scene);
            ASSERT_FALSE(out.empty());
            const Cube cube = read_cube(out / "transient.npy");
            median[std::pair(spp, footprint)] = error(cube);
            steady.emplace(std::pair(spp, footprint), read_image(out / "steady.npy"));
            if (!footprint) continue;
            // The first light is the square's earliest path, to the bin. The spread is linear in the
            // cell and never before the earliest path at the cell's corners, which are traced to first
            // order: the first light may move by a second-order sliver either way (measured: under
            // 0.5 mm at spp 1). Pixels whose earliest path lies within 1 mm of a bin edge are skipped.
            for (int r = 0; r < H; ++r)
                for (int c = 0; c < W; ++c) {
                    const double e = earliest[std::size_t(r * W + c)];
                    const double x = e / w, k = std::floor(x);
                    if ((x - k) * w < 1e-3 || (k + 1 - x) * w < 1e-3) continue;
                    EXPECT_EQ(cube.first_bin(r, c), int(k)) << "spp " << spp << " pixel " << r << "," << c;
                    ++checked;
                }
        }
    EXPECT_GT(checked, 3 * W * H * 3 / 4);
    MEASURED("footprint: median pixel profile error, spp 1/4/16: %.4f %.4f %.4f (point samples %.4f %.4f %.4f)\n",
             m(1, true), m(4, true), m(16, true), m(1, false), m(4, false), m(16, false));
    for (const int spp : {1, 4, 16}) {
        EXPECT_LT(m(spp, true), 0.25 * m(spp, false)) << "spp " << spp;
        // The footprint moves light in time only: the steady image is the samples' own.
        const Image& a = steady.at(std::pair(spp, true));
        const Image& b = steady.at(std::pair(spp, false));
        for (int r = 0; r < H; ++r)
            for (int c = 0; c < W; ++c) EXPECT_NEAR(a.at(r, c), b.at(r, c), 1e-6 * b.at(r, c)) << r << "," << c;
    }
    EXPECT_LT(m(4, true), m(1, true));
}

TEST_F(RenderOutputs, LaserSpotReturnsAtItsPathAndLightsTheWallAsALambertianPoint) {
    // A floor (z = 0) and a back wall (y = 1, facing -y). The laser hits the floor at the point that the
    // centre pixel of the 31 x 31 image looks at. docs/scene.md: the spot reflects as a Lambertian point of
    // intensity albedo P cos / pi, so the wall's direct light is exact: with max_bounces 2 (laser ->
    // spot -> wall), the wall's pixels show only that. Bins of 2 cm.
    const int N = 31, T = 350;
    const double w = 0.02, power = 2.0, rho_floor = 0.5, rho_wall = 0.7;
    const Vec3 spot(0.1, 0.2, 0.0), origin(0.8, -0.6, 1.0), wall0(-1, 1, 0), wu(2, 0, 0), wv(0, 0, 1.5);
    const json scene = {
        {"time", {{"bins", T}, {"bin_width", w}}},
        {"camera", {{"position", {0, -1.8, 1.2}}, {"look_at", vec(spot)}, {"up", {0, 0, 1}}, {"fov", 50},
                    {"width", N}, {"height", N}, {"footprint", false}}},  // point samples: exact first bins
        {"lights", {{{"type", "laser"}, {"origin", vec(origin)}, {"target", vec(spot)}, {"power", power}}}},
        {"objects",
         {{{"type", "rectangle"}, {"origin", {-1, -1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 2, 0}}, {"albedo", rho_floor}},
          {{"type", "rectangle"}, {"origin", vec(wall0)}, {"u", vec(wu)}, {"v", vec(wv)}, {"albedo", rho_wall}}}},
        {"patches", {{"max_edge", 0.1}}},
        {"solver", {{"max_bounces", 2}}}};
    const fs::path out = render("laser", scene);
    ASSERT_FALSE(out.empty());
    const Cube cube = read_cube(out / "transient.npy");
    const Image steady = read_image(out / "steady.npy");
    const Pinhole cam(scene["camera"]);
    const double to_spot = (origin - spot).norm();

    // The spot's pixel: its first light is laser -> spot -> camera, to the bin (1.46 + 2.33 m = 189.7 bins).
    const auto spot_bin = bin_of(to_spot + (cam.position - spot).norm(), w);
    ASSERT_TRUE(spot_bin);
    EXPECT_EQ(cube.first_bin(N / 2, N / 2), *spot_bin);

    // The wall's pixels: arrival laser -> spot -> x -> camera, radiance rho_wall / pi * (rho_floor P
    // cos_spot / pi) cos_x / r^2. The spot sends its light from 1e-5 of the scene's diagonal (3e-5 m)
    // above the floor (where shadow rays start), which changes cos_spot by 3e-5 / z relative: below
    // 1e-4 at the wall points above z = 0.3 that are compared; 2e-4 covers it and float rounding.
    int checked = 0;
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c) {
            const Vec3 d = cam.ray(c + 0.5, r + 0.5);
            const double leg = to_plane(cam.position, d, wall0, -Vec3::UnitY());
            const Vec3 x = cam.position + leg * d;
            if (!inside(x, wall0, wu, wv)) continue;
            const Vec3 to_x = x - spot;
            const double dist = to_x.norm();
            if (const auto b = bin_of(to_spot + dist + leg, w)) {
                EXPECT_EQ(cube.first_bin(r, c), *b) << "wall pixel " << r << "," << c;
            }
            if (x.z() < 0.3) continue;
            const double spot_intensity = rho_floor * power * (to_x.z() / dist) / M_PI;  // W/sr towards x
            const double cos_x = (-Vec3::UnitY()).dot(-to_x / dist);
            const double expected = rho_wall / M_PI * spot_intensity * cos_x / (dist * dist);
            EXPECT_NEAR(steady.at(r, c), expected, 2e-4 * expected) << "wall pixel " << r << "," << c;
            ++checked;
        }
    EXPECT_GT(checked, 150);

    // Nothing anywhere arrives before laser -> spot -> visible point -> camera.
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c) {
            const Vec3 d = cam.ray(c + 0.5, r + 0.5);
            const double on_floor = to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ());
            const double on_wall = to_plane(cam.position, d, wall0, -Vec3::UnitY());
            const double leg = std::min(on_floor, on_wall);
            const Vec3 x = cam.position + leg * d;
            const bool floor_seen = inside(x, Vec3(-1, -1, 0), 2 * Vec3::UnitX(), 2 * Vec3::UnitY());
            if (!std::isfinite(leg) || !(floor_seen || inside(x, wall0, wu, wv))) continue;
            const int first = cube.first_bin(r, c);
            if (first >= 0) {
                EXPECT_GE(first, int(std::floor((to_spot + (x - spot).norm() + leg - kEdge) / w))) << r << "," << c;
            }
        }
}

TEST_F(RenderOutputs, AreaLitFloorMatchesTheFormFactorToTheEmitter) {
    // A 1 x 1 m emitter (L_e = 3, albedo 0: it reflects nothing back) facing down 0.6 m above a 3 x 3 m
    // floor of albedo 0.6. The floor does not see itself, so its radiance is its direct light only:
    // albedo / pi * (pi L_e F(x -> emitter)) = albedo L_e F, with F Howell's B-3 over the four corners.
    const double h = 0.6, rho = 0.6, Le = 3.0, max_edge = 0.1, w = 0.02;
    const int N = 32, T = 250;
    const json scene = {
        {"time", {{"bins", T}, {"bin_width", w}}},
        {"camera", {{"position", {0, -2.5, 1.0}}, {"look_at", {0, 0, 0}}, {"up", {0, 0, 1}}, {"fov", 50},
                    {"width", N}, {"height", N}, {"footprint", false}}},  // point samples: exact first bins
        {"objects",
         {{{"type", "rectangle"}, {"origin", {-1.5, -1.5, 0}}, {"u", {3, 0, 0}}, {"v", {0, 3, 0}}, {"albedo", rho}},
          {{"type", "rectangle"}, {"origin", {-0.5, -0.5, h}}, {"u", {0, 1, 0}}, {"v", {1, 0, 0}},
           {"albedo", 0.0}, {"emission", Le}}}},
        {"patches", {{"max_edge", max_edge}}}};
    const fs::path out = render("area", scene);
    ASSERT_FALSE(out.empty());
    const Cube cube = read_cube(out / "transient.npy");
    const Image steady = read_image(out / "steady.npy");
    const Pinhole cam(scene["camera"]);
    const auto F = [&](double x, double y) { return tprf::test::ff_point_to_parallel_rectangle(x, y, -0.5, 0.5, -0.5, 0.5, h); };
    // The gather evaluates the emitter at each pixel's point (imaging/gather.h): Lambert's contour
    // integral, exact, and shadow rays that find nothing in the way. So each floor pixel is albedo L_e F
    // to float precision (measured: 8e-7); 1e-5 allowed. (Until the camera did this, it interpolated
    // patch profiles, and the allowance was F's variation within a patch's circumradius plus 0.5%.)
    // Pixels within 3 circumradii R of the floor's edges are left out, as then.
    const double R = max_edge / std::sqrt(2.0);
    int checked = 0, hidden = 0;
    double worst = 0.0;
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c) {
            const Vec3 d = cam.ray(c + 0.5, r + 0.5);
            const double leg = to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ());
            const Vec3 x = cam.position + leg * d;
            // The emitter's back hides the floor behind it and shows nothing (one-sided, emits from its front).
            const double te = to_plane(cam.position, d, Vec3(0, 0, h), Vec3::UnitZ());
            const Vec3 on_emitter_plane = cam.position + te * d;
            if (te < leg && std::abs(on_emitter_plane.x()) < 0.5 && std::abs(on_emitter_plane.y()) < 0.5) {
                for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(steady.at(r, c, ch), 0.0f);
                ++hidden;
                continue;
            }
            if (!std::isfinite(leg) || std::max(std::abs(x.x()), std::abs(x.y())) > 1.5 - 3 * R) continue;
            const double f = F(x.x(), x.y());
            EXPECT_NEAR(steady.at(r, c), rho * Le * f, 1e-5 * rho * Le * f)
                << "floor pixel " << r << "," << c << " at " << x.transpose();
            worst = std::max(worst, std::abs(steady.at(r, c) / (rho * Le * f) - 1));
            // The first light: nothing before the straight line from the emitter (exact), and no later than
            // sqrt(2) / 64 m after it. Every floor point here sees the emitter's paths spread over more
            // than 16 bins, so the gather times them by 32 x 32 cells of 1/32 m, whose centres lie within
            // sqrt(2) / 64 m of every point of the emitter.
            const Vec3 nearest(std::clamp(x.x(), -0.5, 0.5), std::clamp(x.y(), -0.5, 0.5), h);
            const double path = (x - nearest).norm() + leg;
            const int first = cube.first_bin(r, c);
            EXPECT_GE(first, int(std::floor((path - kEdge) / w))) << r << "," << c;
            EXPECT_LE(first, int(std::floor((path + std::sqrt(2.0) / 64 + kEdge) / w))) << r << "," << c;
            ++checked;
        }
    EXPECT_GT(checked, 300);
    EXPECT_GT(hidden, 20);
    MEASURED("area-lit floor: worst pixel %.2e of albedo L_e F\n", worst);
}

TEST_F(RenderOutputs, APixelInAPenumbraTakesTheVisiblePartOfTheEmitterThroughItsSamplesSharedRays) {
    // A 0.5 m square emitter (L_e = 2) facing down at z = 1 over a floor of albedo 0.7, and an opaque
    // plate (albedo 0) at z = 0.5 over x < 0. The segment from a floor point (px, py, 0) to an emitter
    // point (ex, ey, 1) crosses z = 0.5 at x = (px + ex) / 2, so the plate hides exactly the emitter's
    // part with ex < -px: what the point sees is a rectangle, and Howell's B-3 gives its form factor in
    // closed form. Nothing else lights the floor (plate and emitter reflect nothing, the floor does not
    // see itself). The camera, below the plate, sees the floor across the penumbra (-0.25 < px < 0.25)
    // and into the umbra. Each floor pixel's samples lie on one plane, so the gather shares the
    // shadow rays of the pixel's samples (gather.cpp, penumbra_open); its radiance must be the pixel
    // mean of albedo L_e F_visible, measured here over 8 x 8 points of the pixel. Flat links: cluster
    // links would share the light the floor sends up among clusters that mix floor and plate patches,
    // and bring back about 1e-7 of it (within their tolerance), which is not what this test is about.
    const double rho = 0.7, Le = 2.0;
    const int N = 40;
    const json scene = {
        {"time", {{"bins", 300}, {"bin_width", 0.01}}},
        {"camera", {{"position", {1.1, 0.05, 0.45}}, {"look_at", {0, 0, 0}}, {"up", {0, 0, 1}}, {"fov", 45},
                    {"width", N}, {"height", N}, {"spp", 16}}},
        {"objects",
         {{{"type", "rectangle"}, {"origin", {-1.5, -1.5, 0}}, {"u", {3, 0, 0}}, {"v", {0, 3, 0}}, {"albedo", rho}},
          {{"type", "rectangle"}, {"origin", {-0.25, -0.25, 1}}, {"u", {0, 0.5, 0}}, {"v", {0.5, 0, 0}},
           {"albedo", 0.0}, {"emission", Le}},
          {{"type", "rectangle"}, {"origin", {-2, -2, 0.5}}, {"u", {2, 0, 0}}, {"v", {0, 4, 0}}, {"albedo", 0.0},
           {"two_sided", true}}}},
        {"patches", {{"max_edge", 0.1}}},
        {"links", {{"method", "flat"}}}};
    const fs::path out = render("penumbra", scene);
    ASSERT_FALSE(out.empty());
    const Image steady = read_image(out / "steady.npy");
    const Pinhole cam(scene["camera"]);
    const auto F = [](double px, double py, bool shadowed) {
        const double from = shadowed ? std::max(-0.25, -px) : -0.25;
        return from < 0.25 ? tprf::test::ff_point_to_parallel_rectangle(px, py, from, 0.25, -0.25, 0.25, 1.0) : 0.0;
    };
    int penumbra = 0, umbra = 0;
    double worst = 0.0, worst_unshadowed = 0.0, got_sum = 0.0, visible_sum = 0.0;
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c) {
            double visible = 0.0, full = 0.0;
            bool floor = true;
            for (int k = 0; k < 64 && floor; ++k) {
                const Vec3 d = cam.ray(c + (k % 8 + 0.5) / 8, r + (k / 8 + 0.5) / 8);
                const Vec3 x = cam.position + to_plane(cam.position, d, Vec3::Zero(), Vec3::UnitZ()) * d;
                // Only pixels wholly on the floor, away from its edges.
                floor = d.z() < 0.0 && std::abs(x.x()) < 1.2 && std::abs(x.y()) < 1.2;
                visible += F(x.x(), x.y(), true) / 64;
                full += F(x.x(), x.y(), false) / 64;
            }
            if (!floor) continue;
            const double got = steady.at(r, c) / (rho * Le);
            if (visible == 0.0) {
                // No direct light; what is left is the rounding of the patches' profiles less their
                // exact pulses (measured 5e-20).
                EXPECT_LT(steady.at(r, c), 1e-9 * rho * Le) << "umbra pixel " << r << "," << c;
                ++umbra;
                continue;
            }
            if (visible > 0.999 * full) continue;  // wholly lit: AreaLitFloorMatchesTheFormFactorToTheEmitter
            ++penumbra;
            got_sum += got;
            visible_sum += visible;
            // Errors relative to the unshadowed light, so that a sliver of penumbra is not a large ratio.
            // The shared rays cover the source with a grid of at least 16 x 16 cells, one ray each, and
            // a straight shadow edge crosses one column of it: up to half a column's light, 1/32.
            worst = std::max(worst, std::abs(got - visible) / full);
            worst_unshadowed = std::max(worst_unshadowed, std::abs(got - full) / full);
            EXPECT_NEAR(got, visible, full / 32) << "penumbra pixel " << r << "," << c;
        }
    MEASURED("penumbra pixels: %d (%d umbra), worst error / unshadowed light %.2e (as if unshadowed: %.2e); "
             "all penumbra pixels' light / exact - 1: %.2e\n",
             penumbra, umbra, worst, worst_unshadowed, got_sum / visible_sum - 1);
    EXPECT_NEAR(got_sum / visible_sum, 1.0, 0.005);  // the cells' errors do not add up
    EXPECT_GT(penumbra, 200);
    EXPECT_GT(umbra, 50);
    EXPECT_GT(worst_unshadowed, 0.5);  // the shadow matters: the test can fail
}

TEST_F(RenderOutputs, CornellBoxConservesEnergyAndLightsTheBackWallFirstWhereGeometrySays) {
    // meshes/cornell-box.json with a longer window: 2048 bins of 1 cm (20.48 m instead of 5.12 m, so
    // that the window holds all the light), at 64 x 64 pixels (the cube is 100 MB) and block.obj by its
    // absolute path. Objects, emitter, patches and the camera's view are the default scene's.
    json scene = json::parse(std::ifstream(fs::path(TPRF_SOURCE_DIR) / "meshes" / "cornell-box.json"));
    const int T = 2048, N = 64;
    const double w = 0.01;
    scene["time"]["bins"] = T;
    scene["time"]["bin_width"] = w;
    scene["camera"]["width"] = N;
    scene["camera"]["height"] = N;
    scene["camera"]["footprint"] = false;  // point samples: the first light is where the samples' geometry says
    for (json& o : scene["objects"])
        if (o.contains("file"))
            o["file"] = (fs::path(TPRF_SOURCE_DIR) / "meshes" / o["file"].get<std::string>()).string();
    const fs::path out = render("cornell", scene);
    ASSERT_FALSE(out.empty());
    const Cube cube = read_cube(out / "transient.npy");
    const Image steady = read_image(out / "steady.npy");
    ASSERT_EQ(cube.a.shape, (std::vector<std::size_t>{std::size_t(N), std::size_t(N), std::size_t(T), 3}));
    const int spp = scene["camera"]["spp"];
    ASSERT_EQ(spp, 4);

    // 1. The window holds all the light: the energy per 128 bins decays geometrically (the open box
    // loses light at every bounce), so what lies beyond the window is at most the last 128 bins' energy
    // times q / (1 - q), q the last decay ratio; it must be below 1e-6 of the total.
    std::vector<double> band(std::size_t(T / 128), 0.0);
    double total = 0.0;
    for (std::size_t i = 0; i < cube.a.data.size(); ++i) {
        band[i / 3 % std::size_t(T) / 128] += cube.a.data[i];
        total += cube.a.data[i];
    }
    const double q = band.back() / band[band.size() - 2];
    ASSERT_LT(q, 1.0);
    EXPECT_LT(band.back() * q / (1 - q), 1e-6 * total) << "light is still arriving at the end of the window";
    // ... so every pixel's bins sum to its steady radiance (docs/scene.md, by linearity): within float
    // accumulation over 2048 bins (1e-5 of the pixel; measured 3e-7) and 1e-7 of the brightest pixel.
    float peak = 0.0f;
    for (float s : steady.a.data) peak = std::max(peak, s);
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c)
            for (int ch = 0; ch < 3; ++ch) {
                const double s = steady.at(r, c, ch);
                EXPECT_NEAR(cube.sum(r, c, ch), s, 1e-5 * s + 1e-7 * peak)
                    << "pixel " << r << "," << c << " channel " << ch;
            }

    // Which object each sample sees, from the scene's own patches and ray tracer.
    const tprf::Scene parsed = tprf::load_scene(m_dir / "cornell.json");
    const tprf::PatchSet patches = tprf::build_patches(parsed);
    const tprf::Visibility vis(patches);
    const Pinhole cam(scene["camera"]);
    const int back_wall = 2, emitter = 5;
    const Vec3 Le(17, 12, 4);
    // The emitter: 0.2 x 0.2 m at z = 0.999, x and y in [0.4, 0.6], facing down.
    const auto emitter_distance = [](const Vec3& x) {
        return (x - Vec3(std::clamp(x.x(), 0.4, 0.6), std::clamp(x.y(), 0.4, 0.6), 0.999)).norm();
    };
    int emitter_pixels = 0, wall_pixels = 0;
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c) {
            std::set<int> objects;
            double shortest_leg = std::numeric_limits<double>::infinity(), longest_leg = 0.0;
            double shortest_path = std::numeric_limits<double>::infinity();
            bool high = true;
            for (int s = 0; s < spp; ++s) {
                const Vec3 d = cam.ray(c + (s % 2 + 0.5) / 2, r + (s / 2 + 0.5) / 2);
                const tprf::RayHit hit = vis.intersect(cam.position, d, std::numeric_limits<double>::infinity());
                objects.insert(hit.hit && hit.front ? int(patches.object[hit.patch]) : -1);
                shortest_leg = std::min(shortest_leg, hit.distance);
                longest_leg = std::max(longest_leg, hit.distance);
                shortest_path = std::min(shortest_path, hit.distance + emitter_distance(hit.point));
                high = high && hit.point.z() > 0.65 && hit.point.x() > 0.05 && hit.point.x() < 0.95;
            }
            if (objects.size() != 1) continue;
            if (*objects.begin() == emitter) {
                // 2. The emitter's own pulse: every sample sees radiance L_e from t = 0, arriving after its
                // leg, split by the linear delay between that bin and the next. Its reflected light comes
                // back only after a round trip to a surface at least 0.399 m below it (the tall block's
                // top; the walls are 0.4 m away), 0.798 m: the bins up to 79 after the first hold L_e
                // exactly, to float rounding.
                const int first = cube.first_bin(r, c);
                if (const auto b = bin_of(shortest_leg, w)) {
                    EXPECT_EQ(first, *b) << "emitter pixel " << r << "," << c;
                }
                ASSERT_LE(std::floor(longest_leg / w) + 1, first + 79);
                for (int ch = 0; ch < 3; ++ch)
                    EXPECT_NEAR(cube.sum(r, c, ch, first, first + 79), Le[ch], 1e-5 * Le[ch])
                        << "emitter pixel " << r << "," << c << " channel " << ch;
                ++emitter_pixels;
            } else if (*objects.begin() == back_wall && high) {
                // 3. The back wall above the blocks (z > 0.65; the blocks reach 0.6) sees the emitter
                // directly: its first light is the straight line from the emitter plus the leg, never
                // earlier, and at most sqrt(2) max_edge / 4 = 1.77 cm later (the emitter's sample points
                // lie max_edge / 4 inside its patches). Measured: 420 pixels exact, 12 one bin late.
                const int first = cube.first_bin(r, c);
                EXPECT_GE(first, int(std::floor((shortest_path - kEdge) / w))) << "back wall pixel " << r << "," << c;
                EXPECT_LE(first, int(std::floor((shortest_path + std::sqrt(2.0) * 0.05 / 4 + kEdge) / w)))
                    << "back wall pixel " << r << "," << c;
                ++wall_pixels;
            }
        }
    EXPECT_GT(emitter_pixels, 12);  // 20 of the 64 x 64 pixels see only the emitter
    EXPECT_GT(wall_pixels, 300);
}

TEST_F(RenderOutputs, TwoSidedRectangleIsLitFromBehindAndOneSidedIsBlack) {
    // A rectangle z = 0 whose front faces +z, with the light and the camera below it (behind it).
    const int N = 16, T = 80;
    const double w = 0.05, rho = 0.5, intensity = 1.5;
    const Vec3 light(0.2, 0.1, -0.7);
    const auto scene = [&](bool two_sided, double camera_z) {
        return json{{"time", {{"bins", T}, {"bin_width", w}}},
                    {"camera", {{"position", {0, 0, camera_z}}, {"look_at", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov", 60},
                                {"width", N}, {"height", N}, {"footprint", false}}},  // point samples
                    {"lights", {{{"type", "point"}, {"position", vec(light)}, {"intensity", intensity}}}},
                    {"objects", {{{"type", "rectangle"}, {"origin", {-1, -1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 2, 0}},
                                  {"albedo", rho}, {"two_sided", two_sided}}}},
                    {"patches", {{"max_edge", 0.25}}}};
    };
    const fs::path two = render("two_sided", scene(true, -1.5));
    const fs::path one = render("one_sided", scene(false, -1.5));
    const fs::path front = render("two_sided_front", scene(true, 1.5));
    ASSERT_FALSE(two.empty() || one.empty() || front.empty());

    // Two-sided, seen from behind: lit as a Lambertian plane whose normal is -z (exact direct light at
    // each pixel centre, 1e-5 for float), arriving at light -> x -> camera.
    const Image steady = read_image(two / "steady.npy");
    const Cube cube = read_cube(two / "transient.npy");
    const Pinhole cam(scene(true, -1.5)["camera"]);
    for (int r = 0; r < N; ++r)
        for (int c = 0; c < N; ++c) {
            const Vec3 d = cam.ray(c + 0.5, r + 0.5);
            const double leg = to_plane(cam.position, d, Vec3::Zero(), -Vec3::UnitZ());
            const Vec3 x = cam.position + leg * d;
            ASSERT_LT(std::max(std::abs(x.x()), std::abs(x.y())), 1.0);
            const double expected = lambert_point(rho, intensity, light, x, -Vec3::UnitZ());
            EXPECT_NEAR(steady.at(r, c), expected, 1e-5 * expected) << r << "," << c;
            if (const auto b = bin_of(leg + (light - x).norm(), w)) {
                EXPECT_EQ(cube.first_bin(r, c), *b) << r << "," << c;
            }
        }
    // One-sided, seen from behind: its back is black, exactly, at every bin.
    for (const char* f : {"transient.npy", "steady.npy"}) {
        const tprf::NpyArray a = tprf::read_npy(one / f);
        EXPECT_EQ(std::count(a.data.begin(), a.data.end(), 0.0f), std::ptrdiff_t(a.data.size())) << "one-sided " << f;
    }
    // Two-sided, seen from the front: the light behind it does not reach the front side.
    for (const char* f : {"transient.npy", "steady.npy"}) {
        const tprf::NpyArray a = tprf::read_npy(front / f);
        EXPECT_EQ(std::count(a.data.begin(), a.data.end(), 0.0f), std::ptrdiff_t(a.data.size())) << "front side " << f;
    }
}

TEST_F(RenderOutputs, BounceCubesSumToTheCubeAndStartWhereGeometrySays) {
    // The corner under a point light with solver.bounces: orders 0..3 and the tail (>= 4) in
    // transient_bounce_0..4.npy (docs/scene.md). 200 bins of 2 cm.
    const int T = 200;
    const double w = 0.02;
    json scene = corner(T, w);
    scene["solver"] = {{"bounces", true}};
    scene["camera"]["footprint"] = false;  // point samples: the first light is the pixel centre's path
    const fs::path out = render("corner", scene);
    ASSERT_FALSE(out.empty());
    const Cube total = read_cube(out / "transient.npy");
    std::vector<Cube> order;
    for (int k = 0; k < 5; ++k) {
        order.push_back(read_cube(out / ("transient_bounce_" + std::to_string(k) + ".npy")));
        ASSERT_EQ(order.back().a.shape, total.a.shape) << k;
    }
    EXPECT_FALSE(fs::exists(out / "transient_bounce_5.npy"));
    // Without emissive surfaces there is no order 0: exactly zero.
    EXPECT_EQ(std::count(order[0].a.data.begin(), order[0].a.data.end(), 0.0f), std::ptrdiff_t(order[0].a.data.size()));
    // The orders add up to the cube: each is filmed from the same terms in float, so the sum of five
    // rounded parts and the rounded whole differ by a few float ulps of the peak (1e-6 is 8 ulps;
    // measured 1.8e-8).
    float peak = 0.0f;
    for (float v : total.a.data) peak = std::max(peak, v);
    double worst = 0.0;
    for (std::size_t i = 0; i < total.a.data.size(); ++i) {
        double sum = 0.0;
        for (const Cube& k : order) sum += k.a.data[i];
        worst = std::max(worst, std::abs(sum - total.a.data[i]));
    }
    EXPECT_LE(worst, 1e-6 * peak);

    // Order 1 is the direct light: it starts at light -> x -> camera, and its bins sum to the exact
    // direct radiance albedo / pi * I cos / r^2 (1e-5 for float). Order 2 (light -> other plane -> x)
    // cannot start before the light mirrored in the other plane, |L' - x| + leg, except by what the
    // patches blur: a link carries the spread of paths between two patches of diameter D, and the
    // camera reads profiles of patches up to 2.6 circumradii = 1.3 D away (gather.cpp, kSupportRadii),
    // so 2.3 D early at most (measured: 0.2 m of the 0.33 m).
    const Pinhole cam(scene["camera"]);
    const Vec3 light(0.6, 0.3, 0.7);
    const double D = 0.1 * std::sqrt(2.0);
    int checked = 0;
    for (int r = 0; r < 20; ++r)
        for (int c = 0; c < 24; ++c) {
            const std::optional<CornerHit> h = corner_hit(cam, r, c);
            if (!h) {
                EXPECT_EQ(order[1].first_bin(r, c), -1);
                continue;
            }
            const Vec3 normal = h->plane == 0 ? Vec3::UnitZ() : Vec3::UnitX();
            const double rho = h->plane == 0 ? 0.6 : 0.5;
            const double direct = lambert_point(rho, 1.0, light, h->x, normal);
            EXPECT_NEAR(order[1].sum(r, c, 0), direct, 1e-5 * direct) << r << "," << c;
            if (const auto b = bin_of((light - h->x).norm() + h->leg, w)) {
                EXPECT_EQ(order[1].first_bin(r, c), *b) << r << "," << c;
            }
            Vec3 mirrored = light;
            mirrored[h->plane == 0 ? 0 : 2] *= -1;  // a floor point's light comes off the wall x = 0 and vice versa
            const int first2 = order[2].first_bin(r, c);
            EXPECT_GE(first2, 0) << r << "," << c;
            EXPECT_GE(first2, int(std::floor(((mirrored - h->x).norm() + h->leg - 2.3 * D) / w))) << r << "," << c;
            ++checked;
        }
    EXPECT_GT(checked, 200);
}

TEST_F(RenderOutputs, PicosecondsGiveTheSameCubeAsMetres) {
    // The corner on a window of 150 bins of 2 cm from 0.5 m, and the same window in picoseconds of
    // light travel: bin_width_ps = bin_width_m / c * 1e12. The conversion through c changes the bin
    // width by at most an ulp (1e-16), which can move a linear delay's split by 1e-14: a few float ulps
    // of the cube at most, so 1e-6 of its peak (measured: bit-identical).
    const double c = 299792458.0;
    json metres = corner(150, 0.02), picoseconds = corner(150, 0.02);
    metres["time"]["start"] = 0.5;
    picoseconds["time"] = {{"bins", 150}, {"bin_width", 0.02 / c * 1e12}, {"start", 0.5 / c * 1e12}, {"unit", "ps"}};
    const fs::path m = render("metres", metres), p = render("ps", picoseconds);
    ASSERT_FALSE(m.empty() || p.empty());
    const Cube a = read_cube(m / "transient.npy"), b = read_cube(p / "transient.npy");
    ASSERT_EQ(a.a.shape, b.a.shape);
    float peak = 0.0f;
    double worst = 0.0;
    for (std::size_t i = 0; i < a.a.data.size(); ++i) {
        peak = std::max(peak, a.a.data[i]);
        worst = std::max(worst, double(std::abs(a.a.data[i] - b.a.data[i])));
    }
    EXPECT_GT(peak, 0.0f);
    EXPECT_LE(worst, 1e-6 * peak);
    EXPECT_EQ(tprf::read_npy(m / "steady.npy").data, tprf::read_npy(p / "steady.npy").data);
    const json j = json::parse(std::ifstream(p / "render.json"));
    EXPECT_EQ(j["time"]["unit"], "ps");
    EXPECT_DOUBLE_EQ(j["time"]["bin_width"].get<double>(), 0.02 / c * 1e12);
}

TEST_F(RenderOutputs, SensorWindowsAfterTheFirstArrivalSumTheBinsInside) {
    // A plane under a point light (direct light only), bins of 1/16 m so that every window edge below is
    // exact in binary: a delta pulse's window then measures exactly the bins inside it (docs/sensor.md),
    // to float rounding of the sum (1e-6), and windows before the first or after the last light measure
    // exactly 0.
    const int W = 16, H = 16, T = 80;
    const double w = 0.0625;
    const fs::path out = render("plane", lit_plane(T, w, W, H));
    ASSERT_FALSE(out.empty());
    const Cube cube = read_cube(out / "transient.npy");
    int t0 = T, t1 = -1;
    for (int r = 0; r < H; ++r)
        for (int c = 0; c < W; ++c)
            for (int t = 0; t < T; ++t)
                if (cube.at(r, c, t) != 0.0f) {
                    t0 = std::min(t0, t);
                    t1 = std::max(t1, t);
                }
    // The light lasts 2.3 to 3.4 m of path here: bins 37 to 54, well inside the 5 m window.
    ASSERT_GT(t0, 8);
    ASSERT_LT(t1 + 6, T);
    ASSERT_GT(t1 - t0, 8);
    // [from, to) in bins for each window.
    const std::vector<std::pair<int, int>> windows = {
        {t0 + 1, t0 + 4}, {t0 + 4, t0 + 6}, {t0 + 6, t1 + 1}, {t1 + 1, t1 + 5}, {0, t0}};
    json list = json::array();
    for (const auto& [from, to] : windows) list.push_back({from * w, (to - from) * w});
    const fs::path windows_file = write_json("windows", {{"exposure", {{"type", "windows"}, {"windows", list}}}});
    const int gates = (t1 + 4 - (t0 + 1)) / 2;  // gate k: bins [t0 + 1 + 2k, t0 + 3 + 2k)
    const json gate_block = {
        {"type", "gates"}, {"start", (t0 + 1) * w}, {"width", 2 * w}, {"step", 2 * w}, {"count", gates}};
    const fs::path gates_file = write_json("gates", {{"exposure", gate_block}});

    for (const auto& [file, ranges] :
         {std::pair{windows_file, windows}, std::pair{gates_file, std::vector<std::pair<int, int>>{}}}) {
        std::vector<std::pair<int, int>> bins = ranges;
        if (bins.empty())
            for (int k = 0; k < gates; ++k) bins.emplace_back(t0 + 1 + 2 * k, t0 + 3 + 2 * k);
        const Outcome r = run_tprf("sensor " + out.string() + " " + file.string());
        ASSERT_EQ(r.status, 0) << r.err;
        const tprf::NpyArray m = tprf::read_npy(out / ("sensor-" + file.stem().string()) / "measurements.npy");
        const std::size_t K = bins.size();
        ASSERT_EQ(m.shape, (std::vector<std::size_t>{std::size_t(H), std::size_t(W), K, 3})) << file;
        int lit = 0;
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
                for (std::size_t k = 0; k < K; ++k)
                    for (int ch = 0; ch < 3; ++ch) {
                        const double inside_bins = cube.sum(y, x, ch, bins[k].first, bins[k].second);
                        const float measured = m.data[((std::size_t(y * W + x)) * K + k) * 3 + std::size_t(ch)];
                        if (inside_bins == 0.0)
                            EXPECT_EQ(measured, 0.0f) << file << " pixel " << y << "," << x << " window " << k;
                        else
                            EXPECT_NEAR(measured, inside_bins, 1e-6 * inside_bins)
                                << file << " pixel " << y << "," << x << " window " << k;
                        lit += inside_bins > 0.0;
                    }
        EXPECT_GT(lit, H * W) << file;
    }
}

}  // namespace
