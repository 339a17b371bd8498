#pragma once
/// Distributions in time as point masses on a grid: a pulse's shape, a sensor's timing jitter (and,
/// next, the spread of delays on a link). Every operation keeps the total mass and the mean exactly.

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

}  // namespace tprf
