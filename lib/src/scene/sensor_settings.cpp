#include "tprf/scene/sensor_settings.h"

#include "tprf/core/error.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tprf {
namespace {

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

// wa a + wb b on the grid of b (a resampled onto it, which keeps its total and mean).
TimeKernel mix(const TimeKernel& a, double wa, const TimeKernel& b, double wb) {
    const TimeKernel ga = resample(a, b.step);
    TimeKernel k;
    k.step = b.step;
    k.first = std::min(ga.first, b.first);
    const int end = std::max(ga.first + int(ga.mass.size()), b.first + int(b.mass.size()));
    k.mass.assign(std::size_t(end - k.first), 0.0);
    for (std::size_t q = 0; q < ga.mass.size(); ++q) k.mass[std::size_t(ga.first - k.first) + q] += wa * ga.mass[q];
    for (std::size_t q = 0; q < b.mass.size(); ++q) k.mass[std::size_t(b.first - k.first) + q] += wb * b.mass[q];
    normalise(k);
    return k;
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

TimeKernel exponential_kernel(double time_constant, double bin_width) {
    const double tau = time_constant, cut = kTailReach * tau;
    const double step = std::max(std::min(bin_width, tau) / kStepsPerFeature, (cut + tau) / kMaxKernelPoints);
    TimeKernel k = kernel_range(step, 0.0, cut + tau);
    // Cells of width h over [0, cut): cell j holds exp(-j h / tau) (1 - exp(-h / tau)) at the exponential's
    // centroid in the cell, j h + tau - h / expm1(h / tau); what lies beyond the cut sits at its own mean,
    // cut + tau (memorylessness). So the kernel's total and mean are the exponential's.
    const int cells = std::max(1, int(std::ceil(cut / step)));
    const double h = cut / cells;
    const double in_cell = -std::expm1(-h / tau), centroid = tau - h / std::expm1(h / tau);
    for (int j = 0; j < cells; ++j) add_split(k, j * h + centroid, std::exp(-j * h / tau) * in_cell);
    add_split(k, cut + tau, std::exp(-kTailReach));
    normalise(k);
    return k;
}

TimeKernel jitter_kernel(const Exposure& e, double bin_width) {
    const bool gaussian = e.jitter_fwhm > 0.0;
    const TimeKernel core = gaussian ? gaussian_kernel(e.jitter_fwhm, bin_width) : TimeKernel{bin_width, 0, {1.0}};
    const double f = e.jitter_tail.fraction;
    if (!(f > 0.0)) return core;
    // The diffusion tail delays the avalanche, whose build-up jitters as any other: G * E.
    const TimeKernel exponential = exponential_kernel(e.jitter_tail.time_constant, bin_width);
    const TimeKernel tail = gaussian ? convolve(core, exponential) : exponential;
    return f >= 1.0 ? tail : mix(core, 1.0 - f, tail, f);
}

double jitter_reach(const Exposure& e) {
    double reach = kGaussianReach * e.jitter_fwhm / kFwhmPerSigma;
    if (e.jitter_tail.fraction > 0.0) reach += (kTailReach + 1.0) * e.jitter_tail.time_constant;
    return reach;
}

Eigen::Matrix3d phase_normal_matrix(const std::vector<double>& phases_deg) {
    Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
    for (const double deg : phases_deg) {
        const double phi = deg * std::numbers::pi / 180.0;
        const Eigen::Vector3d row(1.0, std::cos(phi), std::sin(phi));
        m += row * row.transpose();
    }
    return m;
}

}  // namespace tprf
