#pragma once
/// Distributions in time as point masses on a grid: a pulse's shape, a sensor's timing jitter (and,
/// next, the spread of delays on a link). Every operation keeps the total mass and the mean exactly.

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace tprf {

/// Full width at half maximum per standard deviation of a Gaussian, 2 sqrt(2 ln 2).
inline constexpr double kFwhmPerSigma = 2.3548200450309493;
/// A Gaussian is cut at 6 sigma: the mass beyond (2e-9) is below float precision of any bin.
inline constexpr double kGaussianReach = 6.0;
/// Kernel steps per bin and per pulse width: fine enough that a pulse's shape within a bin is resolved.
inline constexpr double kStepsPerFeature = 16.0;
/// Upper bound on kernel points, so that a pulse table spanning millions of bins stays tractable.
inline constexpr double kMaxKernelPoints = 65536.0;
/// Point pairs of a convolution beyond which its grid is made coarser.
inline constexpr double kMaxConvolutionPairs = 1e8;

/// A distribution in time as point masses mass[q] at offset (first + q) * step (time unit), summing
/// to 1. Built so that its mean is the shape's mean exactly.
struct TimeKernel {
    double step = 0.0;
    int first = 0;
    std::vector<double> mass;
};

/// An empty kernel of grid `step` that can hold offsets in [lo, hi].
TimeKernel kernel_range(double step, double lo, double hi);

/// Adds `mass` at offset `t` to a kernel on the grid q * step, split between the two grid points
/// around t so that the kernel's total and mean stay exact. The kernel's range must hold t.
void add_split(TimeKernel& k, double t, double mass);

/// Scales the masses to sum to 1 (the total must be finite and positive).
void normalise(TimeKernel& k);

/// A centred Gaussian of full width `fwhm`, on a grid fine enough for bins of `bin_width`.
TimeKernel gaussian_kernel(double fwhm, double bin_width);

/// `k` on a grid of `step`: each mass split between its two grid points, so total and mean are kept.
TimeKernel resample(const TimeKernel& k, double step);

/// The distribution of the sum of two independent offsets (pulse and jitter): both put on one grid,
/// fine enough for the finer of the two unless that would make the grid or the pairwise sum too large.
TimeKernel convolve(const TimeKernel& a, const TimeKernel& b);

/// The share of a sum of two independent offsets, uniform in [-a, a] and [-b, b], that lies at or before
/// x: how a path that changes linearly along a cell's two half-axes is spread over the cell (a
/// trapezoid; a box when one of a, b is 0, a step when both are). Negative a, b count as their magnitude.
inline double trapezoid_cdf(double x, double a, double b) {
    a = std::abs(a);
    b = std::abs(b);
    if (a < b) std::swap(a, b);
    if (!(a > 0.0)) return x >= 0.0 ? 1.0 : 0.0;
    if (x <= -a - b) return 0.0;
    if (x >= a + b) return 1.0;
    if (b <= 1e-9 * a) return std::clamp((x + a) / (2.0 * a), 0.0, 1.0);
    // (q(x + a + b) - q(x + a - b) - q(x - a + b) + q(x - a - b)) / (8 a b), q(y) = max(y, 0)^2: on each
    // piece only the terms that are on, so that nothing cancels.
    if (x <= b - a) {  // the rising ramp
        const double y = x + a + b;
        return y * y / (8.0 * a * b);
    }
    if (x <= a - b) return (x + a) / (2.0 * a);  // the flat top
    const double y = a + b - x;                    // the falling ramp, from above
    return 1.0 - y * y / (8.0 * a * b);
}

/// Two half-widths whose trapezoid has the mean (0) and the variance of the sum of n independent
/// uniform offsets of half-widths h[0..n): the largest, and the root sum of squares of the others
/// (exact for n <= 2). How a cell's own spread and the spread of a cell it is seen from combine.
inline void equivalent_trapezoid(const double* h, int n, double& a, double& b) {
    double largest = 0.0, squares = 0.0;
    for (int i = 0; i < n; ++i) {
        largest = std::max(largest, std::abs(h[i]));
        squares += h[i] * h[i];
    }
    a = largest;
    b = std::sqrt(std::max(0.0, squares - largest * largest));
}

/// Light spread over paths as a trapezoid: centre + offsets uniform in [-a, a] and [-b, b], metres, none of
/// it before `lowest` (a bound the linear spread must not cross: the shortest path there is).
struct PathSpread {
    double centre = 0.0;
    double a = 0.0;
    double b = 0.0;
    double lowest = 0.0;
};

/// The spread cut at the bin edges origin + k bin_m: calls emit(path, share) once per bin it touches, in
/// increasing bins, `path` a point inside the bin's part of the support and the shares summing to 1.
/// Light before `lowest` is counted in lowest's bin.
template <class Emit>
void spread_over_bins(const PathSpread& spread, double bin_m, double origin, Emit&& emit) {
    const double centre = spread.centre, a = spread.a, b = spread.b, lowest = spread.lowest;
    const double reach = std::abs(a) + std::abs(b);
    const double lo = std::max(centre - reach, std::min(lowest, centre)), hi = centre + reach;
    const double first = std::floor((lo - origin) / bin_m), last = std::floor((hi - origin) / bin_m);
    if (!(hi > lo) || !(last > first)) {
        emit(std::clamp(centre, lo, hi), 1.0);
        return;
    }
    double below = 0.0;
    for (double k = first; k <= last; ++k) {
        const double start = origin + k * bin_m, end = std::min(hi, start + bin_m), from = std::max(lo, start);
        const double upto = k == last ? 1.0 : trapezoid_cdf(end - centre, a, b);
        const double share = upto - below;
        below = std::max(below, upto);
        // The middle of the overlap: well inside the bin, whatever the rounding of its edges.
        if (share > 0.0) emit(0.5 * (from + end), share);
    }
}

}  // namespace tprf
