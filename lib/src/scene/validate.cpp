#include "tprf/scene/validate.h"

#include "tprf/core/error.h"
#include "tprf/core/time_kernel.h"
#include "open_reason.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <system_error>
#include <variant>

namespace tprf {
namespace {

namespace fs = std::filesystem;

// Relative tolerance below which two directions count as parallel: nearer than this, a rectangle or a
// camera frame is numerically meaningless although not exactly degenerate.
constexpr double kParallelTol = 1e-9;
// How far from 1 a laser's direction may be: a parser normalises it (to a few ulps); a hand-built
// scene that forgot to would give every laser spot a wrong time.
constexpr double kUnitTol = 1e-9;
// A pulse or jitter may reach at most this many render windows away from t = 0: beyond, its kernel
// and the convolved profile would be sized by the pulse rather than by the render.
constexpr double kMaxReachInWindows = 64.0;
// Bounds that keep a SPAD's expected counts finite whatever the signal's scale.
constexpr double kMaxPhotons = 1e20;
constexpr double kMaxDarkRate = 1e30;
// A SPAD's laser repetitions over one acquisition: at least one, and few enough that a bin's expected counts
// per cycle stay far above the smallest double.
constexpr double kMaxCycles = 1e15;

bool parallel(const Vec3& a, const Vec3& b) { return a.cross(b).norm() <= kParallelTol * a.norm() * b.norm(); }

// A place in the input, named as the JSON parser names it: the file and the JSON path.
struct At {
    const fs::path& file;
    std::string path;

    [[noreturn]] void fail(std::string_view what) const { fail_input(file, path, what); }
    At key(std::string_view k) const { return {file, path.empty() ? std::string(k) : path + "." + std::string(k)}; }
    At index(std::size_t i) const { return {file, path + "[" + std::to_string(i) + "]"}; }
};

// The parser's own words for the same mistakes (json_node.cpp), so that both routes read alike.
void finite(double v, const At& at) {
    if (!std::isfinite(v)) at.fail("expected a finite number");
}

// A triple (position, direction or colour), each element named as its JSON array element.
template <class Triple>
void finite3(const Triple& v, const At& at) {
    for (Eigen::Index i = 0; i < 3; ++i) finite(v[i], at.index(std::size_t(i)));
}

void positive(double v, const At& at) {
    finite(v, at);
    if (v <= 0.0) at.fail("must be > 0");
}

void positive(int v, const At& at) {
    if (v <= 0) at.fail("must be > 0");
}

void non_negative(double v, const At& at) {
    finite(v, at);
    if (v < 0.0) at.fail("must be >= 0");
}

void non_negative(const Rgb& c, const At& at) {
    finite3(c, at);
    if ((c < 0.0).any()) at.fail("must be >= 0");
}

void non_zero(const Vec3& v, const At& at) {
    finite3(v, at);
    if (v.norm() == 0.0) at.fail("has zero length");
}

// Every point of the image must have its undistorted ray: the distortion may not fold the image over
// (as a strong k1 < 0 does beyond some radius). Probed at every pixel corner along the border and the
// two centre lines, where a radial or tangential fold first shows.
void check_distortion(const Camera& c, const At& at) {
    const Distortion& d = c.distortion;
    finite(d.k1, at.key("k1"));
    finite(d.k2, at.key("k2"));
    finite(d.k3, at.key("k3"));
    finite(d.p1, at.key("p1"));
    finite(d.p2, at.key("p2"));
    if (d.none() || c.width <= 0 || c.height <= 0) return;
    const Intrinsics k = c.pinhole();
    const auto probe = [&](int column, int row) {  // the corner at the top left of pixel (column, row)
        const Vec2 distorted((column - 0.5 - k.cx) / k.fx, (row - 0.5 - k.cy) / k.fy);
        if (d.undo(distorted)) return;
        char where[160];
        std::snprintf(where, sizeof where,
                      "folds the image over at pixel corner (%d, %d): no ray of the lens maps there (a smaller |k1|, "
                      "|k2| or |k3|, or a narrower image)", column, row);
        at.fail(where);
    };
    for (int column = 0; column <= c.width; ++column)
        for (const int row : {0, c.height / 2, c.height}) probe(column, row);
    for (int row = 0; row <= c.height; ++row)
        for (const int column : {0, c.width / 2, c.width}) probe(column, row);
}

void check_camera(const Camera& c, const At& at) {
    finite3(c.position, at.key("position"));
    const At look_at = at.key("look_at");
    finite3(c.look_at, look_at);
    if (c.look_at == c.position) look_at.fail("equals camera.position, so there is no view direction");
    const At up = at.key("up");
    non_zero(c.up, up);
    if (parallel(c.up, c.look_at - c.position)) up.fail("is parallel to the view direction (look_at - position)");
    if (c.intrinsics) {
        const At k = at.key("intrinsics");
        positive(c.intrinsics->fx, k.key("fx"));
        positive(c.intrinsics->fy, k.key("fy"));
        finite(c.intrinsics->cx, k.key("cx"));
        finite(c.intrinsics->cy, k.key("cy"));
    } else {
        const At fov = at.key("fov");
        finite(c.fov_deg, fov);
        if (c.fov_deg <= 0.0 || c.fov_deg >= 180.0) fov.fail("must be in (0, 180) degrees");
    }
    positive(c.width, at.key("width"));
    positive(c.height, at.key("height"));
    positive(c.spp, at.key("spp"));
    check_distortion(c, at.key("distortion"));
}

void check_light(const Light& light, const At& at) {
    if (const auto* p = std::get_if<PointLight>(&light)) {
        finite3(p->position, at.key("position"));
        non_negative(p->intensity, at.key("intensity"));
        if (!p->spot) return;  // isotropic
        const At direction = at.key("direction");
        non_zero(p->direction, direction);
        if (std::abs(p->direction.norm() - 1.0) > kUnitTol) direction.fail("must be a unit vector");
        const At half = at.key("half_angle");
        finite(p->half_angle_deg, half);
        if (!(p->half_angle_deg > 0.0 && p->half_angle_deg < 180.0)) half.fail("must be in (0, 180) degrees");
        const At falloff = at.key("falloff");
        non_negative(p->falloff_deg, falloff);
        if (p->half_angle_deg + p->falloff_deg > 180.0)
            falloff.fail("with half_angle must be at most 180 degrees (the cone would pass the light's back)");
        return;
    }
    const Laser& l = std::get<Laser>(light);
    finite3(l.origin, at.key("origin"));
    const At direction = at.key("direction");
    non_zero(l.direction, direction);
    if (std::abs(l.direction.norm() - 1.0) > kUnitTol) direction.fail("must be a unit vector");
    non_negative(l.power, at.key("power"));
}

void check_rectangle(const RectangleShape& r, const At& at) {
    finite3(r.origin, at.key("origin"));
    const At u = at.key("u");
    const At v = at.key("v");
    finite3(r.u, u);
    finite3(r.v, v);
    non_zero(r.u, u);
    non_zero(r.v, v);
    if (parallel(r.u, r.v)) v.fail("is parallel to u, so the rectangle has no area");
}

// A missing mesh file as the scene file names it: a name relative to the scene file's folder (the
// parsers join the two) is given as written, with that folder in full, so that a user who ran tprf
// from elsewhere sees where it was looked for. "mesh file meshes/x.obj does not exist (relative to /a/b)".
std::string missing_mesh_message(const fs::path& p, const fs::path& scene_file) {
    const fs::path folder = scene_file.parent_path();
    auto b = p.begin();
    for (auto a = folder.begin(); a != folder.end(); ++a, ++b)
        if (b == p.end() || *a != *b) return "mesh file " + p.string() + " does not exist";
    if (folder.empty() && p.is_absolute()) return "mesh file " + p.string() + " does not exist";
    fs::path written;
    for (; b != p.end(); ++b) written /= *b;
    std::error_code ec;
    fs::path full = folder.empty() ? fs::current_path(ec) : fs::absolute(folder, ec);
    full = full.lexically_normal();
    if (!full.has_filename() && full.has_relative_path()) full = full.parent_path();
    return "mesh file " + written.string() + " does not exist (relative to " + full.string() + ")";
}

// The mesh is read by a later stage; checking here reports a bad path with the scene's other errors.
void check_mesh_file(const fs::path& p, const At& at) {
    if (p.empty()) at.fail("is empty");
    std::error_code ec;
    const fs::file_status st = fs::status(p, ec);
    if (!fs::exists(st)) at.fail(missing_mesh_message(p, at.file));
    if (!fs::is_regular_file(st)) at.fail("mesh file " + p.string() + " is not a regular file");
    errno = 0;
    const std::ifstream probe(p, std::ios::binary);
    if (!probe) at.fail("cannot read mesh file " + p.string() + open_reason(errno));
}

// `at` names the matrix as the scene file's `transform.matrix` (16 numbers, row-major).
void check_transform(const Eigen::Matrix4d& m, const At& at) {
    for (Eigen::Index r = 0; r < 4; ++r)
        for (Eigen::Index c = 0; c < 4; ++c) finite(m(r, c), at.index(std::size_t(4 * r + c)));
    if (m.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) at.fail("last row must be 0 0 0 1 (an affine transform)");
    // Scale-relative, so that a tiny but uniform scale is not taken for a singular matrix.
    const Eigen::Matrix3d a = m.topLeftCorner<3, 3>();
    const double size = a.norm() / std::sqrt(3.0);
    if (!(std::abs(a.determinant()) > 1e-12 * size * size * size)) at.fail("is singular");
}

// A specular part: finite, in [0, 1] per channel.
void check_specular_part(const Rgb& value, const At& at) {
    finite3(value, at);
    if ((value < 0.0).any() || (value > 1.0).any()) at.fail("must be in [0, 1]");
}

// A glossy or plastic material: its roughness, a glossy one's reflectance beside its albedo, a
// plastic's index.
void check_glossy(const Object& o, const At& material) {
    const Material& m = o.material;
    const At roughness = material.key("roughness");
    finite(m.roughness, roughness);
    if (!(m.roughness >= 0.01 && m.roughness <= 1.0))
        roughness.fail("must be in [0.01, 1] (GGX alpha; below 0.01 use a mirror)");
    if (m.type == MaterialType::Plastic) {
        const At ior = material.key("ior");
        finite(m.ior, ior);
        if (!(m.ior > 1.0)) ior.fail("must be > 1 (the coat's refractive index against air)");
        return;
    }
    check_specular_part(m.reflectance, material.key("reflectance"));
    const Rgb sum = m.reflectance + o.albedo;
    if ((sum > 1.0 + 1e-12).any())
        material.fail("reflectance + albedo is " + std::to_string(sum.maxCoeff()) +
                      "; it must be at most 1 (energy is not created)");
}

void check_material(const Object& o, const At& at) {
    const Material& m = o.material;
    if (m.glossy()) check_glossy(o, at.key("material"));
    if (!m.specular()) return;
    const At material = at.key("material");
    check_specular_part(m.reflectance, material.key("reflectance"));
    if (m.type == MaterialType::Glass) {
        check_specular_part(m.transmittance, material.key("transmittance"));
        // Light crossing glass keeps its colour: every link, shadow and camera ray passes one number.
        if (m.transmittance.maxCoeff() != m.transmittance.minCoeff())
            material.key("transmittance").fail(
                "must be grey (one number, or three equal ones): tinted transmittance is not supported (a tinted "
                "reflectance is)");
    }
    else if (!(m.transmittance == 0.0).all()) material.key("transmittance").fail("only glass transmits");
    const Rgb sum = m.reflectance + m.transmittance + o.albedo;
    if ((sum > 1.0 + 1e-12).any())
        material.fail("reflectance + transmittance + albedo is " + std::to_string(sum.maxCoeff()) +
                      "; it must be at most 1 (energy is not created)");
}

void check_object(const Object& o, const At& at) {
    if (const auto* r = std::get_if<RectangleShape>(&o.shape)) {
        check_rectangle(*r, at);
    } else {
        const MeshShape& m = std::get<MeshShape>(o.shape);
        check_mesh_file(m.file, at.key("file"));
        check_transform(m.transform, at.key("transform").key("matrix"));
    }
    const At albedo = at.key("albedo");
    finite3(o.albedo, albedo);
    if ((o.albedo < 0.0).any() || (o.albedo > 1.0).any()) albedo.fail("must be in [0, 1]");
    non_negative(o.emission, at.key("emission"));
    check_material(o, at);
}

// A table pulse as the parser leaves it after reading its CSV (which names lines; a hand-built table
// has rows).
void check_pulse_table(const SensorPulse& p, const At& at) {
    const std::vector<double>& t = p.table_time;
    const std::vector<double>& v = p.table_value;
    if (t.size() != v.size()) at.fail("pulse table has " + std::to_string(t.size()) + " times but " +
                                      std::to_string(v.size()) + " values");
    if (t.size() < 2) at.fail("pulse table needs at least two rows");
    for (std::size_t i = 0; i < t.size(); ++i) {
        const std::string where = "pulse table, row " + std::to_string(i) + ": ";
        if (!std::isfinite(t[i]) || !std::isfinite(v[i])) at.fail(where + "expected finite numbers");
        if (v[i] < 0.0) at.fail(where + "value must be >= 0");
        if (i > 0 && t[i] <= t[i - 1]) at.fail(where + "times must increase strictly");
    }
    // As the parser computes it: only the shape counts, so scaled to a peak of 1 the area cannot overflow.
    const double peak = *std::max_element(v.begin(), v.end());
    double area = 0.0;
    for (std::size_t i = 1; i < t.size(); ++i) area += 0.5 * (v[i] / peak + v[i - 1] / peak) * (t[i] - t[i - 1]);
    if (!(peak > 0.0) || !(area > 0.0) || !std::isfinite(area))
        at.fail("pulse table has zero area, or times too far apart to integrate");
}

void check_pulse(const SensorPulse& p, const At& at) {
    switch (p.shape) {
        case PulseShape::Delta: break;
        case PulseShape::Gaussian: positive(p.fwhm, at.key("fwhm")); break;
        case PulseShape::Box: positive(p.width, at.key("width")); break;
        case PulseShape::Table: check_pulse_table(p, at.key("file")); break;
    }
}

// Gates are expanded into windows by the parser; paths name the gates block's keys.
void check_gates(const Exposure& e, const At& at) {
    for (const auto& [start, width] : e.windows) {
        finite(start, at.key("start"));
        positive(width, at.key("width"));
    }
    const At count = at.key("count");
    if (e.windows.empty()) count.fail("must be > 0");
    if (e.windows.size() > std::size_t(kMaxSensorMeasurements))
        count.fail("more than " + std::to_string(kMaxSensorMeasurements) + " gates");
    for (const auto& [start, width] : e.windows)
        if (!std::isfinite(start + width)) at.fail("the last gate ends beyond the largest number");
}

void check_windows(const Exposure& e, const At& at) {
    const At list = at.key("windows");
    if (e.windows.empty()) list.fail("must hold at least one [start, width]");
    if (e.windows.size() > std::size_t(kMaxSensorMeasurements))
        list.fail("more than " + std::to_string(kMaxSensorMeasurements) + " windows");
    for (std::size_t k = 0; k < e.windows.size(); ++k) {
        const At w = list.index(k);
        finite(e.windows[k][0], w.index(0));
        positive(e.windows[k][1], w.index(1));
        if (!std::isfinite(e.windows[k][0] + e.windows[k][1])) w.fail("ends beyond the largest number");
    }
}

void check_amcw(const Exposure& e, const At& at) {
    if (e.frequencies_hz.empty()) {
        positive(e.frequency_mhz, at.key("frequency_mhz"));
    } else {
        const At list = at.key("frequencies");
        if (e.frequency_mhz != 0.0) at.fail("give either \"frequency_mhz\" or \"frequencies\", not both");
        if (e.frequencies_hz.size() > std::size_t(kMaxAmcwFrequencies))
            list.fail("more than " + std::to_string(kMaxAmcwFrequencies) + " frequencies");
        for (std::size_t k = 0; k < e.frequencies_hz.size(); ++k) {
            positive(e.frequencies_hz[k], list.index(k));
            for (std::size_t j = 0; j < k; ++j)
                if (e.frequencies_hz[j] == e.frequencies_hz[k]) list.index(k).fail("repeats an earlier frequency");
        }
    }
    const At photons = at.key("photons");
    non_negative(e.amcw_photons, photons);
    if (e.amcw_photons > kMaxPhotons) photons.fail("must be at most 1e20 electrons per unit of signal");
    const At ambient = at.key("ambient");
    non_negative(e.amcw_ambient, ambient);
    if (e.amcw_ambient > kMaxPhotons) ambient.fail("must be at most 1e20 electrons per sample");
    if (e.amcw_ambient > 0.0 && e.amcw_photons == 0.0)
        ambient.fail("needs \"photons\" (ambient light is counted in electrons, as the signal is with photons)");
    if (e.adc_bits < 0 || e.adc_bits > 24) at.key("adc_bits").fail("must be an integer in [0, 24] (0: not quantised)");
    const At phases = at.key("phases_deg");
    const std::size_t count = e.phases_deg.size();
    for (std::size_t k = 0; k < count; ++k) finite(e.phases_deg[k], phases.index(k));
    if (count * e.amcw_frequencies_hz().size() > std::size_t(kMaxSensorMeasurements)) phases.fail("too many phases");
    // The phase of the fit is determined only when cos and sin are both sampled.
    const Eigen::Matrix3d m = phase_normal_matrix(e.phases_deg);
    if (count < 3 || std::abs(m.determinant()) < 1e-9 * std::pow(double(count), 3))
        phases.fail("needs at least 3 phases that determine a cosine's phase (e.g. [0, 90, 180, 270])");
}

void check_spad(const Exposure& e, const At& at) {
    const At photons = at.key("photons");
    positive(e.photons, photons);
    if (e.photons > kMaxPhotons) photons.fail("must be at most 1e20 photons per unit of signal");
    non_negative(e.jitter_fwhm, at.key("jitter_fwhm"));
    const At dark = at.key("dark_rate");
    non_negative(e.dark_rate, dark);
    if (e.dark_rate > kMaxDarkRate) dark.fail("must be at most 1e30 counts per second");
}

// A probability or a share.
void unit_interval(double v, const At& at) {
    finite(v, at);
    if (v < 0.0 || v > 1.0) at.fail("must be in [0, 1]");
}

// An exponential's 1/e time: > 0 wherever the exponential has weight.
void time_constant(double tau, double weight, const At& at) {
    non_negative(tau, at);
    if (weight > 0.0 && tau == 0.0) at.fail("must be > 0");
}

// A SPAD's detector effects (docs/sensor.md, "SPAD"). A dead pixel's place is checked against the image
// when the sensor is applied, where the image's size is known.
void check_spad_detector(const Exposure& e, const At& at) {
    const At tail = at.key("jitter_tail");
    unit_interval(e.jitter_tail.fraction, tail.key("fraction"));
    time_constant(e.jitter_tail.time_constant, e.jitter_tail.fraction, tail.key("time_constant"));
    non_negative(e.dead_time, at.key("dead_time"));
    const At cycles = at.key("cycles");
    finite(e.cycles, cycles);
    if (e.cycles < 1.0 || e.cycles > kMaxCycles) cycles.fail("must be in [1, 1e15] laser repetitions");
    const At after = at.key("afterpulsing");
    unit_interval(e.afterpulsing.probability, after.key("probability"));
    time_constant(e.afterpulsing.time_constant, e.afterpulsing.probability, after.key("time_constant"));
    const At ambient = at.key("ambient");
    non_negative(e.ambient, ambient);
    if (e.ambient > kMaxDarkRate) ambient.fail("must be at most 1e30 counts per second");
    unit_interval(e.crosstalk, at.key("crosstalk"));
    const At dead = at.key("dead_pixels");
    unit_interval(e.dead_fraction, dead);
    for (std::size_t i = 0; i < e.dead_pixels.size(); ++i)
        for (std::size_t j = 0; j < 2; ++j)
            if (e.dead_pixels[i][j] < 0) dead.index(i).index(j).fail("must be >= 0");
}

void check_sensor_block(const SensorSettings& s, const At& at) {
    check_pulse(s.pulse, at.key("pulse"));
    const At exposure = at.key("exposure");
    switch (s.exposure.type) {
        case ExposureType::Gates: check_gates(s.exposure, exposure); break;
        case ExposureType::Windows: check_windows(s.exposure, exposure); break;
        case ExposureType::Amcw: check_amcw(s.exposure, exposure); break;
        case ExposureType::Spad:
            check_spad(s.exposure, exposure);
            check_spad_detector(s.exposure, exposure);
            break;
    }
    const At noise = at.key("noise");
    if (s.exposure.type == ExposureType::Spad && s.noise.sigma != 0.0)
        noise.fail("a SPAD counts photons, whose noise is Poisson: leave out \"noise\"");
    non_negative(s.noise.sigma, noise.key("sigma"));
}

// The pulse (and jitter) reach no further than kMaxReachInWindows windows, and some gate or window can
// receive light. Assumes a checked block and time axis.
void check_sensor_against_time(const SensorSettings& s, const TimeAxis& time, const At& at) {
    const double limit = kMaxReachInWindows * time.bins * time.bin_width;
    auto check_reach = [&](double reach, const At& where) {
        if (reach <= limit) return;
        std::ostringstream os;
        os << "reaches " << reach << " from t = 0, more than " << kMaxReachInWindows
           << " times the render's window (" << time.bins * time.bin_width << "): render a longer window";
        where.fail(os.str());
    };
    const At pulse = at.key("pulse");
    switch (s.pulse.shape) {
        case PulseShape::Delta: break;
        case PulseShape::Gaussian: check_reach(kGaussianReach * s.pulse.fwhm / kFwhmPerSigma, pulse.key("fwhm")); break;
        case PulseShape::Box: check_reach(0.5 * s.pulse.width, pulse.key("width")); break;
        case PulseShape::Table:
            check_reach(std::max(std::abs(s.pulse.table_time.front()), std::abs(s.pulse.table_time.back())),
                        pulse.key("file"));
            break;
    }
    if (s.exposure.type == ExposureType::Amcw) {
        // The depth tries every wrap of the lowest frequency that fits in the window: a bounded number.
        const std::vector<double> f = s.exposure.amcw_frequencies_hz();
        const double lowest = *std::min_element(f.begin(), f.end());
        const double window_m = 0.5 * time.to_metres(time.end());
        const double wraps = window_m / (0.5 * kSpeedOfLight / lowest);
        if (!(wraps <= kMaxAmcwCandidates)) {
            std::ostringstream os;
            os << "the lowest frequency, " << lowest << " Hz, wraps every " << 0.5 * kSpeedOfLight / lowest
               << " m of depth: " << wraps << " times over the window's " << window_m
               << " m, more than " << kMaxAmcwCandidates << " (frequencies are in Hz)";
            at.key("exposure").key(s.exposure.frequencies_hz.empty() ? "frequency_mhz" : "frequencies").fail(os.str());
        }
    }
    if (s.exposure.type == ExposureType::Spad) {
        check_reach(kGaussianReach * s.exposure.jitter_fwhm / kFwhmPerSigma, at.key("exposure").key("jitter_fwhm"));
        check_reach(jitter_reach(s.exposure), at.key("exposure").key("jitter_tail").key("time_constant"));
    }
    if (s.exposure.type != ExposureType::Gates && s.exposure.type != ExposureType::Windows) return;
    const TimeKernel k = pulse_kernel(s.pulse, time.bin_width);
    const double reach_lo = time.start + k.first * k.step;
    const double reach_hi = time.start + time.bins * time.bin_width + (k.first + double(k.mass.size())) * k.step;
    for (const auto& [start, width] : s.exposure.windows)
        if (start < reach_hi && start + width > reach_lo) return;
    std::ostringstream os;
    os << "every " << (s.exposure.type == ExposureType::Gates ? "gate" : "window")
       << " lies outside the render's time window [" << time.start << ", "
       << time.start + time.bins * time.bin_width << ") and the pulse's reach: it would measure nothing";
    at.key("exposure").fail(os.str());
}

// A capture's grids must be real grids; whether their points lie on a surface is the capture stage's
// question (imaging/capture_points.h), which needs the patches.
void check_grid(const CaptureGrid& g, const At& at) {
    check_rectangle({g.origin, g.u, g.v}, at);
    positive(g.nu, at.key("nu"));
    positive(g.nv, at.key("nv"));
    // Beyond this a capture's H alone would not fit any memory: 2^24 points per grid (4096 x 4096).
    constexpr std::size_t kMaxGridPoints = std::size_t(1) << 24;
    if (g.size() > kMaxGridPoints) at.fail("has " + std::to_string(g.size()) + " points; at most 16,777,216 (4096 x 4096)");
}

void check_capture(const Capture& c, const At& at) {
    finite3(c.laser_position, at.key("laser").key("position"));
    non_negative(c.laser_power, at.key("laser").key("power"));
    finite3(c.sensor_position, at.key("sensor").key("position"));
    const bool exhaustive = c.type == CaptureType::Exhaustive;
    check_grid(c.laser_grid, at.key(c.laser_grid_key));
    if (exhaustive) check_grid(c.sensor_grid, at.key(c.sensor_grid_key));
    if (c.max_bounces < -1 || c.max_bounces == 0 || c.max_bounces == 1)
        at.key("max_bounces").fail("must be >= 2 (3: laser spot -> hidden surface -> sensor point), or null for every bounce");
    if (c.march_bin_factor < 1 || c.march_bin_factor > Capture::kMaxMarchBinFactor)
        at.key("march_bin_factor").fail("must be an integer in [1, " + std::to_string(Capture::kMaxMarchBinFactor) +
                                        "] (1: the march of orders 4 and up on the scene's bins)");
    if (c.march_grid_step < 1 || c.march_grid_step > Capture::kMaxMarchGridStep)
        at.key("march_grid_step").fail("must be an integer in [1, " + std::to_string(Capture::kMaxMarchGridStep) +
                                       "] (1: the later bounces marched at every grid point)");
    if (c.march_grid_step > 1 && exhaustive)
        at.key("march_grid_step").fail("must be 1 for an exhaustive capture (it moves a confocal scan's later light between its points)");
}

void check_objects(const Scene& scene, const At& root) {
    const At objects = root.key("objects");
    if (scene.objects.empty()) objects.fail("must hold at least one object");
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
        const Object& o = scene.objects[i];
        check_object(o, o.json_path.empty() ? objects.index(i) : At{scene.file, o.json_path});
    }
}

// `patches` and `solver`: 0 and -1 are the Scene's "absent" (a parser rejects them written out).
void check_settings(const Scene& scene, const At& root) {
    const At max_edge = root.key("patches").key("max_edge");
    finite(scene.max_edge, max_edge);
    if (scene.max_edge < 0.0) max_edge.fail("must be > 0");
    const At tolerance = root.key("links").key("tolerance");
    finite(scene.links.tolerance, tolerance);
    if (!(scene.links.tolerance > 0.0)) tolerance.fail("must be > 0");
    if (scene.links.tolerance >= 1.0) tolerance.fail("must be < 1 (a form-factor error; 0.001 is a good start)");
    const At time_bins = root.key("links").key("time_bins");
    finite(scene.links.time_bins, time_bins);
    if (scene.links.time_bins < 0.0) time_bins.fail("must be >= 0 (0 turns the timing criterion off)");
    if (scene.links.spread_pieces < 0 || scene.links.spread_pieces > kMaxSpreadPieces)
        root.key("links").key("spread_pieces").fail("must be an integer in [0, " + std::to_string(kMaxSpreadPieces) +
                                                    "] (0: each patch link at its centroid delay)");
    if (scene.links.glossy_resolution != kGlossyAuto &&
        (scene.links.glossy_resolution < 0 || scene.links.glossy_resolution > kMaxGlossyResolution))
        root.key("links").key("glossy_resolution").fail(
            "must be \"auto\" or an integer in [0, " + std::to_string(kMaxGlossyResolution) +
            "] (rings of a glossy patch's directional cells, 4 R^2 cells; 0: glossy patches pass light on as Lambertian)");
    if (scene.solver.max_bounces < -1) root.key("solver").key("max_bounces").fail("must be >= 0");
    if (scene.solver.max_specular < 0 || scene.solver.max_specular > 16)
        root.key("solver").key("max_specular").fail("must be in [0, 16]");
}

}  // namespace

void validate_time(const TimeAxis& time, const fs::path& file, std::string_view json_path) {
    const At at{file, std::string(json_path)};
    positive(time.bins, at.key("bins"));
    positive(time.bin_width, at.key("bin_width"));
    finite(time.start, at.key("start"));
}

void validate(const Scene& scene) {
    const At root{scene.file, ""};
    validate_time(scene.time, scene.file, "time");
    if (scene.camera) check_camera(*scene.camera, root.key("camera"));
    const At lights = root.key("lights");
    for (std::size_t i = 0; i < scene.lights.size(); ++i) check_light(scene.lights[i], lights.index(i));
    check_objects(scene, root);
    check_settings(scene, root);
    if (scene.capture) {
        const At capture{scene.file, scene.capture->json_path};
        check_capture(*scene.capture, capture);
        if (scene.capture->march_bin_factor > 1 && scene.camera)
            capture.key("march_bin_factor").fail("must be 1 in a scene with a camera (the camera's links are marched on "
                                                 "the scene's bins): render the capture from a scene without one");
    }
    if (!scene.sensor) return;
    const SensorSettings& s = *scene.sensor;
    const At sensor{s.file.empty() ? scene.file : s.file, s.json_path.empty() ? "sensor" : s.json_path};
    check_sensor_block(s, sensor);
    check_sensor_against_time(s, scene.time, sensor);
}

void validate_sensor(const SensorSettings& sensor) { check_sensor_block(sensor, At{sensor.file, sensor.json_path}); }

void validate_sensor(const SensorSettings& sensor, const TimeAxis& time) {
    const At at{sensor.file, sensor.json_path};
    check_sensor_block(sensor, at);
    check_sensor_against_time(sensor, time, at);
}

}  // namespace tprf
