#include "tprf/imaging/sensor_model.h"

#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/core/random.h"
#include "tprf/core/types.h"
#include "tprf/scene/validate.h"

#include <Eigen/Dense>
#include <omp.h>

#include <algorithm>
#include <array>
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
#include <utility>
#include <vector>

namespace tprf {

namespace {

constexpr double kMaxPoissonMean = 1e15;
// The SplitMix64 output of the user's seed that seeds the choice of dead pixels: pixels' own streams use
// outputs 0 to H W - 1, far below 2^63.
constexpr std::uint64_t kDeadPixelStream = std::uint64_t(1) << 63;

// The kernel the exposure sees: the pulse, and for a SPAD its timing jitter (and the jitter's tail) too.
TimeKernel exposure_kernel(const SensorSettings& s, double bin_width) {
    TimeKernel k = pulse_kernel(s.pulse, bin_width);
    const Exposure& e = s.exposure;
    if (e.type == ExposureType::Spad && (e.jitter_fwhm > 0.0 || e.jitter_tail.fraction > 0.0))
        k = convolve(k, jitter_kernel(e, bin_width));
    return k;
}

// Measurement k of one pixel's profile e (T x 3), per channel, before any noise.
void weighted_sum(const SensorWeights& weights, std::size_t k, const float* e, double acc[3]) {
    acc[0] = acc[1] = acc[2] = 0.0;
    const std::vector<double>& w = weights.weight[k];
    const float* ek = e + std::size_t(weights.first[k]) * 3;
    for (std::size_t i = 0; i < w.size(); ++i)
        for (int c = 0; c < 3; ++c) acc[c] += w[i] * double(ek[i * 3 + std::size_t(c)]);
}

// A SPAD's detector, prepared once per render (docs/sensor.md, "SPAD"). Offsets and times in bins.
struct SpadModel {
    std::uint64_t seed = 0;
    double photons = 1.0;
    double background = 0.0;          // dark and ambient counts per bin over the acquisition
    double cycles = 1.0;              // laser repetitions
    bool dead_time = false;           // whether detections blind the detector at all
    std::size_t dead_bins = 0;        // the bins blinded after a detection's own
    double crosstalk = 0.0;           // probability per 4-neighbour
    double afterpulse = 0.0;          // expected afterpulses per detection
    std::size_t head_first = 0;       // offset of head[0]; head[i] is the share of offset head_first + i,
    std::vector<double> head;         // up to tail_first; from there tail_weight * ratio^(m - tail_first)
    std::size_t tail_first = 0;
    double tail_weight = 0.0, ratio = 0.0;
    std::vector<unsigned char> dead;  // per pixel, row-major; empty: none dead
};

// P(U + Z > z) for U uniform in [0, 1) (a detection's place in its bin) and Z exponential of mean u: how much
// of the afterpulses' delay beyond the dead time's end reaches past z bins from the detection bin's start.
double delay_survival(double z, double u) {
    if (z <= 0.0) return 1.0;
    if (z < 1.0) return 1.0 - (z + u * std::expm1(-z / u));
    return u * -std::expm1(-1.0 / u) * std::exp(-(z - 1.0) / u);
}

// The share h[m] of a detection's afterpulses that falls m bins after its own, for the delay dead_time +
// Exp(time_constant); exact integrals, which beyond the first one or two offsets fall geometrically (ratio
// exp(-dt / tau)), so that the convolution needs only a running sum.
void afterpulse_offsets(const Exposure& e, double dt, std::size_t K, SpadModel& m) {
    const double a = e.dead_time / dt, u = e.afterpulsing.time_constant / dt;
    // A delay too long for a double in bins puts no afterpulse in the window.
    m.afterpulse = std::isfinite(u) ? e.afterpulsing.probability : 0.0;
    if (!(m.afterpulse > 0.0)) return;
    auto h = [&](double offset) { return delay_survival(offset - a, u) - delay_survival(offset + 1.0 - a, u); };
    auto index = [&](double x) { return x >= double(K) ? K : std::size_t(std::max(0.0, x)); };
    m.head_first = index(std::floor(a));
    m.tail_first = index(std::ceil(a + 1.0));
    for (std::size_t i = m.head_first; i < m.tail_first; ++i) m.head.push_back(h(double(i)));
    if (m.tail_first < K) m.tail_weight = h(double(m.tail_first));
    m.ratio = std::exp(-1.0 / u);
}

std::string dead_pixel_path(const SensorSettings& s, std::size_t i) {
    const std::string key = "exposure.dead_pixels[" + std::to_string(i) + "]";
    return s.json_path.empty() ? key : s.json_path + "." + key;
}

// The pixels that count nothing: those listed, and round(fraction H W) more chosen from the seed (the
// smallest SplitMix64 keys, which do not depend on the thread count).
std::vector<unsigned char> dead_pixel_mask(const SensorSettings& s, int height, int width) {
    const Exposure& e = s.exposure;
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
    if (!(e.dead_fraction > 0.0) && e.dead_pixels.empty()) return {};
    std::vector<unsigned char> dead(pixels, 0);
    auto check = [&](std::size_t i, const std::string& what, int v, int size) {
        if (v < 0 || v >= size)
            fail_input(s.file, dead_pixel_path(s, i), what + " " + std::to_string(v) + " is outside the image's " +
                                                          std::to_string(size) + " " + what + "s (0 to " +
                                                          std::to_string(size - 1) + ")");
    };
    for (std::size_t i = 0; i < e.dead_pixels.size(); ++i) {
        const auto [row, column] = e.dead_pixels[i];
        check(i, "row", row, height);
        check(i, "column", column, width);
        dead[std::size_t(row) * std::size_t(width) + std::size_t(column)] = 1;
    }
    const auto count = std::size_t(std::llround(e.dead_fraction * double(pixels)));
    if (count == 0) return dead;
    const std::uint64_t stream = SplitMix64::output(e.seed, kDeadPixelStream);
    std::vector<std::pair<std::uint64_t, std::size_t>> keys(pixels);
    for (std::size_t p = 0; p < pixels; ++p) keys[p] = {SplitMix64::output(stream, p), p};
    if (count < pixels) std::nth_element(keys.begin(), keys.begin() + std::ptrdiff_t(count), keys.end());
    for (std::size_t i = 0; i < std::min(count, pixels); ++i) dead[keys[i].second] = 1;
    return dead;
}

SpadModel spad_model(const SensorSettings& s, const TimeAxis& time, int height, int width) {
    const Exposure& e = s.exposure;
    const std::size_t K = std::size_t(time.bins);
    SpadModel m;
    m.seed = e.seed;
    m.photons = e.photons;
    m.background = e.dark_rate * time.to_metres(time.bin_width) / kSpeedOfLight;
    if (e.ambient > 0.0) m.background += e.ambient * (time.to_metres(time.bin_width) / kSpeedOfLight) * e.cycles;
    m.cycles = e.cycles;
    m.dead_time = e.dead_time > 0.0;
    // A detection blinds the rest of its bin and the next floor(dead_time / bin) bins: on average within half a
    // bin of the dead time (the 1e-9 keeps a dead time of exactly n bins from rounding down to n - 1).
    const double blind = std::floor(e.dead_time / time.bin_width + 1e-9);
    m.dead_bins = blind >= double(K) ? K : std::size_t(blind);
    m.crosstalk = e.crosstalk;
    afterpulse_offsets(e, time.bin_width, K, m);
    m.dead = dead_pixel_mask(s, height, width);
    return m;
}

bool is_dead(const SpadModel& m, std::size_t p) { return !m.dead.empty() && m.dead[p] != 0; }

// Expected counts over the acquisition of one pixel's profile e, K x 3, before the detector's dead time:
// photons x signal + dark + ambient, each rounded as expected_counts() rounds it.
void spad_rates(const SensorWeights& w, const float* e, const SpadModel& m, double* lambda) {
    for (std::size_t k = 0; k < w.first.size(); ++k) {
        double acc[3];
        weighted_sum(w, k, e, acc);
        for (std::size_t c = 0; c < 3; ++c) lambda[k * 3 + c] = expected_counts(m.photons, acc[c], m.background);
    }
}

// Dead time (in place): the expected detections over the acquisition from the expected counts without it.
// Per cycle, bin k holds a photon with p_k = 1 - exp(-x_k), x_k = lambda_k / N, and the detector is live with
// q_k; detections within dead_bins of each other exclude each other, so D_k = q_k p_k exactly, with
// q_{k+1} = q_k exp(-x_k) + D_{k - dead_bins} (docs/sensor.md, "Dead time and pile-up").
void pile_up(const SpadModel& m, double* lambda, std::size_t K, std::vector<double>& D) {
    if (!m.dead_time) return;
    for (std::size_t c = 0; c < 3; ++c) {
        double live = 1.0;
        for (std::size_t k = 0; k < K; ++k) {
            const double x = lambda[k * 3 + c] / m.cycles;
            D[k] = x > 0.0 ? live * -std::expm1(-x) : 0.0;
            const double back = k >= m.dead_bins ? D[k - m.dead_bins] : 0.0;
            live = std::min(1.0, (x > 0.0 ? live * std::exp(-x) : live) + back);
            lambda[k * 3 + c] = m.cycles * D[k];
        }
    }
}

// Afterpulses (in place): lambda_k += P sum_m h[m] lambda_{k - m}, the head's terms one by one and the
// geometric tail as the running sum run_i = ratio run_{i-1} + lambda_i.
void add_afterpulses(const SpadModel& m, double* lambda, std::size_t K, std::vector<double>& detections) {
    if (!(m.afterpulse > 0.0)) return;
    for (std::size_t c = 0; c < 3; ++c) {
        for (std::size_t k = 0; k < K; ++k) detections[k] = lambda[k * 3 + c];
        double run = 0.0;
        for (std::size_t k = 0; k < K; ++k) {
            double a = 0.0;
            for (std::size_t i = 0; i < m.head.size() && m.head_first + i <= k; ++i)
                a += m.head[i] * detections[k - m.head_first - i];
            if (k >= m.tail_first) {
                run = run * m.ratio + detections[k - m.tail_first];
                a += m.tail_weight * run;
            }
            lambda[k * 3 + c] = detections[k] + m.afterpulse * a;
        }
    }
}

// One thread's buffers, K x 3 (and K).
struct SpadScratch {
    explicit SpadScratch(std::size_t K) : lambda(K * 3), neighbour(K * 3), work(K) {}
    std::vector<double> lambda, neighbour, work;
};

// The means of live pixel p's counts, into scratch.lambda (K x 3): its own expected counts, plus crosstalk
// from each live 4-neighbour's detections (after that neighbour's own dead time), through the pixel's dead
// time, plus afterpulses.
void spad_means(const SpadModel& m, const SensorWeights& w, const CubeView& view, std::size_t p, SpadScratch& scratch) {
    const float* cube = view.data;
    const std::size_t T = std::size_t(view.time.bins);
    const int height = view.height, width = view.width;
    const std::size_t K = w.first.size();
    spad_rates(w, cube + p * T * 3, m, scratch.lambda.data());
    if (m.crosstalk > 0.0) {
        const auto row = std::int64_t(p) / width, column = std::int64_t(p) % width;
        const std::int64_t near[4][2] = {{row - 1, column}, {row + 1, column}, {row, column - 1}, {row, column + 1}};
        for (const auto& [r, c] : near) {
            if (r < 0 || c < 0 || r >= height || c >= width) continue;
            const std::size_t q = std::size_t(r * width + c);
            if (is_dead(m, q)) continue;
            spad_rates(w, cube + q * T * 3, m, scratch.neighbour.data());
            pile_up(m, scratch.neighbour.data(), K, scratch.work);
            for (std::size_t i = 0; i < K * 3; ++i) scratch.lambda[i] += m.crosstalk * scratch.neighbour[i];
        }
    }
    pile_up(m, scratch.lambda.data(), K, scratch.work);
    add_afterpulses(m, scratch.lambda.data(), K, scratch.work);
}

// A SPAD's histograms: each pixel's means, then its Poisson counts from its own stream, output p of
// SplitMix64(seed), drawn bin by bin and channel by channel whichever thread draws it.
void apply_spad(const SensorSettings& s, const SensorWeights& w, const CubeView& view, float* measurements, int threads) {
    const TimeAxis& time = view.time;
    const int height = view.height, width = view.width;
    const SpadModel m = spad_model(s, time, height, width);
    const std::size_t K = w.first.size();
    const auto pixels = std::int64_t(height) * width;
    // Allocated here, not in the region: an allocation failure there would end the process.
    const std::vector<SpadScratch>::size_type lanes = std::size_t(threads);
    std::vector<SpadScratch> scratches(lanes, SpadScratch{K});
#pragma omp parallel num_threads(threads)
    {
        SpadScratch& scratch = scratches[std::size_t(omp_get_thread_num())];
#pragma omp for schedule(dynamic, 16)
        for (std::int64_t i = 0; i < pixels; ++i) {
            if (cancel_requested()) continue;  // apply_sensor throws after the region
            const auto p = std::size_t(i);
            float* out = measurements + p * K * 3;
            if (is_dead(m, p)) {
                std::fill(out, out + K * 3, 0.0f);
                continue;
            }
            spad_means(m, w, view, p, scratch);
            Random rng(SplitMix64::output(m.seed, std::uint64_t(p)));
            for (std::size_t j = 0; j < K * 3; ++j) {
                const double mean = scratch.lambda[j];
                // Beyond 1e15 expected counts the Poisson spread (1/sqrt(mean)) is below float precision
                // (and Random::poisson takes means up to 2^52 only): the count is its mean. Saturated rather
                // than infinite beyond a float's range.
                const double v = mean > kMaxPoissonMean ? mean : rng.poisson(mean);
                out[j] = float(std::clamp(v, -double(FLT_MAX), double(FLT_MAX)));
            }
        }
    }
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

// Angular frequency of a modulation of `hz` per unit of the scene's time axis.
double omega_per_unit(double hz, const TimeAxis& time) {
    return 2.0 * std::numbers::pi * hz * time.to_metres(1.0) / kSpeedOfLight;
}

}  // namespace

int measurement_count(const SensorSettings& s, const TimeAxis& time) {
    switch (s.exposure.type) {
        case ExposureType::Gates:
        case ExposureType::Windows: return int(s.exposure.windows.size());
        case ExposureType::Amcw: return int(s.exposure.phases_deg.size() * s.exposure.amcw_frequencies_hz().size());
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
        // Measurement m is phase m % P at frequency m / P.
        const std::vector<double> frequencies = e.amcw_frequencies_hz();
        const std::size_t phases = e.phases_deg.size();
        const double dt = time.bin_width;
        for (std::size_t f = 0; f < frequencies.size(); ++f) {
            const double w = omega_per_unit(frequencies[f], time);
            std::complex<double> P = 0.0;
            for (std::size_t q = 0; q < k.mass.size(); ++q) P += k.mass[q] * std::polar(1.0, w * (k.first + double(q)) * k.step);
            const double half = 0.5 * w * dt;
            const double sinc = half < 1e-4 ? 1.0 - half * half / 6.0 : std::sin(half) / half;
            for (std::size_t j = 0; j < phases; ++j) {
                const std::size_t m = f * phases + j;
                const double phi = e.phases_deg[j] * std::numbers::pi / 180.0;
                std::vector<double>& row = out.weight[m];
                out.first[m] = 0;
                row.resize(std::size_t(time.bins));
                for (int i = 0; i < time.bins; ++i) {
                    const double mid = time.start + (i + 0.5) * dt;
                    row[std::size_t(i)] = 0.5 + 0.5 * (P * std::polar(1.0, w * mid - phi)).real() * sinc;
                }
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

namespace {

// What turns an AMCW pixel's raw samples (F frequencies x P phases) into its depth, made once per
// frame: per phase cos and sin of its angle, the least-squares fit's factorised normal matrix, per
// frequency its wrap c / (2 f) and weight f^2, and how many wraps of the lowest frequency the window
// holds (validate_sensor bounds them by kMaxAmcwCandidates).
class AmcwDecoder {
public:
    AmcwDecoder(const SensorSettings& s, double max_distance) : m_fit(phase_normal_matrix(s.exposure.phases_deg)) {
        for (const double deg : s.exposure.phases_deg) {
            const double phi = deg * std::numbers::pi / 180.0;
            m_cos.push_back(std::cos(phi));
            m_sin.push_back(std::sin(phi));
        }
        for (const double f : s.exposure.amcw_frequencies_hz()) {
            m_wrap.push_back(0.5 * kSpeedOfLight / f);
            m_weight.push_back(f * f);
        }
        m_reach = max_distance;
    }

    // The depth of one pixel's samples (amcw_depth in the header says how).
    template <class T>
    double depth(const T* raw) const {
        const std::size_t F = m_wrap.size(), P = m_cos.size();
        // Each frequency's distance in [0, wrap); those without modulation take no part.
        std::array<double, kMaxAmcwFrequencies> distance{}, wrap{}, weight{};
        std::size_t n = 0;
        for (std::size_t f = 0; f < F; ++f) {
            double theta = 0.0;
            if (!phase(raw + f * P, theta)) continue;
            wrap[n] = m_wrap[f];
            weight[n] = m_weight[f];
            distance[n++] = theta / (2.0 * std::numbers::pi) * m_wrap[f];
        }
        if (n == 0) return 0.0;
        if (n == 1) return distance[0];
        // Candidates: the longest wrap's distance plus whole wraps, up to the window's reach; the one
        // whose phases agree best with every frequency's.
        const std::size_t base = std::size_t(std::max_element(wrap.begin(), wrap.begin() + n) - wrap.begin());
        const double reach = std::max(m_reach, wrap[base]);
        const auto off = [&](double d, std::size_t f) {  // d's distance to f's nearest reading, in wraps of f
            const double x = (d - distance[f]) / wrap[f];
            return x - std::round(x);
        };
        double best = distance[base], best_cost = std::numeric_limits<double>::infinity();
        const double candidates = std::min(std::floor((reach - distance[base]) / wrap[base]), double(kMaxAmcwCandidates));
        for (double k = 0; k <= candidates; ++k) {
            const double d = distance[base] + k * wrap[base];
            double cost = 0.0;
            for (std::size_t f = 0; f < n; ++f) cost += off(d, f) * off(d, f);
            if (cost < best_cost - 1e-12) best = d, best_cost = cost;
        }
        double sum = 0.0, total = 0.0;
        for (std::size_t f = 0; f < n; ++f) {
            sum += weight[f] * (best - off(best, f) * wrap[f]);
            total += weight[f];
        }
        return sum / total;
    }

private:
    // The phase theta in [0, 2 pi) of the least-squares fit a + b cos(phi) + c sin(phi) to the P
    // samples m[k], and whether they carry any modulation (b, c not both 0).
    template <class T>
    bool phase(const T* m, double& theta) const {
        Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
        for (std::size_t k = 0; k < m_cos.size(); ++k) rhs += double(m[k]) * Eigen::Vector3d(1.0, m_cos[k], m_sin[k]);
        const Eigen::Vector3d abc = m_fit.solve(rhs);
        if (abc[1] == 0.0 && abc[2] == 0.0) return false;
        theta = std::atan2(abc[2], abc[1]);
        if (theta < 0.0) theta += 2.0 * std::numbers::pi;
        return true;
    }

    Eigen::LDLT<Eigen::Matrix3d> m_fit;
    std::vector<double> m_cos, m_sin, m_wrap, m_weight;
    double m_reach = 0.0;
};

}  // namespace

double amcw_depth(const SensorSettings& s, const double* raw, double max_distance) {
    return AmcwDecoder(s, max_distance).depth(raw);
}

namespace {

// The largest distance an AMCW pixel's light can encode in the window: half the path at its end (an
// emitter beside the camera), metres.
double window_distance(const TimeAxis& time) { return 0.5 * time.to_metres(time.end()); }

// An AMCW pixel's raw samples from its measurements (K x 3): the channels' sum, as the one infrared
// channel of a ToF camera, and with `photons` a Poisson count of photons times it plus `ambient`.
void amcw_raw(const Exposure& e, const float* measurements, std::size_t K, std::optional<Random>& shot, double* raw) {
    for (std::size_t k = 0; k < K; ++k) {
        const double sum = double(measurements[k * 3]) + measurements[k * 3 + 1] + measurements[k * 3 + 2];
        raw[k] = e.amcw_photons > 0.0 ? shot->poisson(std::max(0.0, e.amcw_photons * sum) + e.amcw_ambient) : sum;
    }
}

}  // namespace

std::vector<double> spad_expected_counts(const SensorSettings& s, const CubeView& cube, int row, int column) {
    const TimeAxis& time = cube.time;
    const int height = cube.height, width = cube.width;
    TPRF_CHECK(s.exposure.type == ExposureType::Spad);
    TPRF_CHECK(row >= 0 && row < height && column >= 0 && column < width);
    const SensorWeights w = sensor_weights(s, time);
    const SpadModel m = spad_model(s, time, height, width);
    const std::size_t p = std::size_t(row) * std::size_t(width) + std::size_t(column);
    SpadScratch scratch(w.first.size());
    if (!is_dead(m, p)) spad_means(m, w, cube, p, scratch);
    return scratch.lambda;
}

void apply_sensor(const SensorSettings& s, const CubeView& view, float* measurements, float* depth,
                  const SensorOptions& options, float* raw) {
    const TimeAxis& time = view.time;
    const float* cube = view.data;
    const int height = view.height, width = view.width;
    const SensorWeights weights = sensor_weights(s, time);
    const std::size_t K = weights.first.size(), T = std::size_t(time.bins);
    const std::int64_t pixels = std::int64_t(height) * width;
    const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
    if (s.exposure.type == ExposureType::Spad) {
        apply_spad(s, weights, view, measurements, threads);
        check_cancelled();
        if (depth != nullptr) std::fill(depth, depth + pixels, 0.0f);
        return;
    }
    const bool draws = s.noise.sigma > 0.0;  // a generator is seeded only where it is used
    const bool amcw = s.exposure.type == ExposureType::Amcw;
    const bool quantised = amcw && s.exposure.adc_bits > 0;
    const std::optional<AmcwDecoder> decoder = amcw ? std::optional<AmcwDecoder>(std::in_place, s, window_distance(time))
                                                    : std::nullopt;
    std::vector<float> own_raw;  // the raw samples when the caller keeps none: the depth needs them
    if (amcw && raw == nullptr) {
        own_raw.resize(std::size_t(pixels) * K);
        raw = own_raw.data();
    }
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads)
    for (std::int64_t p = 0; p < pixels; ++p) {
        if (cancel_requested()) continue;  // thrown after the region
        const float* e = cube + std::size_t(p) * T * 3;
        float* out = measurements + std::size_t(p) * K * 3;
        // Pixel p's stream is seeded with output p of SplitMix64(seed), so that a pixel's noise does not
        // depend on which thread draws it; its shot noise (AMCW photons) from output p of the stream
        // seeded with the exposure's own seed, as a SPAD's counts.
        std::optional<Random> rng, shot;
        if (draws) rng.emplace(SplitMix64::output(s.noise.seed, std::uint64_t(p)));
        if (amcw && s.exposure.amcw_photons > 0.0) shot.emplace(SplitMix64::output(s.exposure.seed, std::uint64_t(p)));
        for (std::size_t k = 0; k < K; ++k) {
            double acc[3];
            weighted_sum(weights, k, e, acc);
            for (int c = 0; c < 3; ++c) {
                double v = acc[c];
                if (draws) v = rng->add_normal(v, s.noise.sigma);
                if (s.clamp) v = std::max(0.0, v);
                // Saturated rather than infinite when a signal's scale exceeds a float's range.
                out[k * 3 + std::size_t(c)] = float(std::clamp(v, -double(FLT_MAX), double(FLT_MAX)));
            }
        }
        if (!amcw) {
            if (depth != nullptr) depth[p] = 0.0f;
            continue;
        }
        std::vector<double> samples(K);
        amcw_raw(s.exposure, out, K, shot, samples.data());
        for (std::size_t k = 0; k < K; ++k) raw[std::size_t(p) * K + k] = float(std::min(samples[k], double(FLT_MAX)));
        if (depth != nullptr && !quantised) depth[p] = float(decoder->depth(samples.data()));
    }
    check_cancelled();
    if (!quantised) return;
    // The ADC: the frame's largest raw sample is its full scale (as an auto-exposure sets it), each
    // sample rounded to one of 2^bits levels below it; the depth from the levels.
    const std::size_t samples = std::size_t(pixels) * K;
    if (samples == 0) return;
    const double top = *std::max_element(raw, raw + samples);
    const double levels = std::ldexp(1.0, s.exposure.adc_bits) - 1.0;
    for (std::size_t q = 0; q < samples; ++q) raw[q] = top > 0.0 ? float(std::round(std::max(0.0, double(raw[q])) / top * levels)) : 0.0f;
    if (depth == nullptr) return;
#pragma omp parallel for schedule(dynamic, 64) num_threads(threads)
    for (std::int64_t p = 0; p < pixels; ++p) depth[p] = float(decoder->depth(raw + std::size_t(p) * K));
}

SensorPlot sensor_plot(const SensorSettings& s, const TimeAxis& time, const float* profile, const float* measurements,
                       int x, int y) {
    const double dt = time.bin_width;
    auto mean3 = [](const float* v) { return (double(v[0]) + v[1] + v[2]) / 3.0; };
    SensorPlot plot;
    plot.x = x, plot.y = y;
    plot.exposure = exposure_name(s.exposure.type);
    plot.time_unit = unit_name(time.unit);
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
            case ExposureType::Amcw: at = s.exposure.phases_deg[std::size_t(k) % s.exposure.phases_deg.size()]; break;
            case ExposureType::Spad: at = time.start + k * dt; break;
        }
        plot.measurement_at.push_back(at);
        plot.measurements.push_back(mean3(measurements + std::size_t(k) * 3));
    }
    return plot;
}

}  // namespace tprf
