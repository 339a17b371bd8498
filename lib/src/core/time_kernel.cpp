#include "tprf/core/time_kernel.h"

#include "tprf/core/error.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tprf {

TimeKernel kernel_range(double step, double lo, double hi) {
    TimeKernel k;
    k.step = step;
    k.first = int(std::floor(lo / step)) - 1;
    k.mass.assign(std::size_t(int(std::ceil(hi / step)) - k.first + 2), 0.0);
    return k;
}

void add_split(TimeKernel& k, double t, double mass) {
    const double x = t / k.step - k.first;
    const double lo = std::floor(x);
    const double f = x - lo;
    const std::size_t i = std::size_t(std::max(0.0, lo));
    k.mass[i] += mass * (1.0 - f);
    if (f > 0.0) k.mass[i + 1] += mass * f;
}

void normalise(TimeKernel& k) {
    double total = 0.0;
    for (const double m : k.mass) total += m;
    TPRF_CHECK(std::isfinite(total) && total > 0.0);
    for (double& m : k.mass) m /= total;
}

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

TimeKernel resample(const TimeKernel& k, double step) {
    TimeKernel out = kernel_range(step, k.first * k.step, (k.first + double(k.mass.size())) * k.step);
    for (std::size_t q = 0; q < k.mass.size(); ++q)
        if (k.mass[q] != 0.0) add_split(out, (k.first + double(q)) * k.step, k.mass[q]);
    return out;
}

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

}  // namespace tprf
