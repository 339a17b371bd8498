#include "tprf/sensor.h"

#include "tprf/error.h"
#include "tprf/geometry.h"
#include "tprf/json_node.h"
#include "tprf/plot.h"

#include <Eigen/Dense>
#include <omp.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdlib>
#include <complex>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <string>

namespace tprf {

namespace fs = std::filesystem;

namespace {

constexpr double kFwhmPerSigma = 2.3548200450309493;  // 2 sqrt(2 ln 2)
// A Gaussian is cut at 6 sigma: the mass beyond (2e-9) is below float precision of any bin.
constexpr double kGaussianReach = 6.0;
// Kernel steps per bin and per pulse width: fine enough that a pulse's shape within a bin is resolved.
constexpr double kStepsPerFeature = 16.0;
// Upper bound on kernel points, so that a pulse table spanning millions of bins stays tractable.
constexpr double kMaxKernelPoints = 65536.0;
// A pulse or jitter may reach at most this many render windows away from t = 0: beyond, its kernel
// and the convolved profile would be sized by the pulse rather than by the render.
constexpr double kMaxReachInWindows = 64.0;
constexpr double kMaxPoissonMean = 1e15;
// Bounds that keep a SPAD's expected counts finite whatever the signal's scale.
constexpr double kMaxPhotons = 1e20;
constexpr double kMaxDarkRate = 1e30;
// Point pairs of a pulse-jitter convolution beyond which its grid is made coarser.
constexpr double kMaxConvolutionPairs = 1e8;
// Measurements per pixel beyond which the measurements alone would dwarf any render.
constexpr int kMaxMeasurements = 1 << 20;

std::uint64_t seed_value(const JsonNode& n) {
    const double v = n.number();
    if (v < 0.0 || v != std::floor(v) || v > 9007199254740992.0) n.fail("must be an integer in [0, 2^53]");
    return static_cast<std::uint64_t>(v);
}

// A table pulse: "time,value" rows (a header row, blank lines and '#' comments are skipped).
void read_pulse_table(const JsonNode& node, SensorPulse& pulse) {
    const std::string name = node.string();
    if (name.empty()) node.fail("is empty");
    fs::path path(name);
    if (path.is_relative()) path = node.file.parent_path() / path;
    std::error_code ec;
    if (fs::is_directory(path, ec)) node.fail("pulse table " + path.string() + " is a directory");
    std::ifstream in(path);
    if (!in) node.fail("cannot read pulse table " + path.string());
    std::string line;
    int line_no = 0;
    bool first_row = true;
    while (std::getline(in, line)) {
        ++line_no;
        const std::size_t begin = line.find_first_not_of(" \t\r");
        if (begin == std::string::npos || line[begin] == '#') continue;
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream row(line);
        std::string first_field;
        row >> first_field;
        char* end = nullptr;
        std::strtod(first_field.c_str(), &end);
        // Only a first row that does not start with a number is a header: a malformed data row is an error.
        if (first_row && (end == first_field.c_str() || *end != '\0')) {
            first_row = false;
            continue;
        }
        first_row = false;
        row.clear();
        row.str(line);
        double t = 0.0, v = 0.0;
        std::string rest;
        const std::string where = "pulse table " + path.string() + ", line " + std::to_string(line_no) + ": ";
        if (!(row >> t >> v) || (row >> rest)) node.fail(where + "expected two finite numbers \"time,value\"");
        if (!std::isfinite(t) || !std::isfinite(v)) node.fail(where + "expected finite numbers");
        if (v < 0.0) node.fail(where + "value must be >= 0");
        if (!pulse.table_time.empty() && t <= pulse.table_time.back())
            node.fail(where + "times must increase strictly");
        pulse.table_time.push_back(t);
        pulse.table_value.push_back(v);
    }
    if (pulse.table_time.size() < 2) node.fail("pulse table " + path.string() + " needs at least two rows");
    // Only the shape matters (it is normalised to unit area): scaled to a peak of 1, values near the
    // largest double cannot overflow the area.
    const double peak = *std::max_element(pulse.table_value.begin(), pulse.table_value.end());
    if (peak > 0.0)
        for (double& v : pulse.table_value) v /= peak;
    double area = 0.0;
    for (std::size_t i = 1; i < pulse.table_time.size(); ++i)
        area += 0.5 * (pulse.table_value[i] + pulse.table_value[i - 1]) * (pulse.table_time[i] - pulse.table_time[i - 1]);
    if (!(area > 0.0) || !std::isfinite(area))
        node.fail("pulse table " + path.string() + " has zero area, or times too far apart to integrate");
}

SensorPulse parse_pulse(const JsonNode& n) {
    SensorPulse p;
    const std::string shape = n.find("shape") ? n.child("shape").string() : "delta";
    if (shape == "delta") {
        n.check_keys({"shape"});
    } else if (shape == "gaussian") {
        n.check_keys({"shape", "fwhm"});
        p.shape = PulseShape::Gaussian;
        p.fwhm = n.child("fwhm").positive();
    } else if (shape == "box") {
        n.check_keys({"shape", "width"});
        p.shape = PulseShape::Box;
        p.width = n.child("width").positive();
    } else if (shape == "table") {
        n.check_keys({"shape", "file"});
        p.shape = PulseShape::Table;
        read_pulse_table(n.child("file"), p);
    } else {
        n.child("shape").fail("unknown pulse shape " + in_quotes(shape) +
                              " (expected \"delta\", \"gaussian\", \"box\" or \"table\")");
    }
    return p;
}

// The 3 x 3 normal matrix of the fit M(phi) = a + b cos(phi) + c sin(phi) over the phases.
Eigen::Matrix3d phase_normal_matrix(const std::vector<double>& phases_deg) {
    Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
    for (const double deg : phases_deg) {
        const double phi = deg * std::numbers::pi / 180.0;
        const Eigen::Vector3d row(1.0, std::cos(phi), std::sin(phi));
        m += row * row.transpose();
    }
    return m;
}

Exposure parse_exposure(const JsonNode& n) {
    Exposure e;
    const JsonNode type = n.child("type");
    const std::string name = type.string();
    if (name == "gates") {
        n.check_keys({"type", "start", "width", "step", "count"});
        e.type = ExposureType::Gates;
        const double start = n.child("start").number();
        const double width = n.child("width").positive();
        const double step = n.child("step").positive();
        const JsonNode count_node = n.child("count");
        const int count = count_node.positive_int();
        if (count > kMaxMeasurements) count_node.fail("more than " + std::to_string(kMaxMeasurements) + " gates");
        if (!std::isfinite(start + (count - 1) * step + width)) n.fail("the last gate ends beyond the largest number");
        for (int k = 0; k < count; ++k) e.windows.push_back({start + k * step, width});
    } else if (name == "windows") {
        n.check_keys({"type", "windows"});
        e.type = ExposureType::Windows;
        const JsonNode list = n.child("windows");
        const std::size_t count = list.array_size();
        if (count == 0) list.fail("must hold at least one [start, width]");
        if (count > std::size_t(kMaxMeasurements)) list.fail("more than " + std::to_string(kMaxMeasurements) + " windows");
        for (std::size_t k = 0; k < count; ++k) {
            const JsonNode w = list.at(k);
            if (w.array_size() != 2) w.fail("expected [start, width]");
            e.windows.push_back({w.at(0).number(), w.at(1).positive()});
            if (!std::isfinite(e.windows.back()[0] + e.windows.back()[1])) w.fail("ends beyond the largest number");
        }
    } else if (name == "amcw") {
        n.check_keys({"type", "frequency_mhz", "phases_deg"});
        e.type = ExposureType::Amcw;
        e.frequency_mhz = n.child("frequency_mhz").positive();
        if (const auto phases = n.find("phases_deg")) {
            const std::size_t count = phases->array_size();
            for (std::size_t k = 0; k < count; ++k) e.phases_deg.push_back(phases->at(k).number());
            if (count > std::size_t(kMaxMeasurements)) phases->fail("too many phases");
            // The phase of the fit is determined only when cos and sin are both sampled.
            const Eigen::Matrix3d m = phase_normal_matrix(e.phases_deg);
            if (count < 3 || std::abs(m.determinant()) < 1e-9 * std::pow(double(count), 3))
                phases->fail("needs at least 3 phases that determine a cosine's phase (e.g. [0, 90, 180, 270])");
        } else {
            e.phases_deg = {0.0, 90.0, 180.0, 270.0};
        }
    } else if (name == "spad") {
        n.check_keys({"type", "photons", "jitter_fwhm", "dark_rate", "seed"});
        e.type = ExposureType::Spad;
        const JsonNode photons = n.child("photons");
        e.photons = photons.positive();
        if (e.photons > kMaxPhotons) photons.fail("must be at most 1e20 photons per unit of signal");
        if (const auto jitter = n.find("jitter_fwhm")) e.jitter_fwhm = jitter->non_negative();
        if (const auto dark = n.find("dark_rate")) {
            e.dark_rate = dark->non_negative();
            if (e.dark_rate > kMaxDarkRate) dark->fail("must be at most 1e30 counts per second");
        }
        if (const auto seed = n.find("seed")) e.seed = seed_value(*seed);
    } else {
        type.fail("unknown exposure type " + in_quotes(name) +
                  " (expected \"gates\", \"windows\", \"amcw\" or \"spad\")");
    }
    return e;
}

// Adds `mass` at offset `t` to a kernel on the grid q * step, split between the two grid points
// around t so that the kernel's total and mean stay exact. The kernel's range must hold t.
void add_split(TimeKernel& k, double t, double mass) {
    const double x = t / k.step - k.first;
    const double lo = std::floor(x);
    const double f = x - lo;
    const std::size_t i = std::size_t(std::max(0.0, lo));
    k.mass[i] += mass * (1.0 - f);
    if (f > 0.0) k.mass[i + 1] += mass * f;
}

// An empty kernel of grid `step` that can hold offsets in [lo, hi].
TimeKernel kernel_range(double step, double lo, double hi) {
    TimeKernel k;
    k.step = step;
    k.first = int(std::floor(lo / step)) - 1;
    k.mass.assign(std::size_t(int(std::ceil(hi / step)) - k.first + 2), 0.0);
    return k;
}

void normalise(TimeKernel& k) {
    double total = 0.0;
    for (const double m : k.mass) total += m;
    TPRF_CHECK(std::isfinite(total) && total > 0.0);
    for (double& m : k.mass) m /= total;
}

// A centred Gaussian of full width `fwhm`; cell masses at q * step from the error function.
TimeKernel gaussian_kernel(double fwhm, double bin_width) {
    const double sigma = fwhm / kFwhmPerSigma;
    const double reach = kGaussianReach * sigma;
    const double step = std::max(std::min(bin_width, fwhm) / kStepsPerFeature, 2.0 * reach / kMaxKernelPoints);
    const int half = int(std::ceil(reach / step));
    TimeKernel k;
    k.step = step;
    k.first = -half;
    k.mass.resize(std::size_t(2 * half + 1));
    const double scale = 1.0 / (std::numbers::sqrt2 * sigma);
    for (int q = -half; q <= half; ++q)
        k.mass[std::size_t(q + half)] = 0.5 * (std::erf((q + 0.5) * step * scale) - std::erf((q - 0.5) * step * scale));
    normalise(k);
    return k;
}

TimeKernel table_kernel(const SensorPulse& p, double bin_width) {
    const double t0 = p.table_time.front(), t1 = p.table_time.back();
    const double span = t1 - t0;
    // Also no finer than the table's distance from t = 0 allows, so that grid indices fit an int.
    const double step = std::max({std::min(bin_width, span) / kStepsPerFeature, span / kMaxKernelPoints,
                                  std::max(std::abs(t0), std::abs(t1)) / kMaxKernelPoints});
    TimeKernel k = kernel_range(step, t0, t1);
    // Each segment in pieces no longer than a step; a piece's mass sits at its centroid, so that the
    // kernel's mean is the table's.
    for (std::size_t s = 1; s < p.table_time.size(); ++s) {
        const double a = p.table_time[s - 1], b = p.table_time[s];
        const double va = p.table_value[s - 1], vb = p.table_value[s];
        const int pieces = std::max(1, int(std::ceil((b - a) / k.step)));
        for (int j = 0; j < pieces; ++j) {
            const double x0 = a + (b - a) * j / pieces, x1 = a + (b - a) * (j + 1) / pieces;
            const double y0 = va + (vb - va) * (x0 - a) / (b - a), y1 = va + (vb - va) * (x1 - a) / (b - a);
            const double mass = 0.5 * (y0 + y1) * (x1 - x0);
            if (mass <= 0.0) continue;
            add_split(k, x0 + (x1 - x0) * (y0 + 2.0 * y1) / (3.0 * (y0 + y1)), mass);
        }
    }
    normalise(k);
    return k;
}

// `k` on a grid of `step`: each mass split between its two grid points, so total and mean are kept.
TimeKernel resample(const TimeKernel& k, double step) {
    TimeKernel out = kernel_range(step, k.first * k.step, (k.first + double(k.mass.size())) * k.step);
    for (std::size_t q = 0; q < k.mass.size(); ++q)
        if (k.mass[q] != 0.0) add_split(out, (k.first + double(q)) * k.step, k.mass[q]);
    return out;
}

// The distribution of the sum of two independent offsets (pulse and jitter): both put on one grid,
// fine enough for the finer of the two unless that would make the grid or the pairwise sum too large.
TimeKernel convolve(const TimeKernel& a, const TimeKernel& b) {
    const double ra = double(a.mass.size()) * a.step, rb = double(b.mass.size()) * b.step;
    const double reach = std::max(std::abs(a.first * a.step), std::abs((a.first + double(a.mass.size())) * a.step)) +
                         std::max(std::abs(b.first * b.step), std::abs((b.first + double(b.mass.size())) * b.step));
    const double step = std::max({std::min(a.step, b.step), reach / kMaxKernelPoints,
                                  std::sqrt(ra * rb / kMaxConvolutionPairs)});
    const TimeKernel ga = resample(a, step), gb = resample(b, step);
    TimeKernel k;
    k.step = step;
    k.first = ga.first + gb.first;
    k.mass.assign(ga.mass.size() + gb.mass.size() - 1, 0.0);
    for (std::size_t i = 0; i < ga.mass.size(); ++i) {
        if (ga.mass[i] == 0.0) continue;
        for (std::size_t j = 0; j < gb.mass.size(); ++j) k.mass[i + j] += ga.mass[i] * gb.mass[j];
    }
    return k;
}

// The kernel the exposure sees: the pulse, and for a SPAD its timing jitter too.
TimeKernel exposure_kernel(const SensorSettings& s, double bin_width) {
    TimeKernel k = pulse_kernel(s.pulse, bin_width);
    if (s.exposure.type == ExposureType::Spad && s.exposure.jitter_fwhm > 0.0)
        k = convolve(k, gaussian_kernel(s.exposure.jitter_fwhm, bin_width));
    return k;
}

// A bin index from a real position, clamped in floating point first, so that a window far outside the
// axis cannot overflow the conversion.
int bin_clamped(double x, int lo, int hi) { return int(std::clamp(x, double(lo), double(hi))); }

// Weights of the source bins for a box window [a, b): each bin's energy, spread evenly over the bin
// and shifted by every kernel offset, counted by its overlap with the window.
void box_window_weights(const TimeKernel& k, const TimeAxis& time, double a, double b, int& first,
                        std::vector<double>& w) {
    const double dt = time.bin_width;
    const double tau_lo = k.first * k.step, tau_hi = (k.first + double(k.mass.size())) * k.step;
    const int i0 = std::max(0, bin_clamped(std::floor((a - tau_hi - time.start) / dt), -2, time.bins) - 1);
    const int i1 = std::min(time.bins - 1, bin_clamped(std::ceil((b - tau_lo - time.start) / dt), -2, time.bins) + 1);
    first = i0;
    w.assign(i1 >= i0 ? std::size_t(i1 - i0 + 1) : 0, 0.0);
    for (std::size_t q = 0; q < k.mass.size(); ++q) {
        const double m = k.mass[q];
        if (m == 0.0) continue;
        const double tau = (k.first + double(q)) * k.step;
        const int lo = std::max(i0, bin_clamped(std::floor((a - tau - time.start) / dt), -2, time.bins) - 1);
        const int hi = std::min(i1, bin_clamped(std::ceil((b - tau - time.start) / dt), -2, time.bins));
        for (int i = lo; i <= hi; ++i) {
            const double s = time.start + i * dt + tau;
            const double overlap = std::min(b, s + dt) - std::max(a, s);
            if (overlap > 0.0) w[std::size_t(i - i0)] += m * overlap / dt;
        }
    }
    // Trim the zero ends so that the per-pixel loop touches only bins that matter.
    std::size_t lead = 0;
    while (lead < w.size() && w[lead] == 0.0) ++lead;
    std::size_t keep = w.size();
    while (keep > lead && w[keep - 1] == 0.0) --keep;
    w = std::vector<double>(w.begin() + std::ptrdiff_t(lead), w.begin() + std::ptrdiff_t(keep));
    first += int(lead);
}

// Angular frequency of the modulation per unit of the scene's time axis.
double omega_per_unit(const Exposure& e, const TimeAxis& time) {
    return 2.0 * std::numbers::pi * e.frequency_mhz * 1e6 * time.to_metres(1.0) / kSpeedOfLight;
}

// SplitMix64: decorrelated per-pixel seeds from one user seed, so that a pixel's noise does not
// depend on which thread draws it.
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t pixel) {
    std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (pixel + 1);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

}  // namespace

const char* exposure_name(ExposureType type) {
    switch (type) {
        case ExposureType::Gates: return "gates";
        case ExposureType::Windows: return "windows";
        case ExposureType::Amcw: return "amcw";
        case ExposureType::Spad: return "spad";
    }
    return "?";
}

SensorSettings parse_sensor(const JsonNode& n) {
    n.check_keys({"pulse", "exposure", "noise", "clamp"});
    SensorSettings s;
    s.file = n.file;
    s.json_path = n.path;
    if (const auto pulse = n.find("pulse")) s.pulse = parse_pulse(*pulse);
    s.exposure = parse_exposure(n.child("exposure"));
    if (const auto noise = n.find("noise")) {
        noise->check_keys({"sigma", "seed"});
        if (s.exposure.type == ExposureType::Spad)
            noise->fail("a SPAD counts photons, whose noise is Poisson: leave out \"noise\"");
        s.noise.sigma = noise->child("sigma").non_negative();
        if (const auto seed = noise->find("seed")) s.noise.seed = seed_value(*seed);
    }
    if (const auto clamp = n.find("clamp")) s.clamp = clamp->boolean();
    return s;
}

SensorSettings load_sensor(const fs::path& file) {
    const nlohmann::json root = read_json_file(file, "sensor file");
    const JsonNode top{root, "", file};
    top.expect_object();
    // A scene file (or any object with a "sensor" member) gives its block.
    if (root.contains("sensor")) return parse_sensor(top.child("sensor"));
    return parse_sensor(top);
}

void check_sensor(const SensorSettings& s, const TimeAxis& time) {
    const std::string root = s.json_path.empty() ? "" : s.json_path + ".";
    const double limit = kMaxReachInWindows * time.bins * time.bin_width;
    auto check_reach = [&](double reach, const std::string& path) {
        if (reach <= limit) return;
        std::ostringstream os;
        os << "reaches " << reach << " from t = 0, more than " << kMaxReachInWindows
           << " times the render's window (" << time.bins * time.bin_width << "): render a longer window";
        fail_input(s.file, root + path, os.str());
    };
    switch (s.pulse.shape) {
        case PulseShape::Delta: break;
        case PulseShape::Gaussian: check_reach(kGaussianReach * s.pulse.fwhm / kFwhmPerSigma, "pulse.fwhm"); break;
        case PulseShape::Box: check_reach(0.5 * s.pulse.width, "pulse.width"); break;
        case PulseShape::Table:
            check_reach(std::max(std::abs(s.pulse.table_time.front()), std::abs(s.pulse.table_time.back())), "pulse.file");
            break;
    }
    if (s.exposure.type == ExposureType::Spad)
        check_reach(kGaussianReach * s.exposure.jitter_fwhm / kFwhmPerSigma, "exposure.jitter_fwhm");
    if (s.exposure.type != ExposureType::Gates && s.exposure.type != ExposureType::Windows) return;
    const TimeKernel k = pulse_kernel(s.pulse, time.bin_width);
    const double reach_lo = time.start + k.first * k.step;
    const double reach_hi = time.start + time.bins * time.bin_width + (k.first + double(k.mass.size())) * k.step;
    for (const auto& [start, width] : s.exposure.windows)
        if (start < reach_hi && start + width > reach_lo) return;
    const std::string path = root + "exposure";
    std::ostringstream os;
    os << "every " << (s.exposure.type == ExposureType::Gates ? "gate" : "window")
       << " lies outside the render's time window [" << time.start << ", "
       << time.start + time.bins * time.bin_width << ") and the pulse's reach: it would measure nothing";
    fail_input(s.file, path, os.str());
}

int measurement_count(const SensorSettings& s, const TimeAxis& time) {
    switch (s.exposure.type) {
        case ExposureType::Gates:
        case ExposureType::Windows: return int(s.exposure.windows.size());
        case ExposureType::Amcw: return int(s.exposure.phases_deg.size());
        case ExposureType::Spad: return time.bins;
    }
    return 0;
}

TimeKernel pulse_kernel(const SensorPulse& p, double bin_width) {
    switch (p.shape) {
        case PulseShape::Delta: return TimeKernel{bin_width, 0, {1.0}};
        case PulseShape::Gaussian: return gaussian_kernel(p.fwhm, bin_width);
        case PulseShape::Box: {
            // Equal masses at the centres of n equal cells of [-w/2, w/2]: symmetric, so the mean is 0.
            const double step = std::max(std::min(bin_width, p.width) / kStepsPerFeature, p.width / kMaxKernelPoints);
            TimeKernel k = kernel_range(step, -0.5 * p.width, 0.5 * p.width);
            const int n = std::max(1, int(std::ceil(p.width / step)));
            for (int j = 0; j < n; ++j) add_split(k, -0.5 * p.width + (j + 0.5) * p.width / n, 1.0 / n);
            return k;
        }
        case PulseShape::Table: return table_kernel(p, bin_width);
    }
    throw InternalError("unknown pulse shape");
}

SensorWeights sensor_weights(const SensorSettings& s, const TimeAxis& time) {
    const TimeKernel k = exposure_kernel(s, time.bin_width);
    const Exposure& e = s.exposure;
    SensorWeights out;
    const int K = measurement_count(s, time);
    out.first.resize(std::size_t(K));
    out.weight.resize(std::size_t(K));
    if (e.type == ExposureType::Amcw) {
        // Exposure (1 + cos(w t - phi)) / 2, non-negative as a real pixel's sensitivity. Shifting by the
        // kernel multiplies the cosine's phasor by the kernel's characteristic function P(w); averaged over
        // a bin [a, a + dt) the cosine becomes Re(P e^{i(w (a + dt/2) - phi)}) sinc(w dt / 2), exactly,
        // and without the cancellation of a difference of sines when w dt is small.
        const double w = omega_per_unit(e, time);
        const double dt = time.bin_width;
        std::complex<double> P = 0.0;
        for (std::size_t q = 0; q < k.mass.size(); ++q) P += k.mass[q] * std::polar(1.0, w * (k.first + double(q)) * k.step);
        const double half = 0.5 * w * dt;
        const double sinc = half < 1e-4 ? 1.0 - half * half / 6.0 : std::sin(half) / half;
        for (int m = 0; m < K; ++m) {
            const double phi = e.phases_deg[std::size_t(m)] * std::numbers::pi / 180.0;
            std::vector<double>& row = out.weight[std::size_t(m)];
            out.first[std::size_t(m)] = 0;
            row.resize(std::size_t(time.bins));
            for (int i = 0; i < time.bins; ++i) {
                const double mid = time.start + (i + 0.5) * dt;
                row[std::size_t(i)] = 0.5 + 0.5 * (P * std::polar(1.0, w * mid - phi)).real() * sinc;
            }
        }
        return out;
    }
    for (int m = 0; m < K; ++m) {
        double a = 0.0, width = time.bin_width;
        if (e.type == ExposureType::Spad)
            a = time.start + m * time.bin_width;
        else
            a = e.windows[std::size_t(m)][0], width = e.windows[std::size_t(m)][1];
        box_window_weights(k, time, a, a + width, out.first[std::size_t(m)], out.weight[std::size_t(m)]);
    }
    return out;
}

ConvolvedProfile convolve_with_pulse(const SensorPulse& pulse, const TimeAxis& time, const float* profile) {
    // A bin's energy, even over the bin and shifted by tau, falls into the bins floor(tau/dt) and the
    // next in the ratio (1 - f) : f, f = frac(tau/dt): one transfer row for every source bin.
    const TimeKernel k = pulse_kernel(pulse, time.bin_width);
    const double dt = time.bin_width;
    const int o_lo = int(std::floor(k.first * k.step / dt)) - 1;
    const int o_hi = int(std::floor((k.first + double(k.mass.size())) * k.step / dt)) + 2;
    std::vector<double> transfer(std::size_t(o_hi - o_lo + 1), 0.0);
    for (std::size_t q = 0; q < k.mass.size(); ++q) {
        const double x = (k.first + double(q)) * k.step / dt;
        const double lo = std::floor(x), f = x - lo;
        transfer[std::size_t(int(lo) - o_lo)] += k.mass[q] * (1.0 - f);
        transfer[std::size_t(int(lo) + 1 - o_lo)] += k.mass[q] * f;
    }
    ConvolvedProfile out;
    out.first_bin = o_lo;
    out.energy.assign(std::size_t(time.bins + o_hi - o_lo), 0.0);
    for (int i = 0; i < time.bins; ++i) {
        const double e = profile[std::size_t(i)];
        if (e == 0.0) continue;
        for (std::size_t o = 0; o < transfer.size(); ++o) out.energy[std::size_t(i) + o] += e * transfer[o];
    }
    return out;
}

double amcw_depth(const SensorSettings& s, const float* measurements) {
    const std::vector<double>& phases = s.exposure.phases_deg;
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    for (std::size_t k = 0; k < phases.size(); ++k) {
        const double phi = phases[k] * std::numbers::pi / 180.0;
        const double m = double(measurements[k * 3]) + measurements[k * 3 + 1] + measurements[k * 3 + 2];
        rhs += m * Eigen::Vector3d(1.0, std::cos(phi), std::sin(phi));
    }
    const Eigen::Vector3d abc = phase_normal_matrix(phases).ldlt().solve(rhs);
    if (abc[1] == 0.0 && abc[2] == 0.0) return 0.0;
    double theta = std::atan2(abc[2], abc[1]);
    if (theta < 0.0) theta += 2.0 * std::numbers::pi;
    const double omega_per_metre = 2.0 * std::numbers::pi * s.exposure.frequency_mhz * 1e6 / kSpeedOfLight;
    return 0.5 * theta / omega_per_metre;
}

void apply_sensor(const SensorSettings& s, const TimeAxis& time, const float* cube, int height, int width,
                  float* measurements, float* depth, const SensorOptions& options) {
    const SensorWeights weights = sensor_weights(s, time);
    const std::size_t K = weights.first.size(), T = std::size_t(time.bins);
    const std::int64_t pixels = std::int64_t(height) * width;
    const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
    const bool spad = s.exposure.type == ExposureType::Spad;
    const double dark = spad ? s.exposure.dark_rate * time.to_metres(time.bin_width) / kSpeedOfLight : 0.0;
    const std::uint64_t seed = spad ? s.exposure.seed : s.noise.seed;
    const bool draws = spad || s.noise.sigma > 0.0;  // a generator is seeded only where it is used
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads)
    for (std::int64_t p = 0; p < pixels; ++p) {
        const float* e = cube + std::size_t(p) * T * 3;
        float* out = measurements + std::size_t(p) * K * 3;
        std::optional<std::mt19937_64> rng;
        if (draws) rng.emplace(mix_seed(seed, std::uint64_t(p)));
        std::normal_distribution<double> normal(0.0, 1.0);
        for (std::size_t k = 0; k < K; ++k) {
            double acc[3] = {0.0, 0.0, 0.0};
            const std::vector<double>& w = weights.weight[k];
            const float* ek = e + std::size_t(weights.first[k]) * 3;
            for (std::size_t i = 0; i < w.size(); ++i)
                for (int c = 0; c < 3; ++c) acc[c] += w[i] * double(ek[i * 3 + std::size_t(c)]);
            for (int c = 0; c < 3; ++c) {
                double v = acc[c];
                if (spad) {
                    const double mean = s.exposure.photons * std::max(0.0, v) + dark;
                    // Beyond 1e15 expected counts the Poisson spread (1/sqrt(mean)) is below float
                    // precision, and a draw could overflow the integer: the count is its mean.
                    if (mean > kMaxPoissonMean)
                        v = mean;
                    else
                        v = mean > 0.0 ? double(std::poisson_distribution<std::int64_t>(mean)(*rng)) : 0.0;
                } else {
                    if (s.noise.sigma > 0.0) v += s.noise.sigma * normal(*rng);
                    if (s.clamp) v = std::max(0.0, v);
                }
                // Saturated rather than infinite when a signal's scale exceeds a float's range.
                out[k * 3 + std::size_t(c)] = float(std::clamp(v, -double(FLT_MAX), double(FLT_MAX)));
            }
        }
        if (depth != nullptr) depth[p] = s.exposure.type == ExposureType::Amcw ? float(amcw_depth(s, out)) : 0.0f;
    }
}

void write_sensor_plot(const fs::path& path, const SensorSettings& s, const TimeAxis& time, const float* profile,
                       const float* measurements, int x, int y) {
    const char* unit = time.unit == TimeUnit::Picoseconds ? "ps" : "m";
    const double dt = time.bin_width;
    auto mean3 = [](const float* v) { return (double(v[0]) + v[1] + v[2]) / 3.0; };

    // The TPRF and its convolution with the pulse as densities (energy per unit time), so that the two
    // curves are comparable whatever the bin width.
    PlotPanel tprf_panel;
    tprf_panel.title = "pixel (" + std::to_string(x) + ", " + std::to_string(y) + "): TPRF and TPRF * pulse";
    tprf_panel.x_label = std::string("time (") + unit + ")";
    tprf_panel.y_label = std::string("radiance s per ") + unit;
    PlotSeries ideal{"TPRF", {}, {}, {40, 40, 40}, SeriesStyle::Steps};
    for (int i = 0; i <= time.bins; ++i) {
        ideal.x.push_back(time.start + i * dt);
        ideal.y.push_back(mean3(profile + std::size_t(std::min(i, time.bins - 1)) * 3) / dt);
    }
    std::vector<float> grey(std::size_t(time.bins));
    for (int i = 0; i < time.bins; ++i) grey[std::size_t(i)] = float(mean3(profile + std::size_t(i) * 3));
    const ConvolvedProfile conv = convolve_with_pulse(s.pulse, time, grey.data());
    PlotSeries convolved{"TPRF * pulse", {}, {}, {220, 60, 30}, SeriesStyle::Line};
    for (std::size_t m = 0; m < conv.energy.size(); ++m) {
        convolved.x.push_back(time.start + (conv.first_bin + double(m) + 0.5) * dt);
        convolved.y.push_back(conv.energy[m] / dt);
    }
    tprf_panel.series = {ideal, convolved};
    tprf_panel.x_range = std::make_pair(time.start, time.start + time.bins * dt);

    PlotPanel m_panel;
    m_panel.title = std::string("measurements (") + exposure_name(s.exposure.type) + ")";
    const int K = measurement_count(s, time);
    PlotSeries meas{"M_k", {}, {}, {30, 90, 200}, SeriesStyle::Markers};
    for (int k = 0; k < K; ++k) {
        double at = 0.0;
        switch (s.exposure.type) {
            case ExposureType::Gates:
            case ExposureType::Windows:
                at = s.exposure.windows[std::size_t(k)][0] + 0.5 * s.exposure.windows[std::size_t(k)][1];
                break;
            case ExposureType::Amcw: at = s.exposure.phases_deg[std::size_t(k)]; break;
            case ExposureType::Spad: at = time.start + k * dt; break;
        }
        meas.x.push_back(at);
        meas.y.push_back(mean3(measurements + std::size_t(k) * 3));
    }
    if (s.exposure.type == ExposureType::Spad) {
        meas.style = SeriesStyle::Steps;
        meas.label = "photon counts";
        meas.x.push_back(time.start + K * dt);
        meas.y.push_back(meas.y.empty() ? 0.0 : meas.y.back());
        m_panel.y_label = "counts per bin";
    } else {
        m_panel.y_label = "measurement";
    }
    m_panel.x_label = s.exposure.type == ExposureType::Amcw ? "phase (degrees)" : std::string("time (") + unit + ")";
    if (s.exposure.type == ExposureType::Spad) m_panel.x_range = tprf_panel.x_range;
    m_panel.series = {meas};
    write_plot_png(path, {tprf_panel, m_panel});
}

}  // namespace tprf
