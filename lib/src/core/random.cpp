// Compiled with -ffp-contract=off (lib/CMakeLists.txt): a multiply-add fused on one machine and not on
// another would round differently and could change a count.
#include "tprf/core/random.h"

#include <array>
#include <algorithm>
#include <cmath>
#include <numbers>

namespace tprf {

namespace {

/// Below this mean the multiplication method, from it on PTRS (whose constants hold for means >= 10).
constexpr double kPtrsMinMean = 10.0;
/// Whole numbers below this take log(k!) from a table; from it on Stirling's series.
constexpr int kLogFactorialTable = 16;

/// log(k!) for k = 0 .. 15, from the exact factorials (all below 2^53).
const std::array<double, kLogFactorialTable>& log_factorial_table() {
    static const std::array<double, kLogFactorialTable> table = [] {
        std::array<double, kLogFactorialTable> t{};
        double f = 1.0;
        for (int k = 0; k < kLogFactorialTable; ++k) {
            if (k > 0) f *= k;
            t[std::size_t(k)] = std::log(f);
        }
        return t;
    }();
    return table;
}

/// log P(K = k) for a Poisson variable of mean `mean` (log_mean = log(mean)), k a whole number >= 0.
/// From k = 16 on, with Stirling's log k! = (k + 1/2) log k - k + log(2 pi) / 2 + c(k),
///     log P = -mean h((k - mean) / mean) - log(2 pi k) / 2 - c(k),   h(x) = (1 + x) log1p(x) - x,
/// which is -mean + k log(mean) - log k! without its cancellation: at a mean of 1e15 both of those
/// terms are near 3.5e16, and their difference, a number near 1, would keep no correct digit.
/// c(k) = 1/(12k) - 1/(360k^3) + 1/(1260k^5) - 1/(1680k^7) is within 1/(1188 k^9) < 2e-14.
double log_poisson_pmf(double k, double mean, double log_mean) {
    if (k < kLogFactorialTable) return -mean + k * log_mean - log_factorial_table()[std::size_t(k)];
    const double x = (k - mean) / mean;
    const double h = (1.0 + x) * std::log1p(x) - x;
    const double r = 1.0 / k, r2 = r * r;
    const double c = r * (1.0 / 12 - r2 * (1.0 / 360 - r2 * (1.0 / 1260 - r2 * (1.0 / 1680))));
    return -mean * h - 0.5 * std::log(2.0 * std::numbers::pi * k) - c;
}

}  // namespace

double Random::normal() {
    if (m_has_spare) {
        m_has_spare = false;
        return m_spare;
    }
    const double u1 = 1.0 - uniform();  // (0, 1]: log(u1) is finite
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double theta = 2.0 * std::numbers::pi * u2;
    m_spare = r * std::sin(theta);
    m_has_spare = true;
    return r * std::cos(theta);
}

double Random::poisson(double mean) {
    if (!(mean > 0.0)) return 0.0;
    if (mean < kPtrsMinMean) {
        // Multiplication method: uniforms are multiplied until the product drops to exp(-mean) or
        // below; the count is the number of factors before the last.
        const double limit = std::exp(-mean);
        double count = 0.0, product = uniform();
        while (product > limit) {
            product *= uniform();
            count += 1.0;
        }
        return count;
    }
    // PTRS, Hormann (1993), steps 1 to 5 as published; only the log-probability of step 5 is
    // rearranged (log_poisson_pmf).
    const double log_mean = std::log(mean);
    const double b = 0.931 + 2.53 * std::sqrt(mean);
    const double a = -0.059 + 0.02483 * b;
    const double log_alpha = std::log(1.1239 + 1.1328 / (b - 3.4));
    const double v_r = 0.9277 - 3.6224 / (b - 2.0);
    for (;;) {
        const double u = uniform() - 0.5;
        const double v = uniform();
        const double us = 0.5 - std::abs(u);
        if (us == 0.0) continue;  // u = -1/2 exactly: the transformation has a pole there
        const double k = std::floor((2.0 * a / us + b) * u + mean + 0.43);
        if (us >= 0.07 && v <= v_r) return k;
        if (k < 0.0 || (us < 0.013 && v > us)) continue;
        if (std::log(v) + log_alpha - std::log(a / (us * us) + b) <= log_poisson_pmf(k, mean, log_mean)) return k;
    }
}

double Random::add_normal(double v, double sigma) { return v + sigma * normal(); }

double expected_counts(double photons, double signal, double dark) { return photons * std::max(0.0, signal) + dark; }

}  // namespace tprf
