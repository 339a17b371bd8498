// NLOS captures (pipeline/capture.h): onsets from geometry, the third bounce of a small patch against
// its closed form, reciprocity of exhaustive scans, batches against single marches, and bad blocks.

#include "test_process.h"
#include "test_scenes.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/io/npy.h"
#include "tprf/pipeline/capture.h"
#include "tprf/scene/parse_json.h"
#include "tprf/transport/link_set.h"

#include <gtest/gtest.h>
#include <H5Cpp.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <string>

namespace tprf {
namespace {

namespace fs = std::filesystem;

// A 2 m relay wall in the plane z = 0, its front toward +z.
const char* kWall = R"({"type": "rectangle", "origin": [-1, -1, 0], "u": [2, 0, 0], "v": [0, 2, 0], "albedo": 0.8})";
// A hidden plane z = 0.6 + 0.2 x over the wall, its front toward the wall.
const char* kTiltedPlane =
    R"({"type": "rectangle", "origin": [-1, -1, 0.4], "u": [0, 2, 0], "v": [2, 0, 0.4], "albedo": 0.5})";

std::string scene_text(const std::string& objects, const std::string& capture, const std::string& time,
                       double max_edge = 0.05, const std::string& links = R"({"method": "flat"})") {
    return R"({"time": )" + time + R"(, "objects": [)" + objects + R"(], "patches": {"max_edge": )" +
           std::to_string(max_edge) + R"(}, "links": )" + links + R"(, "capture": )" + capture + "}";
}

// The built stages a capture needs.
struct Built {
    Scene scene;
    PatchSet patches;
    std::unique_ptr<Visibility> visibility;
    LinkSet links;

    explicit Built(const std::string& text) : scene(parse_scene(text, "capture_test.json")) {
        patches = build_patches(scene);
        visibility = std::make_unique<Visibility>(patches);
        if (capture_needs_links(scene))
            links = make_link_set(patches, *visibility, scene.links, march_time(scene).bin_width_m());
    }
    CaptureResult capture(int batch = 0) const {
        CaptureOptions options;
        options.batch = batch;
        return compute_capture(scene, patches, *visibility, capture_needs_links(scene) ? &links : nullptr, options);
    }
};

double plane_distance(const Vec3& x) {
    // The plane through (-1, -1, 0.4) with normal (0.8, 0, -4) (u x v of kTiltedPlane).
    const Vec3 n = Vec3(0.8, 0.0, -4.0).normalized();
    return std::abs(n.dot(x - Vec3(-1, -1, 0.4)));
}

// The first bin after `from` that holds light, or the row's length.
std::size_t first_lit(const float* H, std::size_t from, std::size_t bins) {
    while (from < bins && H[from] == 0.0f) ++from;
    return from;
}

// The bin of a path, or nothing where the path lies within 1e-4 m of a bin's edge (the float paths of
// the views and of Embree are known to about 1e-6 of their length: either bin may then hold it).
std::optional<std::size_t> bin_of(double path, double bw) {
    const double x = path / bw, k = std::floor(x);
    if ((x - k) * bw < 1e-4 || (k + 1 - x) * bw < 1e-4) return std::nullopt;
    return std::size_t(k);
}

// Confocal onsets: the first light after the spot (bin 0) reaches every sensor point at twice its distance
// to the hidden plane (plus both device legs when they are accounted), to the bin. The foot of the
// perpendicular lies inside the plane for every point, where the third bounce's first light starts at
// the shortest path by way of the patch's plane: exact.
void check_confocal_onsets(bool account) {
    const std::string capture = std::string(R"({"type": "confocal", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]}, "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0],
        "v": [0, 1, 0], "nu": 8, "nv": 8}, "max_bounces": 3, "account_first_and_last_bounces": )") +
                                (account ? "true" : "false") + "}";
    const Built b(scene_text(std::string(kWall) + "," + kTiltedPlane, capture,
                             R"({"bins": 700, "bin_width": 0.01})"));
    const CaptureResult r = b.capture();
    ASSERT_EQ(r.pairs, 64u);
    EXPECT_FALSE(r.solved);
    const double bw = 0.01;
    const Vec3 device(0, -1.5, 0.3);
    int checked = 0;
    for (std::size_t s = 0; s < r.pairs; ++s) {
        const Vec3 x = r.points.sensor[s].point;
        const double legs = account ? 2.0 * (device - x).norm() : 0.0;
        const double d = plane_distance(x);
        const std::size_t spot = std::size_t(std::floor(legs / bw));
        const float* H = r.H.data() + s * std::size_t(r.bins);
        // The spot itself: albedo P / (pi A_cell), A_cell = 1/64 m^2.
        EXPECT_NEAR(H[spot], 0.8 * 64 / M_PI, 1e-5 * 0.8 * 64 / M_PI) << "point " << s;
        const auto expected = bin_of(2 * d + legs, bw);
        if (!expected) continue;
        ++checked;
        EXPECT_EQ(first_lit(H, spot + 1, std::size_t(r.bins)), *expected) << "point " << s << " d " << d;
    }
    EXPECT_GE(checked, 60);
}

// Where the nearest hidden point is a patch's edge (a plate beside the sensor points, not over them),
// the cells' light is timed as boxes about their samples: the onset is the bin of twice the distance to
// the plate's edge, never later (samples alone start h/4 inside the patch: 1 to 2 bins late here), and
// earlier only by the path's curvature across a cell, (h sqrt(2) / 4)^2 / d.
TEST(Capture, ConfocalOnsetsAtAPatchEdgeAreNotLate) {
    const std::string capture = R"({"type": "confocal", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]}, "grid": {"origin": [-0.6, -0.05, 0], "u": [0.7, 0, 0],
        "v": [0, 0.1, 0], "nu": 14, "nv": 1}, "max_bounces": 3})";
    const char* plate =
        R"({"type": "rectangle", "origin": [0.2, -0.15, 0.5], "u": [0, 0.3, 0], "v": [0.3, 0, 0], "albedo": 0.5})";
    const Built b(scene_text(std::string(kWall) + "," + plate, capture, R"({"bins": 400, "bin_width": 0.01})"));
    const CaptureResult r = b.capture();
    ASSERT_EQ(r.pairs, 14u);
    const double h = 0.05, bw = 0.01;
    int checked = 0, exact = 0;
    for (std::size_t s = 0; s < r.pairs; ++s) {
        const Vec3 x = r.points.sensor[s].point;
        const double d = std::hypot(0.2 - x.x(), 0.5);  // to the plate's nearest edge, y = 0 on it
        const auto latest = bin_of(2 * d, bw);
        if (!latest) continue;
        ++checked;
        const std::size_t earliest = std::size_t(std::floor((2 * d - h * h / (8 * d) - 1e-4) / bw));
        const std::size_t onset = first_lit(r.H.data() + s * std::size_t(r.bins), 1, std::size_t(r.bins));
        EXPECT_LE(onset, *latest) << "point " << s << " x " << x.x();
        EXPECT_GE(onset, earliest) << "point " << s << " x " << x.x();
        exact += onset == *latest;
    }
    MEASURED("edge onsets: %d of %d in the exact bin\n", exact, checked);
    EXPECT_GE(checked, 10);  // 3 of the 14 paths lie on a bin edge (1.45 m, 1.25 m, 1.68003 m)
}

// Exhaustive onsets: laser point l and sensor point s apart, the first light by way of the hidden plane
// arrives along the shortest path l -> plane -> s, the straight line from l to the mirror image of s
// across the plane (found here by reflecting s, independently of the capture's formula), to the bin.
TEST(Capture, ExhaustiveOnsetsFollowTheMirrorImageOfTheSensorPoint) {
    const std::string capture = R"({"type": "exhaustive", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]}, "grid": {"origin": [-0.45, -0.45, 0], "u": [0.9, 0, 0],
        "v": [0, 0.9, 0], "nu": 3, "nv": 3}, "sensor_grid": {"origin": [-0.3, -0.3, 0], "u": [0.6, 0, 0],
        "v": [0, 0.6, 0], "nu": 4, "nv": 4}, "max_bounces": 3})";
    const Built b(scene_text(std::string(kWall) + "," + kTiltedPlane, capture, R"({"bins": 500, "bin_width": 0.01})"));
    const CaptureResult r = b.capture();
    ASSERT_EQ(r.pairs, 9u * 16u);
    const Vec3 n = Vec3(0.8, 0.0, -4.0).normalized(), on_plane(-1, -1, 0.4);
    int checked = 0;
    for (std::size_t l = 0; l < 9; ++l)
        for (std::size_t s = 0; s < 16; ++s) {
            const Vec3 x = r.points.laser[l].point, y = r.points.sensor[s].point;
            const Vec3 mirrored = y - 2.0 * n.dot(y - on_plane) * n;
            const auto expected = bin_of((x - mirrored).norm(), 0.01);
            if (!expected) continue;
            ++checked;
            const float* H = r.H.data() + (l * 16 + s) * std::size_t(r.bins);
            // Bin 0 may hold the spot itself (when it lies in s's cell): the hidden plane's light comes later.
            EXPECT_EQ(first_lit(H, 1, std::size_t(r.bins)), *expected) << "laser " << l << " sensor " << s;
        }
    EXPECT_GE(checked, 130);  // 138 of 144: the rest lie within 1e-4 m of a bin edge
}

TEST(Capture, ConfocalOnsetsAreTwiceTheDistanceToTheHiddenPlane) { check_confocal_onsets(false); }

TEST(Capture, ConfocalOnsetsAddTheDeviceLegsWhenAccounted) { check_confocal_onsets(true); }

// One small hidden patch (2 cm, one patch) above the wall, laser point l and sensor point s apart: the
// third bounce is albedo_l albedo_j albedo_s P A / pi^3 cos_l cos_j / r_l^2 cos_j' cos_s / r_s^2. The
// 2 x 2 samples integrate a kernel that varies by (a / r)^2 ~ 1e-3 across the patch: 1% holds easily.
TEST(Capture, ThirdBounceOfASmallPatchMatchesTheClosedForm) {
    const std::string capture = R"({"type": "exhaustive", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0.5, -1.5, 0.3]},
        "grid": {"origin": [-0.305, -0.005, 0], "u": [0.01, 0, 0], "v": [0, 0.01, 0], "nu": 1, "nv": 1},
        "sensor_grid": {"origin": [0.195, -0.005, 0], "u": [0.01, 0, 0], "v": [0, 0.01, 0], "nu": 1, "nv": 1},
        "max_bounces": 3})";
    const char* patch =
        R"({"type": "rectangle", "origin": [-0.01, -0.01, 0.5], "u": [0, 0.02, 0], "v": [0.02, 0, 0], "albedo": 0.5})";
    const Built b(scene_text(std::string(kWall) + "," + patch, capture, R"({"bins": 300, "bin_width": 0.01})"));
    const CaptureResult r = b.capture();
    ASSERT_EQ(r.pairs, 1u);
    double total = 0.0;
    for (float v : r.H) total += v;
    const double D = 0.5, rl2 = 0.3 * 0.3 + D * D, rs2 = 0.2 * 0.2 + D * D;
    const double expected = 0.8 * 0.5 * 0.8 * 1.0 * 0.02 * 0.02 / (M_PI * M_PI * M_PI) * (D * D / (rl2 * rl2)) *
                            (D * D / (rs2 * rs2));
    MEASURED("third bounce %.9g expected %.9g (%.2e)\n", total, expected, total / expected - 1);
    EXPECT_NEAR(total, expected, 0.01 * expected);
    // All of it near the path l -> patch -> s (the patch's samples span a few millimetres of path).
    const double path = std::sqrt(rl2) + std::sqrt(rs2);
    for (int t = 0; t < r.bins; ++t) {
        if (r.H[std::size_t(t)] == 0.0f) continue;
        EXPECT_NEAR((t + 0.5) * 0.01, path, 0.02) << "bin " << t;
    }
}

// A small glossy (then plastic) hidden patch between a laser point and a sensor point placed about its
// specular direction: its third bounce is the Lambertian one's with albedo / pi replaced by the BRDF
// between the directions to the two points, albedo_l P albedo_s A f(wi, wo) / pi^2 (cos cos / r^2) at
// each end. f written out here: GGX D, Smith G1, and for plastic the dielectric Fresnel F.
TEST(Capture, ThirdBounceOfASmallGlossyPatchMatchesTheClosedForm) {
    const std::string capture = R"({"type": "exhaustive", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0.5, -1.5, 0.3]},
        "grid": {"origin": [-0.305, -0.005, 0], "u": [0.01, 0, 0], "v": [0, 0.01, 0], "nu": 1, "nv": 1},
        "sensor_grid": {"origin": [0.245, -0.005, 0], "u": [0.01, 0, 0], "v": [0, 0.01, 0], "nu": 1, "nv": 1},
        "max_bounces": 3})";
    const double D = 0.5, a = 0.2, ior = 1.5;
    const Vec3 l(-0.3, 0, 0), s(0.25, 0, 0), x(0, 0, D), n(0, 0, -1);
    const Vec3 wi = (l - x).normalized(), wo = (s - x).normalized(), h = (wi + wo).normalized();
    const double ci = n.dot(wi), co = n.dot(wo), ch = n.dot(h);
    const auto g1 = [&](double c) { return 2.0 / (1.0 + std::sqrt(1.0 + a * a * (1.0 - c * c) / (c * c))); };
    const double t2 = (1.0 - ch * ch) / (ch * ch);
    const double lobe = a * a / (M_PI * std::pow(ch, 4) * std::pow(a * a + t2, 2)) * g1(ci) * g1(co) / (4.0 * ci * co);
    const auto fresnel = [&](double c) {
        const double ct = std::sqrt(1.0 - (1.0 - c * c) / (ior * ior));
        const double rs = (c - ior * ct) / (c + ior * ct), rp = (ior * c - ct) / (ior * c + ct);
        return 0.5 * (rs * rs + rp * rp);
    };
    const double glossy_f = 0.1 / M_PI + 0.7 * lobe;
    const double plastic_f = fresnel(wi.dot(h)) * lobe + (1.0 - fresnel(ci)) * (1.0 - fresnel(co)) * 0.5 / M_PI;
    const std::pair<const char*, double> materials[] = {
        {R"({"type": "glossy", "albedo": 0.1, "reflectance": 0.7, "roughness": 0.2})", glossy_f},
        {R"({"type": "plastic", "albedo": 0.5, "roughness": 0.2, "ior": 1.5})", plastic_f}};
    for (const auto& [material, f] : materials) {
        const std::string patch = R"({"type": "rectangle", "origin": [-0.01, -0.01, 0.5], "u": [0, 0.02, 0],
            "v": [0.02, 0, 0], "material": )" + std::string(material) + "}";
        const Built b(scene_text(std::string(kWall) + "," + patch, capture, R"({"bins": 300, "bin_width": 0.01})"));
        const CaptureResult r = b.capture();
        ASSERT_EQ(r.pairs, 1u);
        double total = 0.0;
        for (float v : r.H) total += v;
        const double rl2 = (l - x).squaredNorm(), rs2 = (s - x).squaredNorm();
        const double expected =
            0.8 * 1.0 * 0.8 * 0.02 * 0.02 * f / (M_PI * M_PI) * (D * D / (rl2 * rl2)) * (D * D / (rs2 * rs2));
        MEASURED("glossy third bounce %.9g expected %.9g (%.2e)\n", total, expected, total / expected - 1);
        EXPECT_NEAR(total, expected, 0.01 * expected) << material;
        // The lobe shows: the BRDF here is far from what the Lambertian part alone (albedo / pi) gives.
        const double lambertian = b.scene.objects[1].albedo[0] / M_PI;
        EXPECT_GT(std::abs(f - lambertian), 0.3 * f) << material;
    }
}

// The relay wall and a hidden corner in front of it (a tilted plane and a wall standing on it).
std::string corner_objects() {
    const char* plane =
        R"({"type": "rectangle", "origin": [-0.5, -0.5, 0.5], "u": [0, 1, 0], "v": [1, 0, 0.2], "albedo": 0.6})";
    const char* side =
        R"({"type": "rectangle", "origin": [-0.5, 0.5, 0.1], "u": [1, 0, 0], "v": [0, 0, 0.5], "albedo": 0.7})";
    return std::string(kWall) + "," + plane + "," + side;
}

// The hidden corner scanned exhaustively, every bounce marched.
std::string corner_scene(const std::string& extra_capture = "",
                         const std::string& time = R"({"bins": 150, "bin_width": 0.02})",
                         const std::string& links = R"({"method": "flat"})") {
    const std::string capture = R"({"type": "exhaustive", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]},
        "grid": {"origin": [-0.4, -0.4, 0], "u": [0.8, 0, 0], "v": [0, 0.8, 0], "nu": 3, "nv": 3})" +
                                extra_capture + "}";
    return scene_text(corner_objects(), capture, time, 0.1, links);
}

// Helmholtz reciprocity: with the laser and the sensor at one position and one grid, H[l, s] = H[s, l] at
// every bin. The exact bounces are sums of the same sample products; the marched ones exchange identical
// pieces (flat links are reciprocal, A_i F_ij = A_j F_ji, and so are cluster links through push and pull,
// A_R F_RS = A_S F_SR); what differs is float rounding and the same-bin iteration's stopping point (1e-7
// of the largest value): 1e-6 of the largest off-diagonal value.
void expect_reciprocal(const std::string& links) {
    SCOPED_TRACE(links);
    const Built b(corner_scene("", R"({"bins": 150, "bin_width": 0.02})", links));
    if (b.scene.links.method == LinkMethod::Hierarchical) {
        ASSERT_GT(b.links.cluster_links(), 0u);
    }
    const CaptureResult r = b.capture();
    ASSERT_TRUE(r.solved);
    const std::size_t n = 9, T = std::size_t(r.bins);
    ASSERT_EQ(r.pairs, n * n);
    double largest = 0.0;
    for (std::size_t l = 0; l < n; ++l)
        for (std::size_t s = 0; s < n; ++s)
            if (l != s)
                for (std::size_t t = 0; t < T; ++t) largest = std::max(largest, double(r.H[(l * n + s) * T + t]));
    ASSERT_GT(largest, 0.0);
    double worst = 0.0;
    for (std::size_t l = 0; l < n; ++l)
        for (std::size_t s = l + 1; s < n; ++s)
            for (std::size_t t = 0; t < T; ++t)
                worst = std::max(worst, std::abs(double(r.H[(l * n + s) * T + t]) - double(r.H[(s * n + l) * T + t])));
    MEASURED("reciprocity (%s): worst %.3g of largest %.3g\n", links.c_str(), worst, largest);
    EXPECT_LE(worst, 1e-6 * largest);
}

// Flat links, then hierarchical ones (the default).
TEST(Capture, ExhaustiveCapturesAreReciprocal) {
    expect_reciprocal(R"({"method": "flat"})");
    expect_reciprocal(R"({"method": "hierarchical", "tolerance": 0.01})");
}

// The later bounces matter (the hidden corner sends light between its faces) and a batch of
// illuminations gives what one march per illumination gives.
TEST(Capture, BatchedMarchesMatchSingleOnes) {
    const Built b(corner_scene());
    const CaptureResult batched = b.capture(0), single = b.capture(1);
    EXPECT_EQ(single.marches, 9);
    EXPECT_LT(batched.marches, 9);
    double largest = 0.0, worst = 0.0;
    for (std::size_t k = 0; k < batched.H.size(); ++k) {
        largest = std::max(largest, double(single.H[k]));
        worst = std::max(worst, std::abs(double(batched.H[k]) - double(single.H[k])));
    }
    EXPECT_LE(worst, 1e-6 * largest);
    // Bounces beyond the third add light after the third bounce's onset.
    const Built third(corner_scene(R"(, "max_bounces": 3)"));
    const CaptureResult r3 = third.capture();
    double all = 0.0, only3 = 0.0;
    for (std::size_t k = 0; k < r3.H.size(); ++k) {
        all += batched.H[k];
        only3 += r3.H[k];
    }
    EXPECT_GT(all, only3 * 1.001);
}

// A march on wider bins (march_bin_factor F) marches the same light: each link splits its delay between
// two of its bins so that the mean delay is kept, and each march bin is spread back over the scene's
// bins by a hat that keeps its light and its mean path. So, per pair of points, the light of the later
// bounces (every bounce less the first three, which do not march) and its mean path are those of the
// march on the scene's bins, to float rounding, while its shape is blurred over about F bins. A window
// that ends before the later bounces do would cut the two marches' light differently: 12 m holds them.
TEST(Capture, AWiderMarchKeepsTheLightAndMeanPathOfLaterBounces) {
    const std::string time = R"({"bins": 600, "bin_width": 0.02})";
    const CaptureResult first3 = Built(corner_scene(R"(, "max_bounces": 3)", time)).capture();
    const CaptureResult fine = Built(corner_scene("", time)).capture();
    const std::size_t T = 600, pairs = fine.H.size() / T;
    ASSERT_EQ(first3.H.size(), fine.H.size());
    // The later bounces' light per pair, and its sum of bin x light.
    const auto later = [&](const CaptureResult& r, std::size_t q, double& light, double& moment, double& tail) {
        light = moment = tail = 0.0;
        for (std::size_t t = 0; t < T; ++t) {
            const double v = double(r.H[q * T + t]) - double(first3.H[q * T + t]);
            light += v;
            moment += v * double(t);
            if (t >= T - 20) tail += std::abs(v);
        }
    };
    for (const int F : {4, 8}) {
        SCOPED_TRACE("march_bin_factor " + std::to_string(F));
        const Built wide(corner_scene(R"(, "march_bin_factor": )" + std::to_string(F), time));
        EXPECT_EQ(march_time(wide.scene).bins, 600 / F + 1);
        const CaptureResult r = wide.capture();
        ASSERT_EQ(r.H.size(), fine.H.size());
        double worst_light = 0.0, worst_mean = 0.0, blur = 0.0, total = 0.0;
        for (std::size_t q = 0; q < pairs; ++q) {
            double a = 0, ma = 0, ta = 0, b = 0, mb = 0, tb = 0;
            later(fine, q, a, ma, ta);
            later(r, q, b, mb, tb);
            ASSERT_GT(a, 0.0);
            ASSERT_LT(ta, 1e-5 * a) << ta / a;  // the window holds the later bounces
            worst_light = std::max(worst_light, std::abs(b - a) / a);
            worst_mean = std::max(worst_mean, std::abs(mb / b - ma / a));
            for (std::size_t t = 0; t < T; ++t)
                blur += std::abs(double(r.H[q * T + t]) - double(fine.H[q * T + t]));
            total += a;
        }
        EXPECT_LT(worst_light, 1e-5);
        EXPECT_LT(worst_mean, 1e-3) << "bins";  // of 2 cm
        // Not a bound the physics fixes, a check that the blur is a blur: its L1 is a fraction of the light.
        EXPECT_GT(blur, 0.0);
        EXPECT_LT(blur, 0.5 * total);
        std::printf("F %d: later light %.2e, mean path %.2e bins, blur L1 %.3f of the later light\n", F, worst_light,
                    worst_mean, blur / total);
    }
}

// march_grid_step S marches the later bounces at every S-th grid point (and the last) along each side
// and moves their light to the points in between. Fixed in advance: a marched point holds what the full
// march gives it (its own march, in another batch: to rounding). Every other point's later light is its
// four lattice neighbours' moved by the change of the first and last legs, right to first order in the
// lattice's spacing h, so its error against the point's own march falls about in proportion to h (what
// it leaves out, the change of the later light among the patches, is itself first order). A plain
// bilinear blend of the same neighbours' light (the blend the march had before, computed here from the
// full march) holds two copies of a peak where one moved copy belongs: at the same lattice the moved
// light must beat it severalfold, and keep each point's later light within a few percent. Run as NLOS
// users scan (no device legs) and with the device legs accounted, the laser and the sensor apart (their
// legs change differently from point to point: the moves must take the laser's first leg and the
// sensor's last).
struct LatticeErrors {
    double marched = 0.0;             // worst |moved - full| at a marched point, of the largest later light
    double light = 0.0;               // worst |later light moved - own| / own at the other points
    double mean = 0.0, blend_mean = 0.0;  // worst |mean path - own|, bins (printed: both are second order)
    double l1 = 0.0, blend_l1 = 0.0;  // sum |profile - own| / sum own over the other points
};

// The hidden corner scanned confocally at 9 x 9 points 4.4 cm apart, 150 bins of 4 cm from `start`
// metres (6 m: the later light's tail is inside); `extra` goes into the capture block.
CaptureResult lattice_scan(const std::string& extra, double start, const std::string& objects = corner_objects(),
                           const std::string& links = R"({"method": "flat"})") {
    const std::string confocal = R"({"type": "confocal",
        "grid": {"origin": [-0.2, -0.2, 0], "u": [0.4, 0, 0], "v": [0, 0.4, 0], "nu": 9, "nv": 9})";
    const std::string time = R"({"bins": 150, "bin_width": 0.04, "start": )" + std::to_string(start) + "}";
    return Built(scene_text(objects, confocal + ", " + extra + "}", time, 0.1, links)).capture();
}

// `first3` and `full`: the scan's first three orders, and every order marched at every point; `moved`:
// every order, marched at the lattice of every `step`-th point.
LatticeErrors lattice_errors(const CaptureResult& first3, const CaptureResult& full, const CaptureResult& moved,
                             int step) {
    const std::size_t T = 150, n = 9;
    EXPECT_EQ(full.H.size(), n * n * T);
    EXPECT_EQ(moved.H.size(), full.H.size());
    const auto later = [&](const CaptureResult& r, std::size_t l, std::size_t t) {
        return double(r.H[l * T + t]) - double(first3.H[l * T + t]);
    };
    double largest = 0.0;
    for (std::size_t l = 0; l < n * n; ++l)
        for (std::size_t t = 0; t < T; ++t) largest = std::max(largest, later(full, l, t));
    LatticeErrors e;
    double own_light = 0.0;
    const std::size_t S = std::size_t(step);
    for (std::size_t a = 0; a < n; ++a)
        for (std::size_t b = 0; b < n; ++b) {
            const std::size_t l = a * n + b;
            const std::size_t a0 = a / S * S, a1 = std::min(a0 + S, n - 1), b0 = b / S * S, b1 = std::min(b0 + S, n - 1);
            if (a == a0 && b == b0) {
                for (std::size_t t = 0; t < T; ++t)
                    e.marched = std::max(e.marched, std::abs(later(moved, l, t) - later(full, l, t)));
                continue;
            }
            const double wa = a1 > a0 ? double(a - a0) / double(a1 - a0) : 0.0;
            const double wb = b1 > b0 ? double(b - b0) / double(b1 - b0) : 0.0;
            double light = 0.0, moved_light = 0.0, blend_light = 0.0, moment = 0.0, moved_moment = 0.0,
                   blend_moment = 0.0;
            for (std::size_t t = 0; t < T; ++t) {
                double blend = 0.0;
                for (std::size_t ca : {a0, a1})
                    for (std::size_t cb : {b0, b1})
                        blend += (ca == a0 ? 1.0 - wa : wa) * (cb == b0 ? 1.0 - wb : wb) * later(full, ca * n + cb, t);
                light += later(full, l, t);
                moved_light += later(moved, l, t);
                blend_light += blend;
                moment += double(t) * later(full, l, t);
                moved_moment += double(t) * later(moved, l, t);
                blend_moment += double(t) * blend;
                e.l1 += std::abs(later(moved, l, t) - later(full, l, t));
                e.blend_l1 += std::abs(blend - later(full, l, t));
            }
            EXPECT_GT(light, 0.0);
            own_light += light;
            e.light = std::max(e.light, std::abs(moved_light - light) / light);
            e.mean = std::max(e.mean, std::abs(moved_moment / moved_light - moment / light));
            e.blend_mean = std::max(e.blend_mean, std::abs(blend_moment / blend_light - moment / light));
        }
    e.marched /= largest;
    e.l1 /= own_light;
    e.blend_l1 /= own_light;
    std::printf("lattice step %d (%.1f cm): marched points %.1e, later light %.2e, mean %.3f bins, L1 %.4f (bilinear "
                "blend: mean %.3f bins, L1 %.4f)\n",
                step, 40.0 / 9.0 * step, e.marched, e.light, e.mean, e.l1, e.blend_mean, e.blend_l1);
    return e;
}

// `devices`: the capture's laser, sensor and device-leg keys.
void expect_lattice_moves(const std::string& devices, double start) {
    SCOPED_TRACE(devices);
    const CaptureResult first3 = lattice_scan(devices + R"(, "max_bounces": 3)", start);
    const CaptureResult full = lattice_scan(devices, start);
    const auto errors = [&](int step) {
        return lattice_errors(first3, full, lattice_scan(devices + R"(, "march_grid_step": )" + std::to_string(step), start),
                              step);
    };
    const LatticeErrors fine = errors(2), coarse = errors(4);
    for (const LatticeErrors& e : {fine, coarse}) {
        EXPECT_LE(e.marched, 1e-5);
        EXPECT_LT(e.l1, e.blend_l1 / 3.0);
        EXPECT_LT(e.light, 0.03);
    }
    EXPECT_LT(fine.l1, 0.55 * coarse.l1);
    EXPECT_LT(fine.light, 0.55 * coarse.light);
}

TEST(Capture, AMarchedLatticeGivesItsPointsTheirOwnLightAndMovesItToTheOthers) {
    expect_lattice_moves(R"("laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, -1.5, 0.3]})", 0.0);
    expect_lattice_moves(R"("laser": {"position": [-0.8, -1.4, 0.35]}, "sensor": {"position": [0.9, -1.3, 0.2]},
        "account_first_and_last_bounces": true)", 3.2);  // the device legs: about 3.2 m
}

// The same corner with its plane a rough metal passing its light on through glossy cells (R = 3): the
// marched points hold their own march's light (to rounding), and the others their lattice neighbours'
// light moved as above, a glossy patch's out-cell light moved with the patch (the change of its lobe
// between the points is left out), so that the moved light beats the bilinear blend as the Lambertian
// corner's does and each point's later light stays within a few percent.
TEST(Capture, AMarchedLatticeMovesAGlossyCornersLaterLight) {
    const std::string devices = R"("laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, -1.5, 0.3]})";
    const std::string plane = R"({"type": "rectangle", "origin": [-0.5, -0.5, 0.5], "u": [0, 1, 0], "v": [1, 0, 0.2],
        "albedo": 0.2, "material": {"type": "glossy", "reflectance": 0.6, "roughness": 0.3}})";
    const std::string side =
        R"({"type": "rectangle", "origin": [-0.5, 0.5, 0.1], "u": [1, 0, 0], "v": [0, 0, 0.5], "albedo": 0.7})";
    const std::string objects = std::string(kWall) + "," + plane + "," + side;
    const std::string links = R"({"method": "flat", "glossy_resolution": 3})";
    const CaptureResult first3 = lattice_scan(devices + R"(, "max_bounces": 3)", 0.0, objects, links);
    const CaptureResult full = lattice_scan(devices, 0.0, objects, links);
    const LatticeErrors e =
        lattice_errors(first3, full, lattice_scan(devices + R"(, "march_grid_step": 2)", 0.0, objects, links), 2);
    EXPECT_LE(e.marched, 1e-5);
    EXPECT_LT(e.l1, e.blend_l1 / 3.0);
    EXPECT_LT(e.light, 0.03);
}

// A window that starts late keeps the marched light that left the patches before it began and reaches
// the sensor points inside it: bin for bin what the same bins of a window from 0 hold.
void expect_late_window_as_early(const std::string& extra) {
    const std::size_t T = 150, offset = 40;  // 0.8 m: after most third bounces have left their patches
    const CaptureResult early = Built(corner_scene(extra)).capture();
    const CaptureResult late =
        Built(corner_scene(extra, R"({"bins": 110, "bin_width": 0.02, "start": 0.8})")).capture();
    const std::size_t pairs = early.H.size() / T;
    ASSERT_EQ(late.H.size(), pairs * (T - offset));
    double largest = 0.0, worst = 0.0, total = 0.0;
    for (std::size_t q = 0; q < pairs; ++q)
        for (std::size_t t = 0; t + offset < T; ++t) {
            const double a = early.H[q * T + t + offset], b = late.H[q * (T - offset) + t];
            largest = std::max(largest, a);
            worst = std::max(worst, std::abs(a - b));
            total += b;
        }
    EXPECT_GT(total, 0.0);
    EXPECT_LE(worst, 1e-6 * largest) << "largest difference " << worst << " of " << largest;
}

// So does a march on wider bins (whose bins, 8 cm, start at both windows' starts alike).
TEST(Capture, ALateWindowHoldsWhatTheSameBinsOfAnEarlyOneHold) {
    for (const std::string& extra : {std::string(), std::string(R"(, "march_bin_factor": 4)")}) {
        SCOPED_TRACE(extra);
        expect_late_window_as_early(extra);
    }
}

// The capture of a scene that needs no march (max_bounces 3), mirrors and glass included.
std::vector<float> capture_h(const std::string& text) {
    const Scene scene = parse_scene(text, "specular_capture.json");
    const PatchSet patches = build_patches(scene);
    const std::unique_ptr<Visibility> visibility = scene_visibility(scene, patches);
    return compute_capture(scene, patches, *visibility, nullptr, {}).H;
}

// A mirror perpendicular to the relay wall (the wall's image is coplanar with it, so the wall never sees
// itself in it) and a plane in front of it: the first three bounces are those of the unfolded scene,
// where the mirror is replaced by the plane's mirror image, to float precision.
TEST(Capture, ThroughAMirrorTheFirstBouncesAreThoseOfTheUnfoldedScene) {
    const std::string capture = R"({"type": "confocal", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]}, "grid": {"origin": [-0.6, -0.6, 0], "u": [1.2, 0, 0],
        "v": [0, 1.2, 0], "nu": 6, "nv": 6}, "max_bounces": 3})";
    const std::string plane =
        R"({"type": "rectangle", "origin": [0.5, -0.3, 0.5], "u": [0, 0.6, 0], "v": [0.2, 0, 0.4], "albedo": 0.6})";
    const std::string mirror = R"({"type": "rectangle", "origin": [1, -1.5, 0.2], "u": [0, 0, 1.8], "v": [0, 3, 0],
        "material": {"type": "mirror", "reflectance": 1}})";
    const std::string image =  // the plane reflected across x = 1 (u and v swapped keep its front)
        R"({"type": "rectangle", "origin": [1.5, -0.3, 0.5], "u": [-0.2, 0, 0.4], "v": [0, 0.6, 0], "albedo": 0.6})";
    const std::string time = R"({"bins": 500, "bin_width": 0.01})";
    const auto capture_of = [&](const std::string& objects) { return capture_h(scene_text(objects, capture, time, 0.1)); };
    const std::vector<float> with_mirror = capture_of(std::string(kWall) + "," + plane + "," + mirror);
    const std::vector<float> unfolded = capture_of(std::string(kWall) + "," + plane + "," + image);
    const std::vector<float> plane_only = capture_of(std::string(kWall) + "," + plane);
    ASSERT_EQ(with_mirror.size(), unfolded.size());
    ASSERT_EQ(plane_only.size(), unfolded.size());
    double largest = 0.0, worst = 0.0, total = 0.0, straight = 0.0;
    for (std::size_t k = 0; k < unfolded.size(); ++k) {
        largest = std::max(largest, double(unfolded[k]));
        worst = std::max(worst, std::abs(double(with_mirror[k]) - double(unfolded[k])));
        if (k % 500 == 0) continue;  // the spot itself (bin 0 of every point's row)
        total += with_mirror[k];
        straight += plane_only[k];
    }
    MEASURED("capture through a mirror vs unfolded: %.3g of the largest; after the spot, %.4g with the mirror, %.4g without\n",
             worst / largest, total, straight);
    EXPECT_LE(worst, 1e-4 * largest);
    EXPECT_GT(total, 2.0 * straight);  // the mirror's light is there, not only the plane's own
}

// A sheet of glass that reflects nothing between the relay wall and the hidden plane: the third bounce
// crosses it twice, so everything after the spot is Tr^2 of the capture without it (every view, the
// small far patches' one-ray views included).
TEST(Capture, GlassBetweenTheWallAndTheHiddenPlanePassesTransmittanceSquared) {
    const std::string capture = R"({"type": "confocal", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]}, "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0],
        "v": [0, 1, 0], "nu": 4, "nv": 4}, "max_bounces": 3})";
    // From y = -0.8 on: every wall-to-plane path crosses it (at y >= -0.75), no device leg does (y <= -0.875);
    // inside the scene's bounds, so that the ray offsets (a share of the scene's size) stay the same.
    const std::string glass = R"({"type": "rectangle", "origin": [-1, -0.8, 0.2], "u": [2, 0, 0], "v": [0, 1.8, 0],
        "material": {"type": "glass", "reflectance": 0, "transmittance": 0.5}})";
    const std::string time = R"({"bins": 400, "bin_width": 0.01})";
    const auto capture_of = [&](const std::string& objects) { return capture_h(scene_text(objects, capture, time, 0.1)); };
    const std::vector<float> clear = capture_of(std::string(kWall) + "," + kTiltedPlane);
    const std::vector<float> behind = capture_of(std::string(kWall) + "," + kTiltedPlane + "," + glass);
    ASSERT_EQ(clear.size(), behind.size());
    double largest = 0.0, worst = 0.0;
    for (std::size_t k = 0; k < clear.size(); ++k) {
        if (k % 400 == 0) continue;  // the spot itself
        largest = std::max(largest, double(clear[k]));
        worst = std::max(worst, std::abs(double(behind[k]) - 0.25 * double(clear[k])));
    }
    ASSERT_GT(largest, 0.0);
    EXPECT_LE(worst, 1e-5 * largest) << "largest difference " << worst << " of " << largest;
}

// A tinted mirror and a tinted hidden plane: a capture is the mean of its three channels, each of which
// is the capture of the scene in that channel's grey values (reflectance and albedo), so the tinted
// capture is the mean of the three grey captures. Taking the tint as its mean reflectance would pair
// the plane's red with the mirror's mean instead of its red: off by about the spread checked below.
TEST(Capture, ATintedMirrorGivesTheMeanOfItsChannelsGreyCaptures) {
    const std::string capture = R"({"type": "confocal", "laser": {"position": [0, -1.5, 0.3]},
        "sensor": {"position": [0, -1.5, 0.3]}, "grid": {"origin": [-0.6, -0.6, 0], "u": [1.2, 0, 0],
        "v": [0, 1.2, 0], "nu": 4, "nv": 4}, "max_bounces": 3})";
    const std::string time = R"({"bins": 500, "bin_width": 0.01})";
    const auto value = [](const std::array<double, 3>& v, int c) {
        char text[96];
        if (c < 0) std::snprintf(text, sizeof text, "[%.17g, %.17g, %.17g]", v[0], v[1], v[2]);
        else std::snprintf(text, sizeof text, "%.17g", v[std::size_t(c)]);
        return std::string(text);
    };
    const std::array<double, 3> albedo{0.2, 0.5, 0.8}, reflectance{0.9, 0.55, 0.2};
    // c < 0: tinted; else channel c's grey values.
    const auto capture_of = [&](int c) {
        const std::string plane = R"({"type": "rectangle", "origin": [0.5, -0.3, 0.5], "u": [0, 0.6, 0],
            "v": [0.2, 0, 0.4], "albedo": )" + value(albedo, c) + "}";
        const std::string mirror = R"({"type": "rectangle", "origin": [1, -1.5, 0.2], "u": [0, 0, 1.8],
            "v": [0, 3, 0], "material": {"type": "mirror", "reflectance": )" + value(reflectance, c) + "}}";
        return capture_h(scene_text(std::string(kWall) + "," + plane + "," + mirror, capture, time, 0.1));
    };
    const std::vector<float> tinted = capture_of(-1), r = capture_of(0), g = capture_of(1), b = capture_of(2);
    ASSERT_EQ(tinted.size(), r.size());
    double largest = 0.0, worst = 0.0, spread = 0.0;
    for (std::size_t k = 0; k < tinted.size(); ++k) {
        if (k % 500 == 0) continue;  // the spot itself
        const double mean = (double(r[k]) + double(g[k]) + double(b[k])) / 3.0;
        largest = std::max(largest, mean);
        worst = std::max(worst, std::abs(double(tinted[k]) - mean));
        spread = std::max(spread, std::abs(double(r[k]) - double(b[k])));
    }
    MEASURED("tinted capture vs the mean of the grey ones: %.3g of the largest (red vs blue: %.3g)\n",
             worst / largest, spread / largest);
    ASSERT_GT(largest, 0.0);
    EXPECT_LE(worst, 1e-5 * largest);
    EXPECT_GT(spread, 0.1 * largest);
}

// Bad capture blocks: one line naming the file and the JSON path, exit status 2, nothing written.
class CaptureCli : public ::testing::Test {
protected:
    void SetUp() override {
        m_dir = fs::temp_directory_path() / ("tprf_capture_" + std::to_string(std::random_device{}()));
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }
    std::string scene(const std::string& capture, const std::string& objects = std::string(kWall) + "," +
                                                                               kTiltedPlane) {
        const fs::path file = m_dir / "scene.json";
        std::ofstream(file) << scene_text(objects, capture, R"({"bins": 100, "bin_width": 0.02})", 0.2);
        return file.string();
    }
    void expect_refused(const std::string& capture, const std::string& path, const std::string& words) {
        const test::Outcome o = test::run_tprf("render " + scene(capture) + " -o " + (m_dir / "out").string());
        EXPECT_EQ(o.status, 2) << o.err;
        EXPECT_NE(o.err.find("scene.json: " + path + ": "), std::string::npos) << o.err;
        EXPECT_NE(o.err.find(words), std::string::npos) << o.err;
        EXPECT_FALSE(fs::exists(m_dir / "out" / "capture.hdf5"));
        // info checks what render checks before its links (the capture's points on the wall too).
        const test::Outcome i = test::run_tprf("info " + scene(capture));
        EXPECT_EQ(i.status, 2) << i.err;
        EXPECT_EQ(i.err, o.err);
    }
    fs::path m_dir;
};

const std::string kDevices = R"("laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, -1.5, 0.3]})";

TEST_F(CaptureCli, GridPointOffEverySurfaceIsRefused) {
    expect_refused(R"({)" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0.2], "u": [1, 0, 0], "v": [0, 1, 0],
        "nu": 4, "nv": 4}})", "capture.grid", "lies on no surface");
}

// A grid point exactly on a corner that four wall patches share (found refused by a single ray).
TEST(Capture, GridPointOnAPatchCornerIsOnTheWall) {
    const Built b(scene_text(kWall, R"({"laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, -1.5, 0.3]},
        "grid": {"origin": [-0.65, 0.55, 0], "u": [0.1, 0, 0], "v": [0, 0.1, 0], "nu": 1, "nv": 1},
        "max_bounces": 3})", R"({"bins": 100, "bin_width": 0.02})", 0.1));
    const CaptureResult r = b.capture();
    ASSERT_EQ(r.points.sensor.size(), 1u);
    EXPECT_LT((r.points.sensor[0].point - Vec3(-0.6, 0.6, 0)).norm(), 1e-12);
}

// `tprf sensor --cube capture` with a SPAD: its histograms per scan point, and a capture.hdf5 that is the
// render's with H the counts (one detector: the first channel's).
TEST_F(CaptureCli, ASpadOnACaptureWritesANoisyCaptureFile) {
    const std::string file = scene(R"({)" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0],
        "v": [0, 1, 0], "nu": 3, "nv": 2}, "max_bounces": 3})");
    const fs::path out = m_dir / "out";
    ASSERT_EQ(test::run_tprf("render " + file + " -o " + out.string()).status, 0);
    std::ofstream(m_dir / "spad.json") << R"({"exposure": {"type": "spad", "photons": 1e6, "seed": 5}})";
    const test::Outcome r = test::run_tprf("sensor " + out.string() + " " + (m_dir / "spad.json").string() +
                                           " --cube capture --name noisy");
    ASSERT_EQ(r.status, 0) << r.err;
    const NpyArray counts = read_npy(out / "sensor-noisy" / "measurements.npy");
    ASSERT_EQ(counts.shape, (std::vector<std::size_t>{3, 2, 100, 3}));  // the scan points as rows of pixels
    const NpyArray clean = read_npy(out / "capture.npy");
    ASSERT_EQ(clean.shape, (std::vector<std::size_t>{100, 3, 2}));
    const H5::H5File noisy((out / "sensor-noisy" / "capture.hdf5").string(), H5F_ACC_RDONLY);
    const H5::DataSet h = noisy.openDataSet("H");
    std::vector<float> H(100 * 6);
    h.read(H.data(), H5::PredType::NATIVE_FLOAT);
    double total = 0.0, expected = 0.0;
    for (std::size_t t = 0; t < 100; ++t)
        for (std::size_t p = 0; p < 6; ++p) {
            EXPECT_EQ(H[t * 6 + p], counts.data[(p * 100 + t) * 3]) << t << " " << p;
            EXPECT_EQ(H[t * 6 + p], std::round(H[t * 6 + p]));  // photon counts
            total += H[t * 6 + p];
            expected += 1e6 * clean.data[t * 6 + p];
        }
    MEASURED("noisy capture: %.0f counts where photons x H gives %.0f\n", total, expected);
    EXPECT_NEAR(total, expected, 5.0 * std::sqrt(expected));
    // A gated sensor's measurements are no histogram: no capture file.
    std::ofstream(m_dir / "gates.json") << R"({"exposure": {"type": "gates", "start": 0, "width": 0.5, "step": 0.5, "count": 3}})";
    ASSERT_EQ(test::run_tprf("sensor " + out.string() + " " + (m_dir / "gates.json").string() + " --cube capture").status, 0);
    EXPECT_TRUE(fs::exists(out / "sensor-gates" / "measurements.npy"));
    EXPECT_FALSE(fs::exists(out / "sensor-gates" / "capture.hdf5"));
}

TEST_F(CaptureCli, ZeroPointsAlongAGridSideIsRefused) {
    expect_refused(R"({)" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0], "v": [0, 1, 0],
        "nu": 0, "nv": 4}})", "capture.grid.nu", "must be > 0");
}

TEST_F(CaptureCli, MarchBinFactorOutOfRangeIsRefused) {
    const std::string grid = R"("grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0], "v": [0, 1, 0], "nu": 4, "nv": 4})";
    for (const char* factor : {"0", "65"})
        expect_refused(R"({)" + kDevices + ", " + grid + R"(, "march_bin_factor": )" + factor + "}",
                       "capture.march_bin_factor", "must be an integer in [1, 64]");
}

// A camera's light is marched on the scene's bins, with the same links as the capture's.
TEST_F(CaptureCli, WiderMarchWithACameraIsRefused) {
    const std::string file = scene(R"({)" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0],
        "v": [0, 1, 0], "nu": 4, "nv": 4}, "march_bin_factor": 4})");
    std::ifstream in(file);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.insert(1, R"("camera": {"position": [0, -1.5, 0.3], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov": 40, "width": 8,
        "height": 8}, )");
    std::ofstream(file) << text;
    const test::Outcome o = test::run_tprf("render " + file + " -o " + (m_dir / "out").string());
    EXPECT_EQ(o.status, 2) << o.err;
    EXPECT_NE(o.err.find("scene.json: capture.march_bin_factor: must be 1 in a scene with a camera"), std::string::npos)
        << o.err;
    EXPECT_FALSE(fs::exists(m_dir / "out"));
}

TEST_F(CaptureCli, MarchGridStepOfAnExhaustiveCaptureIsRefused) {
    expect_refused(R"({"type": "exhaustive", )" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0],
        "v": [0, 1, 0], "nu": 4, "nv": 4}, "march_grid_step": 2})",
                   "capture.march_grid_step", "must be 1 for an exhaustive capture");
}

TEST_F(CaptureCli, ExhaustiveWithoutGridsIsRefused) {
    expect_refused(R"({"type": "exhaustive", )" + kDevices + "}", "capture", "needs \"grid\"");
}

TEST_F(CaptureCli, DeviceBehindAnObjectIsRefused) {
    // Above the hidden plane, whose front faces the wall: the laser meets its back first.
    expect_refused(R"({"laser": {"position": [0, 0, 2]}, "sensor": {"position": [0, -1.5, 0.3]},
        "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0], "v": [0, 1, 0], "nu": 4, "nv": 4}})",
                   "capture.laser.position", "is inside or behind objects[1]");
}

TEST_F(CaptureCli, DeviceBehindTheWallIsRefused) {
    expect_refused(R"({"laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, 0, -1]},
        "grid": {"origin": [-0.5, -0.5, 0], "u": [1, 0, 0], "v": [0, 1, 0], "nu": 4, "nv": 4}})",
                   "capture.sensor.position", "is behind objects[0]");
}

TEST_F(CaptureCli, FramesNeedACamera) {
    const test::Outcome o = test::run_tprf("render " + scene(R"({)" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0],
        "u": [1, 0, 0], "v": [0, 1, 0], "nu": 4, "nv": 4}})") + " -o " + (m_dir / "out").string() + " --frames");
    EXPECT_EQ(o.status, 2) << o.err;
    EXPECT_NE(o.err.find("--frames needs a camera"), std::string::npos) << o.err;
}

// A capture-only render writes capture.hdf5, capture.npy and render.json, and no camera outputs.
TEST_F(CaptureCli, RenderWritesTheCaptureFiles) {
    const fs::path out = m_dir / "out";
    const test::Outcome o = test::run_tprf("render " + scene(R"({)" + kDevices + R"(, "grid": {"origin": [-0.5, -0.5, 0],
        "u": [1, 0, 0], "v": [0, 1, 0], "nu": 4, "nv": 2}, "max_bounces": 3})") + " -o " + out.string());
    ASSERT_EQ(o.status, 0) << o.err;
    EXPECT_TRUE(fs::exists(out / "capture.hdf5"));
    EXPECT_TRUE(fs::exists(out / "render.json"));
    EXPECT_FALSE(fs::exists(out / "transient.npy"));
    const std::string npy = test::read_bytes(out / "capture.npy");
    EXPECT_NE(npy.find("'shape': (100, 4, 2)"), std::string::npos);
    EXPECT_NE(npy.find("'descr': '<f4'"), std::string::npos);
    ASSERT_GT(npy.size(), 10u);
    const std::size_t header = 10 + std::size_t(std::uint8_t(npy[8])) + 256 * std::size_t(std::uint8_t(npy[9]));
    EXPECT_EQ(npy.size(), header + 100 * 4 * 2 * sizeof(float));
}

}  // namespace
}  // namespace tprf
