// Calibrated cameras and spot lights (docs/scene.md): intrinsics and Brown-Conrady distortion checked
// against OpenCV's projection formula written out here, and a spot's light on a plane against its
// closed form.

#include "test_scenes.h"

#include "tprf/core/error.h"
#include "tprf/imaging/camera.h"
#include "tprf/imaging/ground_truth.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"
#include "tprf/transport/light_sources.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>

namespace {

using nlohmann::json;
using tprf::Vec3;

// OpenCV's projectPoints for one point, written from its documentation: the camera frame has x right,
// y down, z along the view; the normalised point (x, y) = (X / Z, Y / Z) is distorted, then scaled by
// the focal lengths and moved to the principal point.
struct OpenCvProjection {
    double fx, fy, cx, cy, k1, k2, k3, p1, p2;

    std::array<double, 2> project(const Vec3& camera_frame) const {
        const double x = camera_frame.x() / camera_frame.z(), y = camera_frame.y() / camera_frame.z();
        const double r2 = x * x + y * y, radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
        const double xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
        const double yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
        return {fx * xd + cx, fy * yd + cy};
    }
};

// A 320 x 240 camera at `position` looking along +y with z up, as the JSON scene gives it.
json calibrated_camera(const json& intrinsics, const json& distortion) {
    json c = {{"position", {0.1, -1.0, 0.4}}, {"look_at", {0.3, 1.0, 0.2}}, {"up", {0, 0, 1}},
              {"width", 320}, {"height", 240}, {"intrinsics", intrinsics}};
    if (!distortion.is_null()) c["distortion"] = distortion;
    return c;
}

json scene_with_camera(const json& camera) {
    return {{"time", {{"bins", 10}, {"bin_width", 0.1}}},
            {"camera", camera},
            {"objects", {{{"type", "rectangle"}, {"origin", {-1, -1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 2, 0}}, {"albedo", 0.5}}}}};
}

std::string error_of(const json& scene) { return tprf::test::parse_error(scene.dump()); }

// Every point in front of the camera that OpenCV's formula puts inside the image is seen by the ray of
// the image position where it lands: camera_ray undoes the distortion that the formula applies.
TEST(CameraModel, APointProjectsWhereOpenCvsFormulaPutsIt) {
    const OpenCvProjection cv{260.0, 250.0, 161.3, 117.8, -0.12, 0.03, -0.004, 0.0015, -0.0008};
    const json camera = calibrated_camera({{"fx", cv.fx}, {"fy", cv.fy}, {"cx", cv.cx}, {"cy", cv.cy}},
                                          {{"k1", cv.k1}, {"k2", cv.k2}, {"k3", cv.k3}, {"p1", cv.p1}, {"p2", cv.p2}});
    const tprf::Scene scene = tprf::parse_scene(scene_with_camera(camera).dump(), "calibrated.json");
    const tprf::Camera& cam = *scene.camera;
    const Vec3 forward = (cam.look_at - cam.position).normalized();
    const Vec3 right = forward.cross(cam.up).normalized(), up = right.cross(forward);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> across(-0.9, 0.9), depth(0.5, 5.0);
    int inside = 0;
    double worst = 0.0, worst_undistorted = 0.0;
    for (int k = 0; k < 2000; ++k) {
        const Vec3 frame(across(rng), across(rng), 1.0);  // x right, y down, z forward
        const Vec3 point = cam.position + depth(rng) * (frame.x() * right - frame.y() * up + frame.z() * forward);
        const auto [u, v] = cv.project(frame);
        if (u < -0.5 || u > 319.5 || v < -0.5 || v > 239.5) continue;
        ++inside;
        // OpenCV's pixel (u, v) is the image position (u + 0.5, v + 0.5): pixel centres at integers.
        const Vec3 ray = tprf::camera_ray(cam, u + 0.5, v + 0.5);
        worst = std::max(worst, (ray - (point - cam.position).normalized()).norm());
        // Without distortion the same point lands at the pinhole's position.
        tprf::Camera pinhole = cam;
        pinhole.distortion = {};
        const double x = frame.x() / frame.z(), y = frame.y() / frame.z();
        const Vec3 straight = tprf::camera_ray(pinhole, cv.fx * x + cv.cx + 0.5, cv.fy * y + cv.cy + 0.5);
        worst_undistorted = std::max(worst_undistorted, (straight - (point - cam.position).normalized()).norm());
    }
    MEASURED("%d points inside the image: rays within %.3g (distorted), %.3g (pinhole) of the points\n", inside,
             worst, worst_undistorted);
    EXPECT_GT(inside, 500);
    EXPECT_LT(worst, 1e-10);
    EXPECT_LT(worst_undistorted, 1e-12);
    // The distortion matters here: the same position read without it misses by far more.
    tprf::Camera pinhole = cam;
    pinhole.distortion = {};
    EXPECT_GT((tprf::camera_ray(pinhole, 1.0, 1.0) - tprf::camera_ray(cam, 1.0, 1.0)).norm(), 1e-2);
}

TEST(CameraModel, DistortionsJacobianIsItsDerivative) {
    const tprf::Distortion d{-0.2, 0.05, -0.01, 0.003, -0.002};
    for (const tprf::Vec2& p : {tprf::Vec2(0.1, -0.2), tprf::Vec2(-0.6, 0.4), tprf::Vec2(0.0, 0.7)}) {
        const double h = 1e-6;
        Eigen::Matrix2d numeric;
        numeric.col(0) = (d.apply(p + tprf::Vec2(h, 0)) - d.apply(p - tprf::Vec2(h, 0))) / (2 * h);
        numeric.col(1) = (d.apply(p + tprf::Vec2(0, h)) - d.apply(p - tprf::Vec2(0, h))) / (2 * h);
        EXPECT_LT((numeric - d.jacobian(p)).norm(), 1e-8) << p.transpose();
        const std::optional<tprf::Vec2> back = d.undo(d.apply(p));
        ASSERT_TRUE(back) << p.transpose();
        EXPECT_LT((*back - p).norm(), 1e-12) << p.transpose();
    }
}

// A fov camera is the camera with fx = fy = (height / 2) / tan(fov / 2) and the principal point at the
// image centre: the same cube, bit for bit. Moving the principal point 3 pixels right moves the image.
TEST(CameraModel, IntrinsicsEqualToAFovCameraRenderTheSameCube) {
    const double fov = 60.0;
    json s = {{"time", {{"bins", 300}, {"bin_width", 0.01}}},
              {"camera", {{"position", {1.6, 0.5, 0.6}}, {"look_at", {0.3, 0.5, 0.3}}, {"up", {0, 0, 1}}, {"fov", fov},
                          {"width", 24}, {"height", 20}, {"spp", 4}}},
              {"lights", {{{"type", "point"}, {"position", {0.6, 0.3, 0.7}}, {"intensity", 1.0}}}},
              {"objects", {{{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", 0.6}},
                           {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {0, 1, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.5}}}},
              {"patches", {{"max_edge", 0.1}}}};
    const tprf::RenderResult by_fov = tprf::render_scene(tprf::parse_scene(s.dump(), "fov.json"), {});
    const double f = 0.5 * 20 / std::tan(0.5 * fov * M_PI / 180.0);
    s["camera"].erase("fov");
    s["camera"]["intrinsics"] = {{"fx", f}, {"fy", f}, {"cx", 11.5}, {"cy", 9.5}};
    const tprf::RenderResult by_k = tprf::render_scene(tprf::parse_scene(s.dump(), "k.json"), {});
    for (const char* name : {"transient", "steady"})
        EXPECT_TRUE(by_fov.arrays.at(name).data == by_k.arrays.at(name).data) << name;

    s["camera"]["intrinsics"]["cx"] = 14.5;
    s["camera"]["footprint"] = false;  // point samples: each sample's own ray, whichever pixel it is in
    const tprf::RenderResult shifted = tprf::render_scene(tprf::parse_scene(s.dump(), "shifted.json"), {});
    s["camera"]["intrinsics"]["cx"] = 11.5;
    const tprf::RenderResult centred = tprf::render_scene(tprf::parse_scene(s.dump(), "centred.json"), {});
    const auto& a = centred.arrays.at("steady").data;
    const auto& b = shifted.arrays.at("steady").data;
    double worst = 0.0, peak = 0.0, moved = 0.0;
    for (std::size_t r = 0; r < 20; ++r)
        for (std::size_t c = 0; c + 3 < 24; ++c) {
            const double here = a[(r * 24 + c) * 3], there = b[(r * 24 + c + 3) * 3];
            worst = std::max(worst, std::abs(here - there));
            peak = std::max(peak, here);
            moved = std::max(moved, std::abs(here - b[(r * 24 + c) * 3]));
        }
    MEASURED("principal point 3 px right: column c + 3 is column c to %.3g of the peak (unshifted %.3g)\n", worst / peak,
             moved / peak);
    EXPECT_LT(worst, 1e-5 * peak);
    EXPECT_GT(moved, 1e-2 * peak);  // the comparison could fail: the image is not uniform along a row
}

TEST(CameraModel, BadIntrinsicsAndFoldingDistortionsNameTheirJsonPath) {
    const json k = {{"fx", 260.0}, {"fy", 260.0}, {"cx", 159.5}, {"cy", 119.5}};
    json both = scene_with_camera(calibrated_camera(k, nullptr));
    both["camera"]["fov"] = 40;
    EXPECT_NE(error_of(both).find("camera: give either \"fov\" or \"intrinsics\", not both"), std::string::npos)
        << error_of(both);
    json neither = scene_with_camera(calibrated_camera(k, nullptr));
    neither["camera"].erase("intrinsics");
    EXPECT_NE(error_of(neither).find("fov"), std::string::npos) << error_of(neither);
    json zero = scene_with_camera(calibrated_camera(k, nullptr));
    zero["camera"]["intrinsics"]["fy"] = 0.0;
    EXPECT_NE(error_of(zero).find("camera.intrinsics.fy: must be > 0"), std::string::npos) << error_of(zero);
    json missing = scene_with_camera(calibrated_camera({{"fx", 1.0}, {"fy", 1.0}, {"cx", 0.0}}, nullptr));
    EXPECT_NE(error_of(missing).find("cy"), std::string::npos) << error_of(missing);
    json unknown = scene_with_camera(calibrated_camera(k, {{"k4", 0.1}}));
    EXPECT_NE(error_of(unknown).find("k4"), std::string::npos) << error_of(unknown);
    // k1 = -0.5 turns back at r = 0.82 (its image radius at most 0.54); the corners of a 320 x 240
    // image at fx = 100 lie at radius 2.
    json folded = scene_with_camera(calibrated_camera({{"fx", 100.0}, {"fy", 100.0}, {"cx", 159.5}, {"cy", 119.5}},
                                                      {{"k1", -0.5}}));
    EXPECT_NE(error_of(folded).find("camera.distortion: folds the image over at pixel corner"), std::string::npos)
        << error_of(folded);
    // The same lens with a narrow image (radius 0.5 at the corners) is fine.
    folded["camera"]["width"] = 60;
    folded["camera"]["height"] = 60;
    folded["camera"]["intrinsics"]["cx"] = 29.5;
    folded["camera"]["intrinsics"]["cy"] = 29.5;
    folded["camera"]["intrinsics"]["fx"] = 85.0;
    folded["camera"]["intrinsics"]["fy"] = 85.0;
    EXPECT_EQ(error_of(folded), "");
}

// The spot's profile written from the scene format's words: full inside the half angle, a smoothstep in
// the angle over the falloff, nothing beyond.
double spot_profile(const Vec3& axis, const Vec3& dir, double half_deg, double falloff_deg) {
    const double angle = std::acos(std::clamp(axis.dot(dir), -1.0, 1.0)) * 180.0 / M_PI;
    if (angle <= half_deg) return 1.0;
    if (angle >= half_deg + falloff_deg) return 0.0;
    const double t = 1.0 - (angle - half_deg) / falloff_deg;
    return 3 * t * t - 2 * t * t * t;
}

// A spot over a plane: every pixel's direct light is albedo / pi times I profile cos / r^2, inside the
// cone, in its falloff and outside it.
TEST(SpotLight, ItsLightOnAPlaneIsItsProfileTimesThePointLights) {
    const Vec3 light(0.1, -0.1, 0.8), target(0.3, 0.2, 0.0);
    const double half = 20.0, falloff = 12.0;
    const json s = {{"time", {{"bins", 400}, {"bin_width", 0.01}}},
                    {"camera", {{"position", {0.0, 0.0, 1.6}}, {"look_at", {0.0, 0.0, 0.0}}, {"up", {0, 1, 0}}, {"fov", 80},
                                {"width", 32}, {"height", 32}, {"footprint", false}}},
                    {"lights", {{{"type", "spot"}, {"position", {light.x(), light.y(), light.z()}},
                                 {"target", {target.x(), target.y(), target.z()}}, {"intensity", 2.0},
                                 {"half_angle", half}, {"falloff", falloff}}}},
                    {"objects", {{{"type", "rectangle"}, {"origin", {-2, -2, 0}}, {"u", {4, 0, 0}}, {"v", {0, 4, 0}}, {"albedo", 0.6}}}},
                    {"patches", {{"max_edge", 0.1}}},
                    {"solver", {{"max_bounces", 1}}}};
    const tprf::Scene scene = tprf::parse_scene(s.dump(), "spot.json");
    const tprf::RenderResult r = tprf::render_scene(scene, {});
    const auto& steady = r.arrays.at("steady").data;
    const tprf::Camera& cam = *scene.camera;
    const Vec3 axis = (target - light).normalized();
    int full = 0, falling = 0, dark = 0;
    double worst = 0.0;
    for (int row = 0; row < 32; ++row)
        for (int col = 0; col < 32; ++col) {
            const Vec3 d = tprf::camera_ray(cam, col + 0.5, row + 0.5);
            const Vec3 x = cam.position + d * (-cam.position.z() / d.z());
            const Vec3 to_light = light - x;
            const double profile = spot_profile(axis, -to_light.normalized(), half, falloff);
            const double expected =
                0.6 * 2.0 * profile * (to_light.z() / to_light.norm()) / to_light.squaredNorm() / M_PI;
            const double got = steady[(std::size_t(row) * 32 + std::size_t(col)) * 3];
            (profile == 1.0 ? full : profile > 0.0 ? falling : dark) += 1;
            worst = std::max(worst, std::abs(got - expected) / (0.6 * 2.0 / M_PI));
            EXPECT_NEAR(got, expected, 1e-5 * 0.6 * 2.0 / M_PI) << "pixel " << row << "," << col << " profile " << profile;
        }
    MEASURED("spot on a plane: %d pixels in the cone, %d in its falloff, %d outside; worst %.3g of albedo I / pi\n",
             full, falling, dark, worst);
    EXPECT_GT(full, 20);
    EXPECT_GT(falling, 20);
    EXPECT_GT(dark, 20);
}

// The power a spot sends is its intensity times the solid angle its profile weighs: summed here over a
// fine latitude-longitude grid of directions, independently of the library's quadrature.
TEST(SpotLight, ThePowerItSendsIsItsProfileOverTheSphere) {
    tprf::PointSource s;
    s.intensity = tprf::Rgb::Constant(1.5);
    s.spot_axis = Vec3(1, 2, -2).normalized();
    s.spot_half_angle = 30.0 * M_PI / 180.0;
    s.spot_falloff = 15.0 * M_PI / 180.0;
    const Vec3 a = s.spot_axis, b = a.unitOrthogonal(), c = a.cross(b);
    const int n_theta = 4000, n_phi = 64;
    double sum = 0.0;
    for (int i = 0; i < n_theta; ++i) {
        const double theta = (i + 0.5) * M_PI / n_theta;
        for (int j = 0; j < n_phi; ++j) {
            const double phi = (j + 0.5) * 2 * M_PI / n_phi;
            const Vec3 dir = std::cos(theta) * a + std::sin(theta) * (std::cos(phi) * b + std::sin(phi) * c);
            sum += s.intensity_towards(dir)[0] * std::sin(theta) * (M_PI / n_theta) * (2 * M_PI / n_phi);
        }
    }
    EXPECT_NEAR(s.power_sent()[0], sum, 1e-5 * sum);
    // Without its axis the same source is isotropic: 4 pi I.
    s.spot_axis = Vec3::Zero();
    EXPECT_DOUBLE_EQ(s.power_sent()[0], 4 * M_PI * 1.5);
}

TEST(SpotLight, BadSpotsNameTheirJsonPath) {
    const json base = {{"time", {{"bins", 10}, {"bin_width", 0.1}}},
                       {"camera", {{"position", {0, 0, 2}}, {"look_at", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov", 40},
                                   {"width", 4}, {"height", 4}}},
                       {"objects", {{{"type", "rectangle"}, {"origin", {-1, -1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 2, 0}}}}}};
    const json spot = {{"type", "spot"}, {"position", {0, 0, 1}}, {"direction", {0, 0, -1}}, {"intensity", 1.0},
                       {"half_angle", 30}, {"falloff", 5}};
    const auto with = [&](const char* key, const json& value) {
        json s = base, l = spot;
        if (value.is_null()) l.erase(key);
        else l[key] = value;
        s["lights"] = {l};
        return error_of(s);
    };
    EXPECT_EQ(with("falloff", nullptr), "");  // a hard edge
    EXPECT_NE(with("half_angle", nullptr).find("lights[0]: missing key \"half_angle\""), std::string::npos)
        << with("half_angle", nullptr);
    EXPECT_NE(with("half_angle", 0).find("lights[0].half_angle: must be in (0, 180) degrees"), std::string::npos)
        << with("half_angle", 0);
    EXPECT_NE(with("falloff", -1).find("lights[0].falloff: must be >= 0"), std::string::npos) << with("falloff", -1);
    EXPECT_NE(with("falloff", 160).find("lights[0].falloff: with half_angle must be at most 180"), std::string::npos)
        << with("falloff", 160);
    EXPECT_NE(with("direction", json::array({0, 0, 0})).find("lights[0].direction: has zero length"), std::string::npos)
        << with("direction", json::array({0, 0, 0}));
    EXPECT_NE(with("direction", nullptr).find("missing key \"direction\" or \"target\""), std::string::npos)
        << with("direction", nullptr);
    json point = base;
    point["lights"] = {{{"type", "point"}, {"position", {0, 0, 1}}, {"intensity", 1.0}, {"half_angle", 30}}};
    EXPECT_NE(error_of(point).find("half_angle"), std::string::npos) << error_of(point);  // not a point light's key
}

}  // namespace

namespace {

// The ground truth maps of a distorted calibrated camera over a floor and a glossy board standing on
// it: every pixel's position lies on the object its map names, projects back (OpenCV's formula) to the
// pixel's centre, is `depth` from the camera and has that object's normal and diffuse albedo; pixels
// that see nothing say so.
TEST(GroundTruth, EveryPixelsCentreRayMeetsWhatItsMapsSay) {
    const OpenCvProjection cv{70.0, 72.0, 31.0, 23.5, -0.08, 0.01, 0.0, 0.001, 0.0005};
    const json s = {
        {"time", {{"bins", 50}, {"bin_width", 0.1}}},
        {"camera", {{"position", {0.0, -1.5, 0.8}}, {"look_at", {0.0, 0.5, 0.0}}, {"up", {0, 0, 1}}, {"width", 64},
                    {"height", 48}, {"intrinsics", {{"fx", cv.fx}, {"fy", cv.fy}, {"cx", cv.cx}, {"cy", cv.cy}}},
                    {"distortion", {{"k1", cv.k1}, {"k2", cv.k2}, {"p1", cv.p1}, {"p2", cv.p2}}}}},
        {"lights", {{{"type", "point"}, {"position", {0.3, -0.5, 1.0}}, {"intensity", 1.0}}}},
        {"objects",
         {{{"type", "rectangle"}, {"origin", {-1, -1, 0}}, {"u", {2, 0, 0}}, {"v", {0, 2, 0}}, {"albedo", {0.2, 0.4, 0.6}}},
          {{"type", "rectangle"}, {"origin", {-0.3, 0.2, 0}}, {"u", {0.6, 0.0, 0}}, {"v", {0, 0.1, 0.5}},
           {"material", {{"type", "glossy"}, {"albedo", 0.3}, {"reflectance", 0.5}, {"roughness", 0.2}}}}}},
        {"patches", {{"max_edge", 0.25}}}};
    const tprf::Scene scene = tprf::parse_scene(s.dump(), "truth.json");
    tprf::RenderOptions options;
    options.aovs = tprf::parse_aov_list("all", "aov");
    const tprf::RenderResult r = tprf::render_scene(scene, options);
    const auto& depth = r.arrays.at("aov_depth");
    const auto& normal = r.arrays.at("aov_normal").data;
    const auto& position = r.arrays.at("aov_position").data;
    const auto& albedo = r.arrays.at("aov_albedo").data;
    const auto& object = r.labels.at("aov_object");
    ASSERT_EQ(depth.shape, (std::vector<std::size_t>{48, 64}));
    ASSERT_EQ(object.shape, (std::vector<std::size_t>{48, 64}));
    const tprf::Camera& cam = *scene.camera;
    const Vec3 forward = (cam.look_at - cam.position).normalized();
    const Vec3 right = forward.cross(cam.up).normalized(), up = right.cross(forward);
    // Each object's plane (a point and the normal of the side the camera sees) and diffuse albedo.
    const Vec3 board_normal = Vec3(0.6, 0, 0).cross(Vec3(0, 0.1, 0.5)).normalized();
    const std::array<Vec3, 2> point = {Vec3(0, 0, 0), Vec3(-0.3, 0.2, 0)};
    const std::array<Vec3, 2> side = {Vec3(0, 0, 1), board_normal.dot(cam.position - point[1]) > 0 ? board_normal
                                                                                                      : Vec3(-board_normal)};
    const std::array<tprf::Rgb, 2> diffuse = {tprf::Rgb(0.2, 0.4, 0.6), tprf::Rgb::Constant(0.3)};
    std::array<int, 3> seen{};  // nothing, the floor, the board
    double worst_px = 0.0;
    for (std::size_t row = 0; row < 48; ++row)
        for (std::size_t col = 0; col < 64; ++col) {
            const std::size_t p = row * 64 + col;
            const int k = object.data[p];
            ASSERT_GE(k, -1);
            ASSERT_LE(k, 1);
            ++seen[std::size_t(k + 1)];
            if (k < 0) {
                EXPECT_TRUE(std::isinf(depth.data[p])) << row << "," << col;
                EXPECT_TRUE(std::isnan(position[3 * p])) << row << "," << col;
                continue;
            }
            const Vec3 x(position[3 * p], position[3 * p + 1], position[3 * p + 2]);
            const Vec3 n(normal[3 * p], normal[3 * p + 1], normal[3 * p + 2]);
            EXPECT_NEAR((x - point[std::size_t(k)]).dot(side[std::size_t(k)]), 0.0, 1e-6) << row << "," << col;
            EXPECT_LT((n - side[std::size_t(k)]).norm(), 1e-6) << row << "," << col;
            EXPECT_NEAR(depth.data[p], (x - cam.position).norm(), 1e-5) << row << "," << col;
            for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(albedo[3 * p + std::size_t(c)], float(diffuse[std::size_t(k)][c]));
            const Vec3 rel = x - cam.position;
            const auto [u, v] = cv.project(Vec3(rel.dot(right), -rel.dot(up), rel.dot(forward)));
            worst_px = std::max(worst_px, std::hypot(u - double(col), v - double(row)));
        }
    MEASURED("ground truth: %d pixels see nothing, %d the floor, %d the board; positions project back within %.3g px\n",
             seen[0], seen[1], seen[2], worst_px);
    EXPECT_LT(worst_px, 1e-3);  // float32 positions about 1 m away
    for (const int n : seen) EXPECT_GT(n, 50);
}

}  // namespace
