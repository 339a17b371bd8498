// The TPRF sensor model: gates sum what arrives inside them, a pulse keeps energy and mean arrival,
// noise and photon counts have the statistics they claim, and a CW-ToF camera recovers geometry
// (and its multipath error) from a render.
#include "tprf/imaging/sensor_model.h"

#include "tprf/imaging/camera.h"
#include "tprf/core/error.h"
#include "tprf/core/random.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"

#include <nlohmann/json.hpp>
#include "tprf/io/npy.h"
#include "tprf/geometry/patches.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"
#include "tprf/geometry/visibility.h"

#include "test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <functional>
#include <numeric>
#include <random>
#include <string>
#include <vector>

namespace tprf {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

SensorSettings sensor_from(const json& block) {
    static const fs::path file = "test.json";
    return parse_sensor_block(block.dump(), file);
}

using test::time_axis;

// A cube (H, W, T, 3) of independent uniform values in [0, 1).
std::vector<float> random_cube(int h, int w, int t, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<float> cube(std::size_t(h * w * t * 3));
    for (float& v : cube) v = u(rng);
    return cube;
}

std::vector<float> measure(const SensorSettings& s, const TimeAxis& time, const std::vector<float>& cube, int h, int w,
                           std::vector<float>* depth = nullptr, int threads = 0) {
    std::vector<float> m(std::size_t(h * w * measurement_count(s, time) * 3));
    if (depth) depth->resize(std::size_t(h * w));
    SensorOptions o;
    o.threads = threads;
    apply_sensor(s, {time, cube.data(), h, w}, m.data(), depth ? depth->data() : nullptr, o);
    return m;
}

TEST(Sensor, DeltaPulseGatesSumTheBinsInsideEachGate) {
    const int H = 2, W = 3, T = 50;
    const TimeAxis time = time_axis(T, 0.01, 0.1);
    const std::vector<float> cube = random_cube(H, W, T, 1);
    // Gates aligned with bins: gate k covers bins 3 + 5k .. 7 + 5k.
    const SensorSettings s = sensor_from(
        {{"exposure", {{"type", "gates"}, {"start", 0.13}, {"width", 0.05}, {"step", 0.05}, {"count", 8}}}});
    const std::vector<float> m = measure(s, time, cube, H, W);
    for (int p = 0; p < H * W; ++p)
        for (int k = 0; k < 8; ++k)
            for (int c = 0; c < 3; ++c) {
                double sum = 0.0;
                for (int i = 3 + 5 * k; i < 8 + 5 * k; ++i) sum += cube[std::size_t((p * T + i) * 3 + c)];
                // float inputs, double sums: agreement to float rounding of the result.
                EXPECT_NEAR(m[std::size_t((p * 8 + k) * 3 + c)], sum, 1e-5 * sum) << "pixel " << p << " gate " << k;
            }
}

TEST(Sensor, PartialBinsAtWindowEdgesAreWeightedByOverlap) {
    const int T = 20;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube = random_cube(1, 1, T, 2);
    // [0.035, 0.0725): half of bin 3, bins 4..6, a quarter of bin 7.
    const SensorSettings s = sensor_from({{"exposure", {{"type", "windows"}, {"windows", {{0.035, 0.0375}}}}}});
    const std::vector<float> m = measure(s, time, cube, 1, 1);
    for (int c = 0; c < 3; ++c) {
        auto e = [&](int i) { return double(cube[std::size_t(i * 3 + c)]); };
        const double expected = 0.5 * e(3) + e(4) + e(5) + e(6) + 0.25 * e(7);
        EXPECT_NEAR(m[std::size_t(c)], expected, 1e-6);
    }
}

TEST(Sensor, WindowsFarOutsideTheAxisMeasureNothing) {
    const TimeAxis time = time_axis(20, 0.01);
    const std::vector<float> cube = random_cube(1, 1, 20, 5);
    const SensorSettings s = sensor_from(
        {{"pulse", {{"shape", "box"}, {"width", 0.02}}},
         {"exposure", {{"type", "windows"}, {"windows", {{-1e300, 1.0}, {0.0, 0.2}, {1e300, 1e300}}}}}});
    validate_sensor(s, time);
    const std::vector<float> m = measure(s, time, cube, 1, 1);
    EXPECT_EQ(m[0], 0.0f);
    EXPECT_EQ(m[6], 0.0f);
    // The middle window holds the whole axis but the box moves half of a bin's worth (w/4 of the first
    // and last bins' contents) out of it at each end.
    double all = 0.0;
    for (int i = 0; i < 20; ++i) all += cube[std::size_t(i * 3)];
    EXPECT_NEAR(m[3], all - (cube[0] + cube[19 * 3]) * 0.25, 1e-5);
}

TEST(Sensor, GaussianPulseKeepsEnergyAndMeanArrival) {
    const int T = 400;
    const double dt = 0.005;
    const TimeAxis time = time_axis(T, dt, 1.0);
    std::vector<float> profile(T, 0.0f);
    profile[100] = 2.0f;
    profile[101] = 1.0f;
    profile[250] = 0.5f;
    profile[253] = 0.25f;
    SensorPulse pulse;
    pulse.shape = PulseShape::Gaussian;
    pulse.fwhm = 0.06;  // 12 bins
    const ConvolvedProfile out = convolve_with_pulse(pulse, time, profile.data());
    double e_in = 0.0, t_in = 0.0, e_out = 0.0, t_out = 0.0;
    for (int i = 0; i < T; ++i) {
        e_in += profile[std::size_t(i)];
        t_in += profile[std::size_t(i)] * (i + 0.5);
    }
    for (std::size_t m = 0; m < out.energy.size(); ++m) {
        e_out += out.energy[m];
        t_out += out.energy[m] * (out.first_bin + double(m) + 0.5);
    }
    EXPECT_NEAR(e_out, e_in, 1e-12 * e_in);
    // Mean arrival in bins; exact up to rounding (the kernel is symmetric, the bin split linear).
    EXPECT_NEAR(t_out / e_out, t_in / e_in, 1e-9);

    // The peak of an isolated spike's response is the Gaussian's 1 / (sigma sqrt(2 pi)) per unit time,
    // which fixes the fwhm -> sigma conversion; spreading over one bin lowers it by (dt/sigma)^2 / 24 (0.3%).
    std::vector<float> spike(T, 0.0f);
    spike[200] = 1.0f;
    const ConvolvedProfile s = convolve_with_pulse(pulse, time, spike.data());
    const double peak = *std::max_element(s.energy.begin(), s.energy.end()) / dt;
    const double sigma = 0.06 / (2.0 * std::sqrt(2.0 * std::log(2.0)));
    EXPECT_NEAR(peak, 1.0 / (sigma * std::sqrt(2.0 * M_PI)), 0.01 * peak);

    // The same through the measurement path: windows of one bin each over an extended axis.
    json windows = json::array();
    for (int i = -30; i < T + 30; ++i) windows.push_back({1.0 + i * dt, dt});
    const SensorSettings sensor =
        sensor_from({{"pulse", {{"shape", "gaussian"}, {"fwhm", 0.06}}}, {"exposure", {{"type", "windows"}, {"windows", windows}}}});
    std::vector<float> cube(std::size_t(T) * 3);
    for (int i = 0; i < T; ++i)
        for (int c = 0; c < 3; ++c) cube[std::size_t(i * 3 + c)] = profile[std::size_t(i)];
    const std::vector<float> m = measure(sensor, time, cube, 1, 1);
    double e_m = 0.0, t_m = 0.0;
    for (int k = 0; k < T + 60; ++k) {
        e_m += m[std::size_t(k * 3)];
        t_m += m[std::size_t(k * 3)] * (k - 30 + 0.5);
    }
    EXPECT_NEAR(e_m, e_in, 1e-6 * e_in);  // float measurements
    EXPECT_NEAR(t_m / e_m, t_in / e_in, 1e-4);
}

TEST(Sensor, PulseNarrowerThanABinIsExact) {
    // A box pulse a tenth of a bin wide (shifts uniform in +-dt/20), through gates of ten whole bins. A bin
    // even over its width, shifted by tau, moves max(0, tau) / dt of itself across its upper edge; the mean
    // of that over the box is (dt/20) / 4 / dt = 1/80. So each gate gains 1/80 of the bins beside it and
    // loses 1/80 of its own first and last bins; the first gate's loss below t = 0 and the last gate's
    // beyond the window are lost for good.
    const int T = 30;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube = random_cube(1, 1, T, 3);
    const SensorSettings s = sensor_from({{"pulse", {{"shape", "box"}, {"width", 0.001}}},
                                          {"exposure", {{"type", "gates"}, {"start", 0.0}, {"width", 0.1}, {"step", 0.1}, {"count", 3}}}});
    const std::vector<float> m = measure(s, time, cube, 1, 1);
    auto e = [&](int i) { return i >= 0 && i < T ? double(cube[std::size_t(i * 3)]) : 0.0; };
    for (int k = 0; k < 3; ++k) {
        double expected = 0.0;
        for (int i = 10 * k; i < 10 * k + 10; ++i) expected += e(i);
        expected += (e(10 * k - 1) + e(10 * k + 10) - e(10 * k) - e(10 * k + 9)) / 80.0;
        EXPECT_NEAR(m[std::size_t(k * 3)], expected, 1e-5) << "gate " << k;
    }
}

TEST(Sensor, TablePulseIsNormalisedAndKeepsItsMean) {
    const fs::path dir = fs::temp_directory_path() / ("tprf_sensor_table_" + std::to_string(std::random_device{}()));
    fs::create_directories(dir);
    // A right triangle rising from 0 at t=0 to 4 at t=0.02: area 0.04, centroid 2/3 of the way.
    std::ofstream(dir / "pulse.csv") << "time,value\n0,0\n0.02,4\n0.0200001,0\n";
    const json block = {{"pulse", {{"shape", "table"}, {"file", "pulse.csv"}}},
                        {"exposure", {{"type", "gates"}, {"start", 0}, {"width", 1}, {"step", 1}, {"count", 1}}}};
    const SensorSettings s = parse_sensor_block(block.dump(), dir / "scene.json");
    const TimeKernel k = pulse_kernel(s.pulse, 0.005);
    double total = 0.0, mean = 0.0;
    for (std::size_t q = 0; q < k.mass.size(); ++q) {
        total += k.mass[q];
        mean += k.mass[q] * (k.first + double(q)) * k.step;
    }
    EXPECT_NEAR(total, 1.0, 1e-12);
    EXPECT_NEAR(mean, 2.0 / 3.0 * 0.02, 1e-7);
    fs::remove_all(dir);
}

TEST(Sensor, ExtremeButValidPulsesStayFiniteAndBounded) {
    const fs::path dir = fs::temp_directory_path() / ("tprf_sensor_extreme_" + std::to_string(std::random_device{}()));
    fs::create_directories(dir);
    const TimeAxis time = time_axis(100, 0.04);
    // A table a tenth of a nanometre wide, 1 m from t = 0: its grid must not overflow, and its mean stays.
    std::ofstream(dir / "narrow.csv") << "1.0,1\n1.0000000001,1\n";
    json block = {{"pulse", {{"shape", "table"}, {"file", "narrow.csv"}}},
                  {"exposure", {{"type", "gates"}, {"start", 0}, {"width", 0.4}, {"step", 0.4}, {"count", 10}}}};
    SensorSettings s = parse_sensor_block(block.dump(), dir / "scene.json");
    validate_sensor(s, time);
    const TimeKernel k = pulse_kernel(s.pulse, time.bin_width);
    double total = 0.0, mean = 0.0;
    for (std::size_t q = 0; q < k.mass.size(); ++q) {
        total += k.mass[q];
        mean += k.mass[q] * (k.first + double(q)) * k.step;
    }
    EXPECT_NEAR(total, 1.0, 1e-12);
    EXPECT_NEAR(mean, 1.00000000005, 1e-9);
    // Values near the largest double: only the shape counts.
    std::ofstream(dir / "huge.csv") << "0,1e308\n0.01,1.7e308\n0.02,0\n";
    block["pulse"]["file"] = "huge.csv";
    s = parse_sensor_block(block.dump(), dir / "scene.json");
    block["clamp"] = false;
    const std::vector<float> cube = random_cube(2, 2, 100, 9);
    for (const float v : measure(s, time, cube, 2, 2)) EXPECT_TRUE(std::isfinite(v));
    // A first row that starts with a number but is malformed is an error, not a header.
    std::ofstream(dir / "bad.csv") << "0,1,2\n0.01,1\n";
    block["pulse"]["file"] = "bad.csv";
    EXPECT_THROW(parse_sensor_block(block.dump(), dir / "scene.json"), Error);
    fs::remove_all(dir);

    // A SPAD whose pulse is far narrower than its jitter: the convolution's grid stays bounded.
    const SensorSettings spad = sensor_from({{"pulse", {{"shape", "gaussian"}, {"fwhm", 1e-10}}},
                                             {"exposure", {{"type", "spad"}, {"photons", 1}, {"jitter_fwhm", 0.04}}}});
    validate_sensor(spad, time);
    const SensorWeights w = sensor_weights(spad, time);
    double sum = 0.0;
    for (const double v : w.weight[50]) sum += v;
    EXPECT_NEAR(sum, 1.0, 1e-9);  // bin 50 keeps its whole signal: jitter (4 cm) is far from the window's ends
    // AMCW at a frequency whose phase hardly turns over a bin: the weights are finite, near 1/2 + cos/2.
    const SensorSettings slow = sensor_from({{"exposure", {{"type", "amcw"}, {"frequency_mhz", 1e-12}}}});
    const SensorWeights a = sensor_weights(slow, time);
    for (const auto& row : a.weight)
        for (const double v : row) EXPECT_TRUE(std::isfinite(v));
    EXPECT_NEAR(a.weight[0][0], 1.0, 1e-9);  // phase 0: (1 + cos 0) / 2
    EXPECT_NEAR(a.weight[2][0], 0.0, 1e-9);  // phase 180
}

TEST(Sensor, NoiseHasTheRequestedSigmaAndIsReproducible) {
    const int H = 32, W = 32, T = 40, K = 10;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube(std::size_t(H * W * T * 3), 0.0f);
    const double sigma = 0.25;
    json block = {{"exposure", {{"type", "gates"}, {"start", 0}, {"width", 0.04}, {"step", 0.04}, {"count", K}}},
                  {"noise", {{"sigma", sigma}, {"seed", 7}}},
                  {"clamp", false}};
    const std::vector<float> m = measure(sensor_from(block), time, cube, H, W, nullptr, 2);
    const double n = double(m.size());
    const double mean = std::accumulate(m.begin(), m.end(), 0.0) / n;
    double var = 0.0;
    for (const float v : m) var += (v - mean) * (v - mean);
    const double sd = std::sqrt(var / (n - 1));
    // Four standard errors: the sample mean's sigma/sqrt(n), the sample sd's sigma/sqrt(2n).
    EXPECT_NEAR(mean, 0.0, 4 * sigma / std::sqrt(n));
    EXPECT_NEAR(sd, sigma, 4 * sigma / std::sqrt(2 * n));

    EXPECT_EQ(measure(sensor_from(block), time, cube, H, W, nullptr, 1), m) << "thread count changed the noise";
    block["noise"]["seed"] = 8;
    EXPECT_NE(measure(sensor_from(block), time, cube, H, W), m) << "another seed gave the same noise";

    // Clamped (the default): no negative measurement, and half of the zero-mean noise becomes 0.
    block.erase("clamp");
    const std::vector<float> c = measure(sensor_from(block), time, cube, H, W);
    EXPECT_GE(*std::min_element(c.begin(), c.end()), 0.0f);
    const double zeros = double(std::count(c.begin(), c.end(), 0.0f)) / n;
    EXPECT_NEAR(zeros, 0.5, 4 * 0.5 / std::sqrt(n));
}

TEST(Sensor, SpadCountsArePoisson) {
    const int H = 8, W = 8, T = 64;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube(std::size_t(H * W * T * 3), 1.0f);
    const double lambda = 5.0;
    const std::vector<float> m = measure(
        sensor_from({{"exposure", {{"type", "spad"}, {"photons", lambda}, {"seed", 3}}}}), time, cube, H, W);
    ASSERT_EQ(m.size(), cube.size());  // K = T
    const double n = double(m.size());
    double mean = 0.0, var = 0.0;
    for (const float v : m) {
        EXPECT_EQ(v, std::floor(v)) << "counts are whole numbers";
        mean += v;
    }
    mean /= n;
    for (const float v : m) var += (v - mean) * (v - mean);
    var /= n - 1;
    // Four standard errors: sqrt(lambda/n) for the mean; sqrt((mu4 - sigma^4)/n) for the variance,
    // with a Poisson's mu4 = lambda (1 + 3 lambda).
    EXPECT_NEAR(mean, lambda, 4 * std::sqrt(lambda / n));
    EXPECT_NEAR(var, lambda, 4 * std::sqrt((lambda + 2 * lambda * lambda) / n));

    // Dark counts alone: dark_rate counts per second of bin time; a bin of 0.01 m lasts 0.01/c s.
    const double per_bin = 2.0;
    const double dark_rate = per_bin / (0.01 / kSpeedOfLight);
    const std::vector<float> zero(cube.size(), 0.0f);
    const std::vector<float> d = measure(
        sensor_from({{"exposure", {{"type", "spad"}, {"photons", 1}, {"dark_rate", dark_rate}, {"seed", 4}}}}), time, zero, H, W);
    const double dark_mean = std::accumulate(d.begin(), d.end(), 0.0) / n;
    EXPECT_NEAR(dark_mean, per_bin, 4 * std::sqrt(per_bin / n));
}

TEST(Sensor, SpadJitterSpreadsCountsAroundTheArrival) {
    const int T = 200;
    const TimeAxis time = time_axis(T, 0.01);
    std::vector<float> cube(std::size_t(T) * 3, 0.0f);
    for (int c = 0; c < 3; ++c) cube[std::size_t(100 * 3 + c)] = 1.0f;
    const double photons = 1e6, fwhm = 0.05;  // 5 bins
    const std::vector<float> m = measure(
        sensor_from({{"exposure", {{"type", "spad"}, {"photons", photons}, {"jitter_fwhm", fwhm}, {"seed", 1}}}}), time,
        cube, 1, 1);
    double total = 0.0, mean = 0.0, var = 0.0;
    for (int i = 0; i < T; ++i) total += m[std::size_t(i * 3)];
    for (int i = 0; i < T; ++i) mean += m[std::size_t(i * 3)] * (i + 0.5) / total;
    for (int i = 0; i < T; ++i) var += m[std::size_t(i * 3)] * (i + 0.5 - mean) * (i + 0.5 - mean) / total;
    // Poisson total: sd 1000. The mean stays at the arrival bin's centre; the variance is the jitter's
    // plus the bin's own spread (1/12) and the histogram's linear split (1/6 at most), in bins^2.
    EXPECT_NEAR(total, photons, 5 * std::sqrt(photons));
    EXPECT_NEAR(mean, 100.5, 0.02);
    const double sigma_bins = fwhm / 0.01 / (2.0 * std::sqrt(2.0 * std::log(2.0)));
    EXPECT_GT(var, sigma_bins * sigma_bins);
    EXPECT_LT(var, sigma_bins * sigma_bins + 1.0 / 12 + 1.0 / 6 + 0.05);
}

// Path lengths up to 10 m in 5 mm bins.
json amcw_scene(const json& objects, const Vec3& eye, const Vec3& look) {
    return {{"time", {{"bins", 2000}, {"bin_width", 0.005}}},
            {"camera", {{"position", {eye.x(), eye.y(), eye.z()}}, {"look_at", {look.x(), look.y(), look.z()}},
                        {"up", {0, 0, 1}}, {"fov", 40}, {"width", 12}, {"height", 10}, {"spp", 1}}},
            {"lights", {{{"type", "point"}, {"position", {eye.x(), eye.y(), eye.z()}}, {"intensity", 1.0}}}},
            {"objects", objects},
            {"patches", {{"max_edge", 0.1}}},
            {"sensor", {{"exposure", {{"type", "amcw"}, {"frequency_mhz", 20}}}}}};
}

// Renders the scene and returns (depth - true distance) for every pixel that sees a surface, where the
// true distance is from the camera to the point the pixel centre sees.
std::vector<double> depth_errors(const json& j, const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / ("tprf_amcw_" + name + "_" + std::to_string(std::random_device{}()));
    fs::create_directories(dir);
    const fs::path file = dir / "scene.json";
    std::ofstream(file) << j.dump(2);
    RenderOptions o;
    o.output = dir / "out";
    render_file(file, o);
    const NpyArray depth = read_npy(dir / "out" / "depth.npy");
    const Scene scene = load_scene(file);
    const Camera& cam = *scene.camera;
    EXPECT_EQ(depth.shape, (std::vector<std::size_t>{std::size_t(cam.height), std::size_t(cam.width)}));
    const PatchSet patches = build_patches(scene);
    const Visibility vis(patches);
    std::vector<double> errors;
    for (int r = 0; r < cam.height; ++r)
        for (int c = 0; c < cam.width; ++c) {
            const RayHit h = vis.intersect(cam.position, camera_ray(cam, c + 0.5, r + 0.5), 1e30);
            if (h.hit && h.front) errors.push_back(depth.data[std::size_t(r * cam.width + c)] - h.distance);
        }
    fs::remove_all(dir);
    return errors;
}

TEST(Sensor, AmcwDepthOfAPlaneLitFromTheCameraIsItsDistance) {
    // One plane, nothing else: single-bounce light only, so the phase is the distance's.
    const json plane = {{{"type", "rectangle"}, {"origin", {0, -1, -1}}, {"u", {0, 2, 0}}, {"v", {0, 0, 2}}}};
    const std::vector<double> e = depth_errors(amcw_scene(plane, Vec3(2.5, 0.1, 0.2), Vec3(0, 0, 0)), "plane");
    ASSERT_GT(e.size(), 100u);
    for (const double err : e) EXPECT_NEAR(err, 0.0, 0.01);
}

TEST(Sensor, AmcwDepthInACornerIsTooLong) {
    // Floor and wall: light that bounces between them arrives later, so its phasor pulls every pixel's
    // phase later (at 20 MHz the extra path, under 3 m, is less than half the 15 m wavelength).
    const json corner = {
        {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {1, 0, 0}}, {"v", {0, 1, 0}}, {"albedo", 0.8}},
        {{"type", "rectangle"}, {"origin", {0, 0, 0}}, {"u", {0, 1, 0}}, {"v", {0, 0, 1}}, {"albedo", 0.8}}};
    const std::vector<double> e = depth_errors(amcw_scene(corner, Vec3(1.6, 0.5, 0.6), Vec3(0.3, 0.5, 0.3)), "corner");
    ASSERT_GT(e.size(), 60u);
    double mean = 0.0;
    for (const double err : e) {
        EXPECT_GT(err, -0.01) << "multipath cannot make a depth shorter than the plane test's tolerance";
        mean += err / double(e.size());
    }
    EXPECT_GT(mean, 0.01) << "the corner's interreflections should lengthen the depth beyond the 1 cm tolerance";
}


// A plane 2.5 to 2.9 m away is beyond the wrap of 100 MHz (1.5 m) and of 80 MHz (1.87 m): each alone
// reads it wrapped, the two together (unambiguous to 7.5 m) read its distance.
TEST(Sensor, TwoFrequenciesUnwrapTheDepthOfAPlaneBeyondEachOnesWrap) {
    const json plane = {{{"type", "rectangle"}, {"origin", {0, -1, -1}}, {"u", {0, 2, 0}}, {"v", {0, 0, 2}}}};
    json j = amcw_scene(plane, Vec3(2.5, 0.1, 0.2), Vec3(0, 0, 0));
    j["sensor"]["exposure"] = {{"type", "amcw"}, {"frequencies", {100e6, 80e6}}, {"phases", 4}};
    const std::vector<double> both = depth_errors(j, "two");
    ASSERT_GT(both.size(), 100u);
    double worst = 0.0;
    for (const double err : both) worst = std::max(worst, std::abs(err));
    j["sensor"]["exposure"] = {{"type", "amcw"}, {"frequency_mhz", 100}};
    const std::vector<double> one = depth_errors(j, "one");
    double wrapped = 0.0;
    for (const double err : one) wrapped += err / double(one.size());
    MEASURED("two frequencies: depth within %.3g m of the distance; 100 MHz alone off by %.3f m on average\n", worst,
             wrapped);
    EXPECT_LT(worst, 0.01);
    EXPECT_NEAR(wrapped, -1.5, 0.01);  // one wrap of 100 MHz short
}

// Raw samples: the channels' sum of the measurements; with photons a Poisson count of photons times it
// plus ambient (mean and variance over many equal pixels); with adc_bits integer levels whose top is
// the frame's largest sample.
TEST(Sensor, AmcwRawSamplesAreChannelSumsWithShotNoiseAndQuantisation) {
    const int H = 64, W = 64, T = 200;
    const TimeAxis time = time_axis(T, 0.01);
    std::vector<float> cube(std::size_t(H * W * T * 3), 0.0f);
    for (std::size_t p = 0; p < std::size_t(H * W); ++p)
        for (int c = 0; c < 3; ++c) cube[(p * T + 37) * 3 + std::size_t(c)] = 0.1f * float(c + 1);  // one bin lit
    json block = {{"exposure", {{"type", "amcw"}, {"frequencies", {20e6, 50e6}}, {"phases", 3}}}};
    const auto raw_of = [&](const json& b, int threads) {
        const SensorSettings s = sensor_from(b);
        const int K = measurement_count(s, time);
        EXPECT_EQ(K, 6);
        std::vector<float> m(std::size_t(H * W * K * 3)), raw(std::size_t(H * W * K));
        SensorOptions o;
        o.threads = threads;
        apply_sensor(s, {time, cube.data(), H, W}, m.data(), nullptr, o, raw.data());
        return std::make_pair(m, raw);
    };
    const auto [m, clean] = raw_of(block, 0);
    for (std::size_t q = 0; q < clean.size(); ++q)
        EXPECT_EQ(clean[q], float(double(m[q * 3]) + m[q * 3 + 1] + m[q * 3 + 2])) << q;
    block["exposure"]["photons"] = 1000.0;
    block["exposure"]["ambient"] = 50.0;
    block["exposure"]["seed"] = 11;
    const std::vector<float> counts = raw_of(block, 1).second;
    EXPECT_EQ(counts, raw_of(block, 2).second);  // the same for any thread count
    for (std::size_t k = 0; k < 6; ++k) {
        const double expected = 1000.0 * clean[k] + 50.0;
        double mean = 0.0, var = 0.0;
        for (std::size_t p = 0; p < std::size_t(H * W); ++p) mean += counts[p * 6 + k] / double(H * W);
        for (std::size_t p = 0; p < std::size_t(H * W); ++p) var += std::pow(counts[p * 6 + k] - mean, 2) / double(H * W - 1);
        const double n = double(H * W);
        MEASURED("sample %zu: mean %.2f (expected %.2f), variance %.2f\n", k, mean, expected, var);
        EXPECT_NEAR(mean, expected, 4.0 * std::sqrt(expected / n));
        EXPECT_NEAR(var, expected, 4.0 * expected * std::sqrt(2.0 / (n - 1)));
    }
    block["exposure"]["adc_bits"] = 8;
    const std::vector<float> levels = raw_of(block, 0).second;
    const float top = *std::max_element(counts.begin(), counts.end());
    EXPECT_EQ(*std::max_element(levels.begin(), levels.end()), 255.0f);
    for (std::size_t q = 0; q < levels.size(); ++q) {
        EXPECT_EQ(levels[q], std::round(levels[q]));
        EXPECT_NEAR(levels[q], counts[q] / top * 255.0, 0.5 + 1e-4) << q;
    }
}

TEST(Sensor, AmcwPhasesCountIsEvenlySpacedAndBadKeysNameTheirPath) {
    const SensorSettings spaced = sensor_from({{"exposure", {{"type", "amcw"}, {"frequency_mhz", 20}, {"phases", 3}}}});
    EXPECT_EQ(spaced.exposure.phases_deg, (std::vector<double>{0.0, 120.0, 240.0}));
    const auto error = [](const json& exposure) {
        try {
            sensor_from({{"exposure", exposure}});
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string();
    };
    const json base = {{"type", "amcw"}, {"frequencies", {20e6, 50e6}}};
    const auto with = [&](const char* key, const json& value) {
        json e = base;
        e[key] = value;
        return error(e);
    };
    EXPECT_EQ(error(base), "");
    EXPECT_NE(with("frequency_mhz", 20).find("give either \"frequency_mhz\" or \"frequencies\""), std::string::npos);
    EXPECT_NE(with("frequencies", {20e6, 20e6}).find("frequencies[1]: repeats an earlier frequency"), std::string::npos)
        << with("frequencies", {20e6, 20e6});
    EXPECT_NE(with("frequencies", {20e6, -1}).find("frequencies[1]: must be > 0"), std::string::npos);
    EXPECT_NE(with("frequencies", json::array()).find("expected at least one frequency"), std::string::npos);
    EXPECT_NE(with("phases", 2).find("phases: must be an integer in [3,"), std::string::npos) << with("phases", 2);
    EXPECT_NE(with("ambient", 5).find("ambient: needs \"photons\""), std::string::npos) << with("ambient", 5);
    EXPECT_NE(with("adc_bits", 30).find("adc_bits: must be an integer in [0, 24]"), std::string::npos);
    EXPECT_NE(with("photons", -1).find("photons: must be >= 0"), std::string::npos);
    // Against a 10 m window, 80 THz wraps 5e6 times: the unwrapping would try each (Hz meant as kHz?).
    const TimeAxis time = time_axis(1000, 0.01);
    try {
        validate_sensor(sensor_from({{"exposure", {{"type", "amcw"}, {"frequencies", {80e12, 100e12}}}}}), time);
        ADD_FAILURE() << "frequencies far too high for the window were accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("exposure.frequencies: the lowest frequency, 8e+13 Hz, wraps every"),
                  std::string::npos)
            << e.what();
    }
    EXPECT_NO_THROW(validate_sensor(sensor_from({{"exposure", {{"type", "amcw"}, {"frequencies", {80e6, 100e6}}}}}), time));
}

// ---- The random numbers behind noise and photon counts (core/random.h, docs/sensor.md) ----

TEST(SensorRandom, SplitMix64MatchesTheReferenceOutputs) {
    // The first outputs of Vigna's splitmix64.c for this seed, as published with rand_xoshiro's test
    // of its translation (github.com/rust-random/rngs, rand_xoshiro/src/splitmix64.rs).
    const std::uint64_t seed = 1477776061723855037ull;
    const std::array<std::uint64_t, 6> expected = {1985237415132408290ull,  2979275885539914483ull,
                                                   13511426838097143398ull, 8488337342461049707ull,
                                                   15141737807933549159ull, 17093170987380407015ull};
    SplitMix64 sm(seed);
    for (std::size_t i = 0; i < expected.size(); ++i) {
        EXPECT_EQ(sm.next(), expected[i]) << "output " << i;
        EXPECT_EQ(SplitMix64::output(seed, i), expected[i]) << "output " << i << " by index (a pixel's seed)";
    }
}

TEST(SensorRandom, Xoshiro256StarStarMatchesTheReferenceOutputs) {
    // xoshiro256starstar.c from the state {1, 2, 3, 4}, as published with rand_xoshiro's test
    // (rand_xoshiro/src/xoshiro256starstar.rs: "produced with the reference implementation").
    Xoshiro256StarStar g(std::array<std::uint64_t, 4>{1, 2, 3, 4});
    const std::array<std::uint64_t, 10> expected = {
        11520ull, 0ull, 1509978240ull, 1215971899390074240ull, 1216172134540287360ull, 607988272756665600ull,
        16172922978634559625ull, 8476171486693032832ull, 10595114339597558777ull, 2904607092377533576ull};
    for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_EQ(g.next(), expected[i]) << "output " << i;
}

TEST(SensorRandom, AStreamGivesTheSameNumbersEverywhere) {
    // Computed once by tools/random_reference.py, a Python reimplementation of random.h written from
    // docs/sensor.md (Python ints masked to 64 bits, the C library's log, sqrt, cos, sin, exp, log1p),
    // and pasted here. Doubles as hexadecimal literals: the comparison is exact.
    Random r(42);
    EXPECT_EQ(r.next_u64(), 1546998764402558742ull);
    EXPECT_EQ(r.next_u64(), 6990951692964543102ull);
    EXPECT_EQ(r.next_u64(), 12544586762248559009ull);
    EXPECT_EQ(r.uniform(), 0x1.d9715a8e0766cp-1);
    EXPECT_EQ(r.uniform(), 0x1.fbcdb8ffc5d8bp-1);
    EXPECT_EQ(r.normal(), -0x1.50ddefa736061p-2);  // the cosine of a pair
    EXPECT_EQ(r.normal(), -0x1.ae92833edca00p+0);  // its sine, drawn with it
    EXPECT_EQ(r.normal(), 0x1.1cdd0889a848fp-3);
    for (const double k : {4.0, 6.0, 3.0, 4.0}) EXPECT_EQ(r.poisson(3.5), k);  // multiplication method
    for (const double k : {1226.0, 1270.0, 1266.0, 1231.0}) EXPECT_EQ(r.poisson(1234.5), k);  // PTRS
    for (const double k : {1000000103100.0, 1000000962220.0, 1000001500209.0}) EXPECT_EQ(r.poisson(1e12), k);
    for (const double k : {1000000005792487.0, 1000000038522556.0, 1000000001739257.0}) EXPECT_EQ(r.poisson(1e15), k);
}

TEST(SensorRandom, NormalsHaveTheMomentsOfAStandardNormal) {
    Random r(11);
    const int n = 1000000;
    double sum = 0.0, sum2 = 0.0, sum4 = 0.0, pair = 0.0;
    for (int i = 0; i < n; i += 2) {
        const double a = r.normal(), b = r.normal();  // the two values of one Box-Muller pair
        for (const double z : {a, b}) sum += z, sum2 += z * z, sum4 += z * z * z * z;
        pair += a * b;
    }
    // Four standard errors of each sample moment: Var(z) = 1, Var(z^2) = E z^4 - 1 = 2, Var(z^4) = E z^8 - 9
    // = 96, and the product of a pair's two values (independent, so E[ab] = 0) has variance 1.
    EXPECT_NEAR(sum / n, 0.0, 4.0 / std::sqrt(n));
    EXPECT_NEAR(sum2 / n, 1.0, 4.0 * std::sqrt(2.0 / n));
    EXPECT_NEAR(sum4 / n, 3.0, 4.0 * std::sqrt(96.0 / n));
    EXPECT_NEAR(pair / (n / 2), 0.0, 4.0 / std::sqrt(n / 2));
}

TEST(SensorRandom, PoissonCountsHaveTheirMeanAsMeanAndVariance) {
    // Below 10 the multiplication method, from 10 on PTRS: both sides of the switch, and PTRS up to the
    // largest mean a SPAD bin draws (1e15; beyond, the count is its mean).
    const int n = 200000;
    for (const double lambda : {0.05, 0.5, 3.0, 9.99, 10.0, 47.5, 1e4, 1e12, 1e15}) {
        Random r(std::uint64_t(lambda * 1000) + 1);
        double sum = 0.0, sum2 = 0.0;
        for (int i = 0; i < n; ++i) {
            const double k = r.poisson(lambda);
            ASSERT_EQ(k, std::floor(k)) << "lambda " << lambda;
            ASSERT_GE(k, 0.0);
            const double d = k - lambda;  // deviations: exact, where sums of counts near 1e15 would not be
            sum += d, sum2 += d * d;
        }
        const double mean_dev = sum / n, var = (sum2 - sum * mean_dev) / (n - 1);
        // Four standard errors: sqrt(lambda / n) for the mean; sqrt((mu4 - sigma^4) / n) for the variance,
        // with a Poisson's mu4 = lambda (1 + 3 lambda).
        EXPECT_NEAR(mean_dev, 0.0, 4 * std::sqrt(lambda / n)) << "lambda " << lambda;
        EXPECT_NEAR(var, lambda, 4 * std::sqrt((lambda + 2 * lambda * lambda) / n)) << "lambda " << lambda;
    }
}

TEST(SensorRandom, PoissonFrequenciesFollowThePoissonLaw) {
    // Pearson's chi-square of the counts against the Poisson probabilities (from lgamma here, not from
    // the generator's own formulas), over the cells expected to hold at least 5 counts (the tails pooled
    // into the end cells). With df degrees of freedom chi-square has mean df and variance 2 df: four
    // standard deviations above the mean is the bound.
    const int n = 1000000;
    for (const double lambda : {3.0, 20.0, 1000.0}) {  // multiplication; PTRS near its table; PTRS (Stirling)
        Random r(std::uint64_t(lambda) + 77);
        std::vector<double> observed(std::size_t(4 * lambda + 100), 0.0);
        for (int i = 0; i < n; ++i) {
            const std::size_t k = std::size_t(r.poisson(lambda));
            observed[std::min(k, observed.size() - 1)] += 1.0;
        }
        auto p = [&](std::size_t k) { return std::exp(-lambda + double(k) * std::log(lambda) - std::lgamma(double(k) + 1)); };
        std::size_t lo = 0, hi = observed.size() - 1;
        while (n * p(lo) < 5) ++lo;
        while (n * p(hi) < 5) --hi;
        double p_low = 0.0, p_mid = 0.0, o_low = 0.0, o_high = 0.0;
        for (std::size_t k = 0; k < lo; ++k) p_low += p(k), o_low += observed[k];
        for (std::size_t k = lo; k <= hi; ++k) p_mid += p(k);
        for (std::size_t k = hi + 1; k < observed.size(); ++k) o_high += observed[k];
        const double p_high = 1.0 - p_low - p_mid;
        double chi2 = 0.0;
        for (std::size_t k = lo; k <= hi; ++k) {
            double e = n * p(k), o = observed[k];
            if (k == lo) e += n * p_low, o += o_low;
            if (k == hi) e += n * p_high, o += o_high;
            chi2 += (o - e) * (o - e) / e;
        }
        const double df = double(hi - lo);
        EXPECT_LT(chi2, df + 4 * std::sqrt(2 * df)) << "lambda " << lambda << ", " << hi - lo + 1 << " cells";
    }
}

TEST(Sensor, SpadCountsBeyondTheBoundAreTheirMean) {
    // 1e20 expected photons per bin (beyond 1e15): the count is the mean itself, in float.
    const TimeAxis time = time_axis(4, 0.01);
    const std::vector<float> cube(4 * 3, 1.0f);
    const std::vector<float> m = measure(sensor_from({{"exposure", {{"type", "spad"}, {"photons", 1e20}}}}), time, cube, 1, 1);
    for (const float v : m) EXPECT_EQ(v, 1e20f);
}


// ---- A SPAD's detector effects: jitter tail, dead time, afterpulsing, ambient light, crosstalk, dead pixels ----

// A cube (H, W, T, 3) that holds `value` in bin `bin` of every pixel and channel, 0 elsewhere.
std::vector<float> spike_cube(int h, int w, int t, int bin, float value) {
    std::vector<float> cube(std::size_t(h * w * t * 3), 0.0f);
    for (int p = 0; p < h * w; ++p)
        for (int c = 0; c < 3; ++c) cube[std::size_t((p * t + bin) * 3 + c)] = value;
    return cube;
}

json spad(const json& extra) {
    json e = {{"type", "spad"}, {"photons", 1000}, {"seed", 5}};
    e.update(extra);
    return {{"exposure", e}};
}

std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

TEST(SensorSpad, JitterTailKernelHasUnitAreaAndMeanTimeConstantTimesFraction) {
    // (fwhm, tau, fraction): Gaussian and tail; a tail alone; all counts in the tail.
    for (const auto& [fwhm, tau, f] : {std::array<double, 3>{0.03, 0.05, 0.3}, {0.0, 0.02, 0.5}, {0.03, 0.05, 1.0},
                                       {0.002, 0.3, 0.05}}) {
        Exposure e;
        e.type = ExposureType::Spad;
        e.jitter_fwhm = fwhm;
        e.jitter_tail = {tau, f};
        const TimeKernel k = jitter_kernel(e, 0.01);
        double total = 0.0, mean = 0.0;
        for (std::size_t q = 0; q < k.mass.size(); ++q) {
            total += k.mass[q];
            mean += k.mass[q] * (k.first + double(q)) * k.step;
        }
        // The Gaussian is symmetric and the exponential's cells sit at their centroids (what lies beyond the
        // 20 tau cut at its own mean): both exact up to rounding, far inside 1e-6.
        EXPECT_NEAR(total, 1.0, 1e-12) << "fwhm " << fwhm << " tau " << tau;
        EXPECT_NEAR(mean, f * tau, 1e-6 * tau) << "fwhm " << fwhm << " tau " << tau;
    }
    // Through the histogram: a spike's expected counts keep their total and arrive f tau later on average
    // (the weights split bins linearly, which keeps the mean; nothing reaches the window's ends).
    const int T = 400;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube = spike_cube(1, 1, T, 100, 1.0f);
    const SensorSettings s = sensor_from(spad({{"jitter_fwhm", 0.03}, {"jitter_tail", {{"time_constant", 0.05}, {"fraction", 0.3}}}}));
    validate_sensor(s, time);
    const std::vector<double> m = spad_expected_counts(s, {time, cube.data(), 1, 1}, 0, 0);
    double total = 0.0, mean = 0.0;
    for (int k = 0; k < T; ++k) total += m[std::size_t(k * 3)], mean += m[std::size_t(k * 3)] * (k + 0.5);
    EXPECT_NEAR(total, 1000.0, 1e-9);
    EXPECT_NEAR(mean / total, 100.5 + 0.3 * 0.05 / 0.01, 1e-6);
}

TEST(SensorSpad, DeadTimeSuppressesLaterBinsByTheSynchronousFactor) {
    // Three bins, a strong first one: 2000, 500 and 500 expected photons over N = 1000 cycles, so x = 2, 0.5,
    // 0.5 per cycle and p_k = 1 - exp(-x_k) (delta pulse, no jitter: each bin keeps its own signal).
    const TimeAxis time = time_axis(3, 0.01);
    std::vector<float> cube = {2, 2, 2, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f};
    const double N = 1000, p0 = 1 - std::exp(-2.0), p1 = 1 - std::exp(-0.5), p2 = p1;
    auto counts = [&](double dead_time) {
        return spad_expected_counts(sensor_from(spad({{"dead_time", dead_time}, {"cycles", N}})), {time, cube.data(), 1, 1}, 0, 0);
    };
    // No dead time: the counts are the photons themselves.
    const std::vector<double> none = counts(0.0);
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(none[std::size_t(c)], 2000.0, 1e-9);
        EXPECT_NEAR(none[std::size_t(3 + c)], 500.0, 1e-9);
    }
    // Dead time over the whole window (TCSPC's one detection per cycle): Coates' pile-up, bin k counts when
    // it holds a photon and no earlier bin did.
    const std::vector<double> coates = counts(0.05);
    const std::array<double, 3> expect_coates = {N * p0, N * (1 - p0) * p1, N * (1 - p0) * (1 - p1) * p2};
    // One bin of dead time: bin 2 is blind only after a detection in bin 1, (1 - p0) p1 of the cycles.
    const std::vector<double> one = counts(0.01);
    const std::array<double, 3> expect_one = {N * p0, N * (1 - p0) * p1, N * p2 * (1 - (1 - p0) * p1)};
    for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(coates[std::size_t(k * 3 + c)], expect_coates[std::size_t(k)], 1e-12 * N) << "bin " << k;
            EXPECT_NEAR(one[std::size_t(k * 3 + c)], expect_one[std::size_t(k)], 1e-12 * N) << "bin " << k;
        }
    // The suppression after the peak is the synchronous model's factor, 1 - p0 = exp(-2) for bin 1.
    EXPECT_NEAR(coates[3] / (N * p1), std::exp(-2.0), 1e-12);
}

TEST(SensorSpad, AfterpulsingAddsItsProbabilityTimesTheDetections) {
    // Detections in bin 10 only; afterpulses after the 5-bin dead time, then exponential with tau = 10 bins:
    // the mass beyond the window's 400 bins (e^-38) is far below the tolerance.
    const int T = 400, H = 16, W = 16;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube = spike_cube(H, W, T, 10, 1.0f);
    const double P = 0.1;
    const json base = {{"dead_time", 0.05}, {"cycles", 1e4}};
    json with = base;
    with["afterpulsing"] = {{"probability", P}, {"time_constant", 0.1}};
    const std::vector<double> d = spad_expected_counts(sensor_from(spad(base)), {time, cube.data(), H, W}, 0, 0);
    const std::vector<double> a = spad_expected_counts(sensor_from(spad(with)), {time, cube.data(), H, W}, 0, 0);
    double detections = 0.0, total = 0.0, offset = 0.0;
    for (int k = 0; k < T; ++k) {
        detections += d[std::size_t(k * 3)];
        total += a[std::size_t(k * 3)];
        offset += (a[std::size_t(k * 3)] - d[std::size_t(k * 3)]) * (k - 10);
    }
    // 1000 photons over 1e4 cycles: a detection in 1 - exp(-0.1) of them.
    EXPECT_NEAR(detections, 1e4 * -std::expm1(-0.1), 1e-9);
    EXPECT_NEAR(total, (1 + P) * detections, 1e-9 * detections);
    // A detection's place in its bin is uniform, so the afterpulses' mean offset is exactly the delay's mean
    // in bins: dead time 5 + tau 10.
    EXPECT_NEAR(offset / (P * detections), 15.0, 1e-6);

    // Drawn: the total over all pixels is Poisson with mean (1 + P) x detections x pixels; 5 sigma.
    const std::vector<float> m = measure(sensor_from(spad(with)), time, cube, H, W);
    const double drawn = std::accumulate(m.begin(), m.end(), 0.0);
    const double expected = (1 + P) * detections * 3 * H * W;
    EXPECT_NEAR(drawn, expected, 5 * std::sqrt(expected));
}

TEST(SensorSpad, AmbientAddsRateTimesBinTimeTimesCycles) {
    const int H = 32, W = 32, T = 64;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> zero(std::size_t(H * W * T * 3), 0.0f);
    const double rate = 1e5, cycles = 1e6, dark = 3e8;  // ambient: per second on the pixel; dark: per second of bin time
    const double bin_seconds = 0.01 / kSpeedOfLight;
    const double per_bin = rate * bin_seconds * cycles + dark * bin_seconds;  // 3.34 + 0.01 counts
    const SensorSettings s = sensor_from(spad({{"ambient", rate}, {"cycles", cycles}, {"dark_rate", dark}}));
    for (const double v : spad_expected_counts(s, {time, zero.data(), H, W}, 3, 4)) EXPECT_NEAR(v, per_bin, 1e-12 * per_bin);
    const std::vector<float> m = measure(s, time, zero, H, W);
    const double n = double(m.size()), mean = std::accumulate(m.begin(), m.end(), 0.0) / n;
    EXPECT_NEAR(mean, per_bin, 5 * std::sqrt(per_bin / n));  // 5 standard errors of a Poisson mean
}

TEST(SensorSpad, CrosstalkGivesEachNeighbourItsProbabilityTimesThePixelsCounts) {
    const int H = 5, W = 5, T = 8;
    const TimeAxis time = time_axis(T, 0.01);
    std::vector<float> cube(std::size_t(H * W * T * 3), 0.0f);
    auto at = [&](int row, int column, int bin) { return std::size_t(((row * W + column) * T + bin) * 3); };
    for (int c = 0; c < 3; ++c) cube[at(2, 2, 3) + std::size_t(c)] = 1.0f;  // only the centre sees light, in bin 3
    const double x = 0.02;
    const SensorSettings s = sensor_from(spad({{"crosstalk", x}}));
    auto counts = [&](int row, int column) { return spad_expected_counts(s, {time, cube.data(), H, W}, row, column)[3 * 3]; };
    // First order: the crosstalk the neighbours receive does not come back. (The bin's weight is 1 up to the
    // rounding of its overlap with itself.)
    const double centre = counts(2, 2);
    EXPECT_NEAR(centre, 1000.0, 1e-9);
    for (const auto& [r, c] : {std::array<int, 2>{1, 2}, {3, 2}, {2, 1}, {2, 3}}) EXPECT_NEAR(counts(r, c), x * centre, 1e-12);
    for (const auto& [r, c] : {std::array<int, 2>{1, 1}, {0, 2}, {3, 3}, {4, 4}}) EXPECT_EQ(counts(r, c), 0.0);
    // A dead pixel sends no crosstalk.
    const SensorSettings dead = sensor_from(spad({{"crosstalk", x}, {"dead_pixels", {{2, 2}}}}));
    EXPECT_EQ(spad_expected_counts(dead, {time, cube.data(), H, W}, 1, 2)[3 * 3], 0.0);

    // Drawn: lit pixels on a lattice of pitch 3, so that every other pixel has at most one lit neighbour.
    const int N = 60;
    std::vector<float> lattice(std::size_t(N * N * T * 3), 0.0f);
    for (int r = 1; r < N; r += 3)
        for (int c = 1; c < N; c += 3)
            for (int ch = 0; ch < 3; ++ch) lattice[std::size_t(((r * N + c) * T + 3) * 3 + ch)] = 1.0f;
    const std::vector<float> m = measure(s, time, lattice, N, N);
    double sum = 0.0, n = 0.0;
    for (int r = 1; r < N; r += 3)
        for (int c = 1; c < N; c += 3)
            for (const auto& [dr, dc] : {std::array<int, 2>{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
                const int rr = r + dr, cc = c + dc;
                if (rr >= N || cc >= N) continue;
                for (int ch = 0; ch < 3; ++ch) sum += m[std::size_t(((rr * N + cc) * T + 3) * 3 + ch)], n += 1;
            }
    EXPECT_NEAR(sum / n, x * 1000.0, 5 * std::sqrt(x * 1000.0 / n));  // 5 standard errors of a Poisson mean
}

TEST(SensorSpad, DeadPixelsCountNothing) {
    const int H = 20, W = 20, T = 16;
    const TimeAxis time = time_axis(T, 0.01);
    const std::vector<float> cube(std::size_t(H * W * T * 3), 1.0f);
    auto dead_set = [&](const json& extra) {
        // 1000 expected photons in every bin: a live pixel's bin is 0 with probability e^-1000.
        json block = spad(json::object());
        block["exposure"].update(extra);
        const std::vector<float> m = measure(sensor_from(block), time, cube, H, W, nullptr, 3);
        std::vector<int> dead;
        for (int p = 0; p < H * W; ++p) {
            const auto first = m.begin() + p * T * 3, last = first + T * 3;
            if (std::all_of(first, last, [](float v) { return v == 0.0f; })) {
                dead.push_back(p);
            } else {
                EXPECT_TRUE(std::none_of(first, last, [](float v) { return v == 0.0f; })) << "pixel " << p;
            }
        }
        return dead;
    };
    EXPECT_EQ(dead_set({{"dead_pixels", {{0, 1}, {19, 7}}}}), (std::vector<int>{1, 19 * W + 7}));
    // A fraction: exactly round(0.1 x 400) pixels, the same ones for the same seed, others for another.
    const std::vector<int> a = dead_set({{"dead_pixels", 0.1}});
    EXPECT_EQ(a.size(), 40u);
    EXPECT_EQ(dead_set({{"dead_pixels", 0.1}}), a);
    EXPECT_NE(dead_set({{"dead_pixels", 0.1}, {"seed", 6}}), a);
    EXPECT_EQ(dead_set({{"dead_pixels", 1.0}}).size(), std::size_t(H * W));
    // Outside the image (known only when the sensor is applied): an error that names the entry.
    const SensorSettings outside = parse_sensor_block(spad({{"dead_pixels", {{3, 4}, {20, 0}}}}).dump(), "s.json", "sensor");
    EXPECT_EQ(error_of([&] { measure(outside, time, cube, H, W); }),
              "s.json: sensor.exposure.dead_pixels[1]: row 20 is outside the image's 20 rows (0 to 19)");
    const SensorSettings right = parse_sensor_block(spad({{"dead_pixels", {{0, 25}}}}).dump(), "s.json", "sensor");
    EXPECT_EQ(error_of([&] { measure(right, time, cube, H, W); }),
              "s.json: sensor.exposure.dead_pixels[0]: column 25 is outside the image's 20 columns (0 to 19)");
}

TEST(SensorSpad, SameSeedGivesTheSameHistogramsForAnyThreadCount) {
    const int H = 12, W = 10, T = 48;
    const TimeAxis time = time_axis(T, 0.01);
    std::vector<float> cube(std::size_t(H * W * T * 3));
    for (std::size_t i = 0; i < cube.size(); ++i) cube[i] = float((i * 7919) % 101) / 101.0f;  // any fixed values
    json block = spad({{"jitter_fwhm", 0.02},
                       {"jitter_tail", {{"time_constant", 0.03}, {"fraction", 0.2}}},
                       {"dead_time", 0.1},
                       {"cycles", 2000},
                       {"afterpulsing", {{"probability", 0.05}, {"time_constant", 0.04}}},
                       {"ambient", 3e6},
                       {"dark_rate", 1e10},
                       {"crosstalk", 0.01},
                       {"dead_pixels", 0.05}});
    const std::vector<float> one = measure(sensor_from(block), time, cube, H, W, nullptr, 1);
    EXPECT_EQ(measure(sensor_from(block), time, cube, H, W, nullptr, 1), one) << "the same run twice";
    for (const int threads : {2, 3, 7}) EXPECT_EQ(measure(sensor_from(block), time, cube, H, W, nullptr, threads), one) << threads << " threads";
    block["exposure"]["seed"] = 6;
    EXPECT_NE(measure(sensor_from(block), time, cube, H, W), one) << "another seed gave the same counts";
}

TEST(SensorSpad, NeutralValuesOfTheNewKeysChangeNothing) {
    // Every new key at its neutral value gives the histograms of a block without them, bit for bit (the same
    // means, the same draws), whatever `cycles` is.
    const int H = 6, W = 7, T = 40;
    const TimeAxis time = time_axis(T, 0.01);
    std::vector<float> cube(std::size_t(H * W * T * 3));
    for (std::size_t i = 0; i < cube.size(); ++i) cube[i] = float((i * 104729) % 97) / 97.0f;
    const json plain = spad({{"jitter_fwhm", 0.02}, {"dark_rate", 1e9}});
    const json neutral = spad({{"jitter_fwhm", 0.02}, {"dark_rate", 1e9},
                               {"jitter_tail", {{"time_constant", 0.05}, {"fraction", 0}}},
                               {"dead_time", 0}, {"cycles", 123}, {"ambient", 0}, {"crosstalk", 0},
                               {"afterpulsing", {{"probability", 0}, {"time_constant", 0}}},
                               {"dead_pixels", json::array()}});
    EXPECT_EQ(measure(sensor_from(neutral), time, cube, H, W), measure(sensor_from(plain), time, cube, H, W));
}

TEST(SensorSpad, BadValuesNameTheirJsonPath) {
    const TimeAxis time = time_axis(100, 0.01);
    auto error = [&](const json& extra) {
        return error_of([&] { validate_sensor(parse_sensor_block(spad(extra).dump(), "s.json", "sensor"), time); });
    };
    EXPECT_EQ(error({{"dead_time", -1}}), "s.json: sensor.exposure.dead_time: must be >= 0");
    EXPECT_EQ(error({{"cycles", 0.5}}), "s.json: sensor.exposure.cycles: must be in [1, 1e15] laser repetitions");
    EXPECT_EQ(error({{"crosstalk", 1.5}}), "s.json: sensor.exposure.crosstalk: must be in [0, 1]");
    EXPECT_EQ(error({{"ambient", -2}}), "s.json: sensor.exposure.ambient: must be >= 0");
    EXPECT_EQ(error({{"afterpulsing", {{"probability", -0.1}, {"time_constant", 1}}}}),
              "s.json: sensor.exposure.afterpulsing.probability: must be in [0, 1]");
    EXPECT_EQ(error({{"afterpulsing", {{"probability", 0.1}, {"time_constant", 0}}}}),
              "s.json: sensor.exposure.afterpulsing.time_constant: must be > 0");
    EXPECT_EQ(error({{"jitter_tail", {{"time_constant", 0.1}, {"fraction", 2}}}}),
              "s.json: sensor.exposure.jitter_tail.fraction: must be in [0, 1]");
    EXPECT_EQ(error({{"dead_pixels", 1.5}}), "s.json: sensor.exposure.dead_pixels: must be in [0, 1]");
    EXPECT_EQ(error({{"dead_pixels", {{0, -1}}}}), "s.json: sensor.exposure.dead_pixels[0][1]: must be >= 0");
    EXPECT_EQ(error({{"dead_pixels", {{0, 1, 2}}}}), "s.json: sensor.exposure.dead_pixels[0]: expected [row, column]");
    EXPECT_EQ(error({{"dead_pixels", "all"}}),
              "s.json: sensor.exposure.dead_pixels: expected a fraction of the pixels (a number in [0, 1]) or a list of [row, column]");
    // A tail that reaches beyond 64 windows (20 time constants and one more).
    EXPECT_NE(error({{"jitter_tail", {{"time_constant", 10}, {"fraction", 0.1}}}}).find("sensor.exposure.jitter_tail.time_constant: reaches 210"),
              std::string::npos);
    // Unknown keys stay errors, inside the new objects too; their keys are required.
    EXPECT_NE(error({{"dead_tme", 1}}).find("sensor.exposure.dead_tme: unknown key"), std::string::npos);
    EXPECT_NE(error({{"afterpulsing", {{"probability", 0.1}, {"tau", 1}}}}).find("afterpulsing.tau: unknown key"), std::string::npos);
    EXPECT_NE(error({{"jitter_tail", {{"fraction", 0.1}}}}).find("sensor.exposure.jitter_tail"), std::string::npos);
    // The SPAD's keys belong to the SPAD.
    const json gates = {{"exposure", {{"type", "gates"}, {"start", 0}, {"width", 0.1}, {"step", 0.1}, {"count", 2}, {"dead_time", 1}}}};
    EXPECT_NE(error_of([&] { sensor_from(gates); }).find("exposure.dead_time: unknown key"), std::string::npos);
}

}  // namespace
}  // namespace tprf
