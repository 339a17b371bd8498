#include "tprf/pipeline/render.h"

#include "tprf/imaging/camera.h"
#include "tprf/core/error.h"
#include "tprf/io/npy.h"
#include "tprf/geometry/patches.h"
#include "tprf/scene/parse_json.h"
#include "tprf/geometry/visibility.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <random>

namespace tprf {
namespace {

namespace fs = std::filesystem;

fs::path fresh_dir(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / ("tprf_render_" + name + "_" + std::to_string(std::random_device{}()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

fs::path write_scene(const fs::path& dir, const nlohmann::json& j) {
    const fs::path file = dir / "scene.json";
    std::ofstream(file) << j.dump(2);
    return file;
}

// A two-plane corner (floor z=0 and wall x=0, 1 x 1 m), a point light and a camera looking into it.
nlohmann::json corner_scene(int bins, double width, bool unwarp = false) {
    return {
        {"time", {{"bins", bins}, {"bin_width", width}}},
        {"camera", {{"position", {1.6, 0.5, 0.6}}, {"look_at", {0.3, 0.5, 0.3}}, {"up", {0, 0, 1}}, {"fov", 60},
                    {"width", 24}, {"height", 20}, {"spp", 1}, {"unwarp", unwarp}}},
        {"lights", {{{"type", "point"}, {"position", {0.6, 0.3, 0.7}}, {"intensity", 1.0}}}},
        {"objects", {{{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", 0.6}},
                     {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {0, 1, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.5}}}},
        {"patches", {{"max_edge", 0.1}}}};
}

RenderOptions quiet_options(const fs::path& out) {
    RenderOptions o;
    o.output = out;
    return o;
}

TEST(Render, FirstArrivalOfEveryPixelIsTheGeometricPath) {
    const fs::path dir = fresh_dir("arrival");
    const double w = 0.01;
    const fs::path file = write_scene(dir, corner_scene(600, w));
    render_file(file, quiet_options(dir / "out"));
    const NpyArray cube = read_npy(dir / "out" / "transient.npy");
    ASSERT_EQ(cube.shape, (std::vector<std::size_t>{20, 24, 600, 3}));

    const Scene scene = load_scene(file);
    const PatchSet patches = build_patches(scene);
    const Visibility vis(patches);
    const Camera& cam = *scene.camera;
    const Vec3 light(0.6, 0.3, 0.7);
    int seen = 0, empty = 0;
    for (int r = 0; r < cam.height; ++r)
        for (int c = 0; c < cam.width; ++c) {
            const RayHit h = vis.intersect(cam.position, camera_ray(cam, c + 0.5, r + 0.5), 1e30);
            const float* profile = cube.data.data() + (std::size_t(r) * 24 + std::size_t(c)) * 600 * 3;
            int first = -1;
            for (int t = 0; t < 600 && first < 0; ++t)
                if (profile[t * 3] != 0.0f) first = t;
            if (!h.hit || !h.front) {
                EXPECT_EQ(first, -1) << "pixel " << r << "," << c << " sees nothing but is lit";
                ++empty;
                continue;
            }
            ++seen;
            const int expected = int(std::floor(((light - h.point).norm() + h.distance) / w));
            // Within one bin (the bound): the pixel's first light is its own direct path.
            EXPECT_NEAR(first, expected, 1) << "pixel " << r << "," << c;
        }
    EXPECT_GT(seen, 200);
    EXPECT_GT(empty, 10);  // the camera sees past the corner's edges
    fs::remove_all(dir);
}

TEST(Render, TimeIntegralOfTheCubeIsTheSteadyImage) {
    const fs::path dir = fresh_dir("integral");
    // 10 m of path: with albedos 0.6 and 0.5 in an open corner, what is left after that is < 1e-6.
    const fs::path file = write_scene(dir, corner_scene(500, 0.02));
    render_file(file, quiet_options(dir / "out"));
    const NpyArray cube = read_npy(dir / "out" / "transient.npy");
    const NpyArray steady = read_npy(dir / "out" / "steady.npy");
    ASSERT_EQ(steady.shape, (std::vector<std::size_t>{20, 24, 3}));
    double peak = 0.0;
    for (float v : steady.data) peak = std::max(peak, double(v));
    for (std::size_t px = 0; px < 20 * 24; ++px)
        for (int c = 0; c < 3; ++c) {
            double sum = 0.0;
            for (int t = 0; t < 500; ++t) sum += cube.data[(px * 500 + std::size_t(t)) * 3 + std::size_t(c)];
            // Float accumulation in the film and the steady solve's 1e-8: 1e-4 of the image's peak.
            EXPECT_NEAR(sum, steady.data[px * 3 + std::size_t(c)], 1e-4 * peak) << "pixel " << px;
        }
    fs::remove_all(dir);
}

TEST(Render, DirectLightOfAPlaneIsAlbedoTimesIrradianceOverPi) {
    const fs::path dir = fresh_dir("direct");
    nlohmann::json j = corner_scene(400, 0.01);
    j["objects"] = {{{"type", "rectangle"}, {"origin", {-2, -2, 0}}, {"u", {4, 0, 0}}, {"v", {0, 4, 0}}, {"albedo", 0.6}}};
    j["camera"] = {{"position", {0.0, 0.0, 1.5}}, {"look_at", {0.0, 0.0, 0.0}}, {"up", {0, 1, 0}}, {"fov", 70},
                   {"width", 16}, {"height", 16}};
    j["lights"] = {{{"type", "point"}, {"position", {0.3, -0.2, 0.8}}, {"intensity", 2.0}}};
    j["solver"] = {{"max_bounces", 1}};
    const fs::path file = write_scene(dir, j);
    render_file(file, quiet_options(dir / "out"));
    const NpyArray steady = read_npy(dir / "out" / "steady.npy");
    const Scene scene = load_scene(file);
    const Camera& cam = *scene.camera;
    const Vec3 light(0.3, -0.2, 0.8);
    for (int r = 0; r < 16; ++r)
        for (int c = 0; c < 16; ++c) {
            const Vec3 d = camera_ray(cam, c + 0.5, r + 0.5);
            const Vec3 x = cam.position + d * (-cam.position.z() / d.z());
            const Vec3 to_light = light - x;
            const double expected = 0.6 * 2.0 * (to_light.z() / to_light.norm()) / to_light.squaredNorm() / M_PI;
            // The bound: 1%. The direct term is exact at the visible point.
            EXPECT_NEAR(steady.data[(std::size_t(r) * 16 + std::size_t(c)) * 3], expected, 0.01 * expected)
                << "pixel " << r << "," << c << " sees " << x.transpose();
        }
    fs::remove_all(dir);
}

TEST(Render, UnwarpRemovesEachPixelsOwnCameraLeg) {
    const fs::path dir = fresh_dir("unwarp");
    const double w = 0.01;
    const fs::path warped = write_scene(dir, corner_scene(600, w, false));
    render_file(warped, quiet_options(dir / "warped"));
    const fs::path unwarped_dir = dir / "u";
    fs::create_directories(unwarped_dir);
    const fs::path unwarped = write_scene(unwarped_dir, corner_scene(600, w, true));
    render_file(unwarped, quiet_options(dir / "unwarped"));
    const NpyArray a = read_npy(dir / "warped" / "transient.npy");
    const NpyArray b = read_npy(dir / "unwarped" / "transient.npy");
    const Scene scene = load_scene(warped);
    const PatchSet patches = build_patches(scene);
    const Visibility vis(patches);
    auto first_bin = [](const NpyArray& cube, std::size_t px) {
        for (int t = 0; t < 600; ++t)
            if (cube.data[(px * 600 + std::size_t(t)) * 3] != 0.0f) return t;
        return -1;
    };
    int checked = 0;
    for (int r = 0; r < 20; ++r)
        for (int c = 0; c < 24; ++c) {
            const RayHit h = vis.intersect(scene.camera->position, camera_ray(*scene.camera, c + 0.5, r + 0.5), 1e30);
            if (!h.hit || !h.front) continue;
            const std::size_t px = std::size_t(r) * 24 + std::size_t(c);
            EXPECT_NEAR(first_bin(a, px) - first_bin(b, px), h.distance / w, 1.0) << "pixel " << r << "," << c;
            ++checked;
        }
    EXPECT_GT(checked, 200);
    fs::remove_all(dir);
}

TEST(Render, EveryOutputHasTheSpecShape) {
    const fs::path dir = fresh_dir("outputs");
    const fs::path file = write_scene(dir, corner_scene(64, 0.05));
    RenderOptions o = quiet_options(dir / "out");
    o.patch_profiles = o.frames = o.streaks = true;
    const RenderReport report = render_file(file, o);
    const fs::path out = dir / "out";
    EXPECT_EQ(read_npy(out / "transient.npy").shape, (std::vector<std::size_t>{20, 24, 64, 3}));
    EXPECT_EQ(read_npy(out / "steady.npy").shape, (std::vector<std::size_t>{20, 24, 3}));
    EXPECT_EQ(read_npy(out / "patch_transient.npy").shape, (std::vector<std::size_t>{report.patches, 64, 3}));
    EXPECT_EQ(read_npy(out / "patch_steady.npy").shape, (std::vector<std::size_t>{report.patches, 3}));
    EXPECT_TRUE(fs::is_regular_file(out / "steady.exr"));
    EXPECT_TRUE(fs::is_regular_file(out / "preview.png"));
    EXPECT_TRUE(fs::is_regular_file(out / "frames" / "frame_00063.exr"));
    EXPECT_TRUE(fs::is_regular_file(out / "streaks" / "row_0019.exr"));
    std::ifstream csv(out / "patches.csv");
    std::string header;
    std::getline(csv, header);
    EXPECT_EQ(header, "id,object,cx,cy,cz,nx,ny,nz,area");
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(out / "render.json"));
    EXPECT_EQ(j["patches"].get<std::size_t>(), report.patches);
    EXPECT_EQ(j["bins"].get<int>(), 64);
    for (const char* phase : {"load", "patches", "links", "solve", "gather", "write", "total"})
        EXPECT_TRUE(j["seconds"].contains(phase)) << phase;
    EXPECT_GT(j["peak_rss_mb"].get<double>(), 0.0);
    // Nothing is left behind but the outputs.
    for (const auto& entry : fs::directory_iterator(out))
        EXPECT_NE(entry.path().filename().string().front(), '.') << entry.path();
    fs::remove_all(dir);
}

TEST(Render, BadSceneWritesNothing) {
    const fs::path dir = fresh_dir("bad");
    nlohmann::json j = corner_scene(64, 0.05);
    j["objects"][1]["albedo"] = 1.5;
    const fs::path file = write_scene(dir, j);
    try {
        render_file(file, quiet_options(dir / "out"));
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("objects[1].albedo"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(dir / "out"));
    fs::remove_all(dir);
}

}  // namespace
}  // namespace tprf
