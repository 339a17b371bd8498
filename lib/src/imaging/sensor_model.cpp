#include "tprf/imaging/sensor_model.h"

#include "tprf/core/error.h"
#include "tprf/core/random.h"
#include "tprf/core/types.h"

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
#include <sstream>
#include <string>

namespace tprf {

namespace {

constexpr double kMaxPoissonMean = 1e15;


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

}  // namespace

int measurement_count(const SensorSettings& s, const TimeAxis& time) {
    switch (s.exposure.type) {
        case ExposureType::Gates:
        case ExposureType::Windows: return int(s.exposure.windows.size());
        case ExposureType::Amcw: return int(s.exposure.phases_deg.size());
        case ExposureType::Spad: return time.bins;
    }
    return 0;
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
        // Pixel p's stream is seeded with output p of SplitMix64(seed), so that a pixel's noise does not
        // depend on which thread draws it.
        std::optional<Random> rng;
        if (draws) rng.emplace(SplitMix64::output(seed, std::uint64_t(p)));
        for (std::size_t k = 0; k < K; ++k) {
            double acc[3] = {0.0, 0.0, 0.0};
            const std::vector<double>& w = weights.weight[k];
            const float* ek = e + std::size_t(weights.first[k]) * 3;
            for (std::size_t i = 0; i < w.size(); ++i)
                for (int c = 0; c < 3; ++c) acc[c] += w[i] * double(ek[i * 3 + std::size_t(c)]);
            for (int c = 0; c < 3; ++c) {
                double v = acc[c];
                if (spad) {
                    const double mean = expected_counts(s.exposure.photons, v, dark);
                    // Beyond 1e15 expected counts the Poisson spread (1/sqrt(mean)) is below float
                    // precision (and Random::poisson takes means up to 2^52 only): the count is its mean.
                    v = mean > kMaxPoissonMean ? mean : rng->poisson(mean);
                } else {
                    if (s.noise.sigma > 0.0) v = rng->add_normal(v, s.noise.sigma);
                    if (s.clamp) v = std::max(0.0, v);
                }
                // Saturated rather than infinite when a signal's scale exceeds a float's range.
                out[k * 3 + std::size_t(c)] = float(std::clamp(v, -double(FLT_MAX), double(FLT_MAX)));
            }
        }
        if (depth != nullptr) depth[p] = s.exposure.type == ExposureType::Amcw ? float(amcw_depth(s, out)) : 0.0f;
    }
}

SensorPlot sensor_plot(const SensorSettings& s, const TimeAxis& time, const float* profile, const float* measurements,
                       int x, int y) {
    const double dt = time.bin_width;
    auto mean3 = [](const float* v) { return (double(v[0]) + v[1] + v[2]) / 3.0; };
    SensorPlot plot;
    plot.x = x, plot.y = y;
    plot.exposure = exposure_name(s.exposure.type);
    plot.time_unit = time.unit == TimeUnit::Picoseconds ? "ps" : "m";
    plot.start = time.start, plot.end = time.start + time.bins * dt;

    // The TPRF and its convolution with the pulse as densities (energy per unit time), so that the two
    // curves are comparable whatever the bin width.
    std::vector<float> grey(std::size_t(time.bins));
    for (int i = 0; i <= time.bins; ++i) plot.tprf_edges.push_back(time.start + i * dt);
    for (int i = 0; i < time.bins; ++i) {
        grey[std::size_t(i)] = float(mean3(profile + std::size_t(i) * 3));
        plot.tprf.push_back(mean3(profile + std::size_t(i) * 3) / dt);
    }
    const ConvolvedProfile conv = convolve_with_pulse(s.pulse, time, grey.data());
    for (std::size_t m = 0; m < conv.energy.size(); ++m) {
        plot.convolved_time.push_back(time.start + (conv.first_bin + double(m) + 0.5) * dt);
        plot.convolved.push_back(conv.energy[m] / dt);
    }

    const int K = measurement_count(s, time);
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
        plot.measurement_at.push_back(at);
        plot.measurements.push_back(mean3(measurements + std::size_t(k) * 3));
    }
    return plot;
}

}  // namespace tprf
