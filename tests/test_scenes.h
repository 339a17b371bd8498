#pragma once
// Scenes with known answers, built directly as tprf::Scene (no JSON), shared by the stage tests.

#include "tprf/core/error.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/scene.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

// The numbers that a test's bounds were set from, printed when TPRF_TEST_MEASURE is set (rerun with
// it to see where a change moved them).
#define MEASURED(...)                                                                    \
    do {                                                                                 \
        if (std::getenv("TPRF_TEST_MEASURE")) std::printf("[measured] " __VA_ARGS__);    \
    } while (false)

namespace tprf::test {

/// The message with which parse_scene refuses scene JSON `text` (named bad.json), or "" when it parses.
inline std::string parse_error(const std::string& text) {
    try {
        parse_scene(text, "bad.json");
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

/// A scratch directory holding a one-triangle mesh, meshes/tri.obj (what the scene tests' files name);
/// removed with everything in it.
struct MeshDir {
    std::filesystem::path path;
    explicit MeshDir(const std::string& prefix) {
        std::random_device rd;
        path = std::filesystem::temp_directory_path() / (prefix + std::to_string(rd()) + std::to_string(rd()));
        std::filesystem::create_directories(path / "meshes");
        std::ofstream(path / "meshes" / "tri.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    }
    ~MeshDir() {
        std::error_code ec;
        std::filesystem::remove_all(path, ec);
    }
    MeshDir(const MeshDir&) = delete;
    MeshDir& operator=(const MeshDir&) = delete;
};

/// A time axis of `bins` bins of `width` metres from `start`.
inline TimeAxis time_axis(int bins, double width, double start = 0.0) {
    TimeAxis t;
    t.bins = bins;
    t.bin_width = width;
    t.start = start;
    return t;
}

inline Object rectangle(const Vec3& origin, const Vec3& u, const Vec3& v, double albedo = 0.5,
                        double emission = 0.0) {
    Object o;
    o.shape = RectangleShape{origin, u, v};
    o.albedo = Rgb::Constant(albedo);
    o.emission = Rgb::Constant(emission);
    return o;
}

/// Howell's catalogue C-11: directly opposed parallel rectangles a x b at distance c.
inline double ff_parallel_rectangles(double a, double b, double c) {
    const double x = a / c, y = b / c;
    const double x1 = std::sqrt(1 + x * x), y1 = std::sqrt(1 + y * y);
    return 2.0 / (M_PI * x * y) *
           (std::log(x1 * y1 / std::sqrt(1 + x * x + y * y)) + x * y1 * std::atan(x / y1) +
            y * x1 * std::atan(y / x1) - x * std::atan(x) - y * std::atan(y));
}

/// Howell's catalogue C-14: perpendicular rectangles with a common edge of length l; the sending
/// rectangle is w x l, the receiving one h x l.
inline double ff_perpendicular_rectangles(double w, double h, double l) {
    const double W = w / l, H = h / l;
    const double w2 = W * W, h2 = H * H, s = w2 + h2;
    const double a = (1 + w2) * (1 + h2) / (1 + s);
    const double b = w2 * (1 + s) / ((1 + w2) * s);
    const double c = h2 * (1 + s) / ((1 + h2) * s);
    return 1.0 / (M_PI * W) *
           (W * std::atan(1 / W) + H * std::atan(1 / H) - std::sqrt(s) * std::atan(1 / std::sqrt(s)) +
            0.25 * (std::log(a) + w2 * std::log(b) + h2 * std::log(c)));
}

/// Differential area to a parallel rectangle a x b at distance c, the normal through one corner
/// (Howell's catalogue B-3).
inline double ff_point_parallel_rectangle_corner(double a, double b, double c) {
    const double A = a / c, B = b / c;
    const double a1 = std::sqrt(1 + A * A), b1 = std::sqrt(1 + B * B);
    return 1.0 / (2 * M_PI) * (A / a1 * std::atan(B / a1) + B / b1 * std::atan(A / b1));
}

/// Differential area at (px, py) on a plane to a parallel rectangle [x0, x1] x [y0, y1] at height h
/// above it: Howell's B-3 added and subtracted over the four corners; B-3 is odd in each side, so the
/// signs handle points outside the rectangle's shadow too.
inline double ff_point_to_parallel_rectangle(double px, double py, double x0, double x1, double y0, double y1,
                                             double h) {
    const auto f = [&](double a, double b) { return ff_point_parallel_rectangle_corner(a, b, h); };
    return f(x1 - px, y1 - py) - f(x0 - px, y1 - py) - f(x1 - px, y0 - py) + f(x0 - px, y0 - py);
}

/// A closed box [0,sx] x [0,sy] x [0,sz] of six rectangles facing inward.
inline void add_closed_box(Scene& scene, const Vec3& size, double albedo = 0.5, double emission = 0.0) {
    const Vec3 X = size.x() * Vec3::UnitX(), Y = size.y() * Vec3::UnitY(), Z = size.z() * Vec3::UnitZ();
    const Vec3 O = Vec3::Zero();
    scene.objects.push_back(rectangle(O, X, Y, albedo, emission));  // floor z=0, normal +z
    scene.objects.push_back(rectangle(Z, Y, X, albedo, emission));  // ceiling z=sz, normal -z
    scene.objects.push_back(rectangle(O, Z, X, albedo, emission));  // wall y=0, normal +y
    scene.objects.push_back(rectangle(Y, X, Z, albedo, emission));  // wall y=sy, normal -y
    scene.objects.push_back(rectangle(O, Y, Z, albedo, emission));  // wall x=0, normal +x
    scene.objects.push_back(rectangle(X, Z, Y, albedo, emission));  // wall x=sx, normal -x
}

/// A closed box [0,s]^3 of six rectangles facing inward.
inline void add_closed_cube(Scene& scene, double s, double albedo = 0.5, double emission = 0.0) {
    add_closed_box(scene, Vec3::Constant(s), albedo, emission);
}

}  // namespace tprf::test
