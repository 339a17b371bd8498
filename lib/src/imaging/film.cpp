#include "tprf/imaging/film.h"

#include "tprf/core/parallel.h"
#include "tprf/imaging/gather.h"
#include "tprf/transport/illumination.h"
#include "tprf/core/error.h"
#include "tprf/transport/second_bounce.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <tuple>
#include <type_traits>

namespace tprf {

namespace {

// kSlack floats past the last row let the fused loop read a full lane group.
constexpr std::size_t kSlack = 8;

// One gather tap's share of a bin: out[t + lag] += weight B[t].
struct BinShare {
    std::uint32_t patch;
    std::uint16_t tint;
    std::int32_t lag;
    std::int64_t first;
    float weight;
};

// A pixel's shares as kernels, one per patch and tint, appended to `taps` and `weights`: summed in
// the order of the sort (the gather's, then the key's), so that the sums do not depend on threads.
void merge_shares(std::vector<BinShare>& shares, std::vector<FilmTaps::Tap>& taps, std::vector<float>& weights,
                  std::uint32_t& longest) {
    std::stable_sort(shares.begin(), shares.end(), [](const BinShare& a, const BinShare& b) {
        return std::tie(a.patch, a.tint, a.lag) < std::tie(b.patch, b.tint, b.lag);
    });
    for (std::size_t s = 0; s < shares.size();) {
        std::size_t e = s;
        std::int64_t first = shares[s].first;
        while (e < shares.size() && shares[e].patch == shares[s].patch && shares[e].tint == shares[s].tint)
            first = std::min(first, shares[e++].first);
        const std::int32_t lag = shares[s].lag;
        const std::uint32_t length = std::uint32_t(shares[e - 1].lag - lag + 1);
        taps.push_back({shares[s].patch, lag, first, weights.size(), length, shares[s].tint});
        longest = std::max(longest, length);
        weights.resize(weights.size() + length, 0.0f);
        float* w = weights.data() + taps.back().offset;
        for (; s < e; ++s) w[shares[s].lag - lag] += shares[s].weight;
    }
}

}  // namespace

FilmTaps film_taps(const Gather& gather, const TimeAxis& time, DelayMode delay, int threads, bool shifted) {
    const BinMap bins = time.bin_map();
    const std::size_t pixels = gather.row.empty() ? 0 : gather.row.size() - 1;
    std::vector<std::vector<FilmTaps::Tap>> per_pixel(pixels);
    std::vector<std::vector<float>> per_pixel_weights(pixels);
    std::vector<std::uint32_t> per_pixel_longest(pixels, 1);
    parallel_for(pixels, {thread_count(threads), 256, true}, [&](std::size_t px) {
        thread_local std::vector<BinShare> shares;
        shares.clear();
        for (std::uint64_t k = gather.row[px]; k < gather.row[px + 1]; ++k) {
            const PixelTap& tap = gather.taps[k];
            const BinSplit split = bins.split(double(tap.leg) + (shifted ? double(tap.shift) : 0.0), delay);
            const std::int64_t first = bins.bin(double(tap.earliest));
            const std::int32_t whole = std::int32_t(split.first);
            if (delay == DelayMode::Nearest) {
                shares.push_back({tap.patch, tap.tint, whole, first, tap.weight});
            } else {
                shares.push_back({tap.patch, tap.tint, whole, first, float(tap.weight * (1.0 - split.frac))});
                shares.push_back({tap.patch, tap.tint, whole + 1, first, float(tap.weight * split.frac)});
            }
        }
        merge_shares(shares, per_pixel[px], per_pixel_weights[px], per_pixel_longest[px]);
    });
    FilmTaps merged;
    for (const Rgb& t : gather.tints) merged.tints.push_back({float(t[0]), float(t[1]), float(t[2])});
    merged.row.assign(pixels + 1, 0);
    std::size_t weights = 0;
    for (std::size_t px = 0; px < pixels; ++px) {
        merged.row[px + 1] = merged.row[px] + per_pixel[px].size();
        weights += per_pixel_weights[px].size();
        merged.longest = std::max(merged.longest, per_pixel_longest[px]);
    }
    merged.taps.reserve(merged.row[pixels]);
    merged.weights.reserve(weights);
    for (std::size_t px = 0; px < pixels; ++px) {
        for (FilmTaps::Tap t : per_pixel[px]) {
            t.offset += merged.weights.size();
            merged.taps.push_back(t);
        }
        merged.weights.insert(merged.weights.end(), per_pixel_weights[px].begin(), per_pixel_weights[px].end());
        std::vector<FilmTaps::Tap>().swap(per_pixel[px]);
        std::vector<float>().swap(per_pixel_weights[px]);
    }
    return merged;
}

BlockSink film_sink(std::span<Film* const> films, double& seconds) {
    return [films, &seconds](const SolveBlock& block) {
        const auto start = std::chrono::steady_clock::now();
        for (Film* film : films) film->add_block(block);
        seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
}

TransientFilm::TransientFilm(const Gather& gather, const Illumination& illumination, const TimeAxis& time, float* cube,
                             FilmOptions options)
    : m_gather(gather), m_illumination(illumination), m_time(time), m_cube(cube), m_order(options.order),
      m_last_is_tail(options.last_is_tail), m_threads(thread_count(options.threads)), m_delay(options.delay),
      m_taps(options.taps ? std::move(options.taps)
                          : std::make_shared<const FilmTaps>(film_taps(gather, time, options.delay, options.threads))),
      m_pad(std::min<std::int64_t>(std::int64_t(m_taps->longest) - 1, std::int64_t(kFilmPadBins))) {}

void TransientFilm::read_second_bounce_apart(const SecondBounceLight* light, std::shared_ptr<const FilmTaps> shifted) {
    TPRF_CHECK(m_capacity == 0);  // before the first block
    if (!light) return;
    m_second_bounce = light;
    m_shifted = shifted ? std::move(shifted)
                        : std::make_shared<const FilmTaps>(film_taps(m_gather, m_time, m_delay, m_threads, true));
    m_first_read.assign(m_illumination.row.size() - 1, 0);
    for (const FilmTaps::Tap& tap : m_shifted->taps) m_first_read[tap.patch] = 1;
    const std::int64_t longest = std::max(m_taps->longest, m_shifted->longest);
    m_pad = std::min<std::int64_t>(longest - 1, std::int64_t(kFilmPadBins));
}

bool TransientFilm::takes_order(int order) const {
    return m_order < 0 || order == m_order || (m_last_is_tail && order > m_order);
}

void TransientFilm::add_direct() {
    const BinMap bins = m_time.bin_map();
    const std::size_t T = std::size_t(m_time.bins);
    for (const DirectArrival& a : m_gather.direct) {
        if (!takes_order(a.order)) continue;
        // A delta at an exact path lies wholly in the bin that contains it.
        const double b = bins.bin_floor(a.path);
        if (b < 0 || b >= double(T)) continue;
        float* v = m_cube + (std::size_t(a.pixel) * T + std::size_t(b)) * 3;
        for (int c = 0; c < 3; ++c) v[c] += float(a.radiance[c]);
    }
}

// Keeps the block's profiles less the pulses of point and area sources, which the gather evaluates
// exactly at each sensing point, after the kept ones.
void TransientFilm::copy_indirect(const SolveBlock& block) {
    const std::size_t n = block.patches, bins = std::size_t(block.bins);
    const float* source = block.radiosity;
    if (m_order >= 0) {
        TPRF_CHECK_LT(m_order, block.terms);
        source = block.per_order + std::size_t(m_order) * n * bins * 3;
    }
    const std::size_t pad = std::size_t(m_pad);
    // The rows, zero: the padding is never written, the kept bins always are. Sized for the solver's
    // largest block (kSinkBins bins; its first can be shorter), or for a larger one when it comes.
    if (m_capacity == 0 || bins > m_capacity) {
        TPRF_CHECK_EQ(m_kept, std::size_t(0));  // add_block has filmed what it kept
        m_capacity = film_buffer_bins(n, std::max(bins, std::size_t(kSinkBins)));
        m_indirect.assign(n * (m_capacity + 2 * pad) * 3 + kSlack, 0.0f);
        if (m_second_bounce) m_first.assign(m_indirect.size(), 0.0f);
    }
    const std::size_t stride = (m_capacity + 2 * pad) * 3;
    if (m_kept == 0) m_first_bin = block.first_bin;
    TPRF_CHECK_EQ(block.first_bin, m_first_bin + int(m_kept));
    TPRF_CHECK_LE(m_kept + bins, m_capacity);
    const BinMap time_bins = m_time.bin_map();
    parallel_for(n, {m_threads, 64, true}, [&](std::size_t i) {  // each patch's row is its own
        if (block.unread(i)) return;  // a glossy in-cell: no tap reads it (its row stays zero)
        float* row = m_indirect.data() + i * stride + (pad + m_kept) * 3;
        std::copy_n(source + i * bins * 3, bins * 3, row);
        for (std::uint64_t k = m_illumination.row[i]; k < m_illumination.row[i + 1]; ++k) {
            const Pulse& p = m_illumination.pulses[k];
            if (!p.exact_at_sensors() || !takes_order(p.order)) continue;
            const double b = time_bins.bin_floor(p.path) - block.first_bin;
            if (b < 0 || b >= double(bins)) continue;
            float* v = row + std::size_t(b) * 3;
            // What is left is the light of other orders in that bin; float cancellation must not
            // turn an exact zero into a small negative radiance.
            for (int c = 0; c < 3; ++c) v[c] = std::max(0.0f, v[c] - float(p.energy[c]));
        }
    });
    m_kept += bins;
}

// One tap over the block, a bin of its kernel at a time: out[base + t + j] += kernel[j] B[t], where
// `profile` is the patch's row at the block's bin 0 and `out` the pixel's profile. Light the patch
// average puts ahead of the earliest possible arrival goes to that bin.
void TransientFilm::add_kernel(const FilmTaps& taps, const FilmTaps::Tap& tap, const float* profile, std::int64_t base,
                               std::int64_t n, float* out) const {
    const std::int64_t T = m_time.bins;
    const float* kernel = taps.weights.data() + tap.offset;
    const float* tint = tap.tint != 0 ? taps.tints[tap.tint].data() : nullptr;
    const bool carry = tap.first >= 0 && tap.first < T;
    float carried[3] = {0, 0, 0};
    for (std::uint32_t j = 0; j < tap.length; ++j) {
        const float w = kernel[j];
        if (w == 0.0f) continue;
        const std::int64_t shift = base + std::int64_t(j);  // output bin of the block's bin 0
        const std::int64_t early = std::clamp<std::int64_t>(tap.first - shift, 0, n);
        if (carry)
            for (std::int64_t t = 0; t < early; ++t)
                for (int c = 0; c < 3; ++c) carried[c] += w * profile[std::size_t(t) * 3 + std::size_t(c)];
        // The rest: a contiguous multiply-add over bins, clipped to the window [0, T).
        const std::int64_t lo = std::max<std::int64_t>(early, -shift), hi = std::min<std::int64_t>(n, T - shift);
        if (lo >= hi) continue;
        float* __restrict o = out + std::size_t(shift + lo) * 3;
        const float* __restrict in = profile + std::size_t(lo) * 3;
        const std::size_t len = std::size_t(hi - lo) * 3;
        if (tint) {  // through tinted mirrors: a weight per channel
            const float wc[3] = {w * tint[0], w * tint[1], w * tint[2]};
            for (std::size_t e = 0; e < len; e += 3)
                for (int c = 0; c < 3; ++c) o[e + std::size_t(c)] += wc[c] * in[e + std::size_t(c)];
            continue;
        }
        for (std::size_t e = 0; e < len; ++e) o[e] += w * in[e];
    }
    if (carry)
        for (int c = 0; c < 3; ++c) out[std::size_t(tap.first) * 3 + std::size_t(c)] += (tint ? tint[c] : 1.0f) * carried[c];
}

// add_kernel for a grey tap whose kernel fits the rows' zero padding: each output bin u of the block's
// reach [base, base + n + length - 1) takes sum_j kernel[j] B[u - base - j] in one pass (the padding
// holds the zeros beyond the block), so each output is read and written once, not once per bin of the
// kernel. The same sums as add_kernel but for float rounding.
void TransientFilm::add_fused(const FilmTaps& taps, const FilmTaps::Tap& tap, const float* profile, std::int64_t base,
                              std::int64_t n, float* out) const {
    const std::int64_t T = m_time.bins, length = std::int64_t(tap.length);
    const float* kernel = taps.weights.data() + tap.offset;
    // profile[e - 3 base - 3j] = B[u - base - j] for e = 3u + c (zero outside the block, in the padding).
    const std::int64_t shift = 3 * base;
    const auto sum = [&](std::int64_t e) {
        float s = 0.0f;
        for (std::int64_t j = 0; j < length; ++j) s += kernel[j] * profile[e - shift - 3 * j];
        return s;
    };
    const std::int64_t reach_lo = base, reach_hi = base + n + length - 1;
    if (tap.first >= 0 && tap.first < T && tap.first > reach_lo) {  // light before the earliest bin
        float carried[3] = {0, 0, 0};
        for (std::int64_t u = reach_lo; u < std::min(tap.first, reach_hi); ++u)
            for (int c = 0; c < 3; ++c) carried[c] += sum(3 * u + c);
        for (int c = 0; c < 3; ++c) out[std::size_t(tap.first) * 3 + std::size_t(c)] += carried[c];
    }
    const std::int64_t e0 = 3 * std::max({reach_lo, tap.first, std::int64_t(0)}), e1 = 3 * std::min(reach_hi, T);
    // Eight outputs at a time (GCC's and Clang's vector extension: one AVX register under -march=x86-64-v3).
    typedef float Lanes __attribute__((vector_size(32)));
    constexpr std::int64_t kLanes = 8;
    std::int64_t e = e0;
    // G groups of eight outputs at a time, each kernel bin read once for all of them: four groups, then
    // one for what is left. Two sums per group (even and odd kernel bins): half the chain of dependent
    // multiply-adds. Every output's sum is the same whatever G.
    const auto groups = [&]<int G>(std::integral_constant<int, G>) {
        for (; e + G * kLanes <= e1; e += G * kLanes) {
            Lanes acc[G] = {}, odd[G] = {}, x;
            std::int64_t j = 0;
            for (; j + 1 < length; j += 2) {
                const float* a = profile + (e - shift - 3 * j);
                for (int g = 0; g < G; ++g) {
                    std::memcpy(&x, a + g * kLanes, sizeof x);
                    acc[g] += kernel[j] * x;
                    std::memcpy(&x, a - 3 + g * kLanes, sizeof x);
                    odd[g] += kernel[j + 1] * x;
                }
            }
            if (j < length) {
                const float* a = profile + (e - shift - 3 * j);
                for (int g = 0; g < G; ++g) {
                    std::memcpy(&x, a + g * kLanes, sizeof x);
                    acc[g] += kernel[j] * x;
                }
            }
            for (int g = 0; g < G; ++g) {
                std::memcpy(&x, out + e + g * kLanes, sizeof x);
                x += acc[g] + odd[g];
                std::memcpy(out + e + g * kLanes, &x, sizeof x);
            }
        }
    };
    groups(std::integral_constant<int, 4>{});
    groups(std::integral_constant<int, 1>{});
    for (; e < e1; ++e) out[e] += sum(e);
}

// One pixel's taps over the block: each reads its patch's profile and spreads it over its kernel
// (the pixel's legs to that patch, split between bins).
void TransientFilm::add_taps(const FilmTaps& taps, const std::vector<float>& rows, const std::vector<char>* lit,
                             std::size_t px) {
    // The kept bins, in rows of m_capacity bins between their zero padding.
    const int first_bin = m_first_bin;
    const std::size_t bins = m_kept, stride = (m_capacity + 2 * std::size_t(m_pad)) * 3;
    float* out = m_cube + px * std::size_t(m_time.bins) * 3;
    for (std::uint64_t k = taps.row[px]; k < taps.row[px + 1]; ++k) {
        const FilmTaps::Tap& tap = taps.taps[k];
        const float* profile = rows.data() + std::size_t(tap.patch) * stride + std::size_t(m_pad) * 3;
        std::int64_t base = first_bin + tap.lag;  // output bin of the block's bin 0 (kernel bin 0)
        std::int64_t n = std::int64_t(bins);
        if (lit) {  // first-link light: only the bins its links can reach hold any (zeros around them)
            if (!(*lit)[tap.patch]) continue;
            const auto [lo, hi] = m_second_bounce->bins_of(tap.patch);
            const std::int64_t skip = std::max<std::int64_t>(0, lo - first_bin);
            n = std::min<std::int64_t>(n, hi - first_bin) - skip;
            if (n <= 0) continue;
            profile += skip * 3;
            base += skip;
        }
        if (tap.tint == 0 && std::int64_t(tap.length) <= m_pad + 1)
            add_fused(taps, tap, profile, base, n, out);
        else
            add_kernel(taps, tap, profile, base, n, out);
    }
}

void TransientFilm::add_block(const SolveBlock& block) {
    // Blocks differ in length (a short first one, then kSinkBins): film what is kept when this one
    // does not fit.
    if (m_kept > 0 && m_kept + std::size_t(block.bins) > m_capacity) finish();
    copy_indirect(block);
}

void TransientFilm::finish() {
    if (m_kept == 0) return;
    const std::size_t pad = std::size_t(m_pad), pixels = m_gather.row.size() - 1, stride = (m_capacity + 2 * pad) * 3;
    // A last, partial fill: the bins after it that a kernel reads still hold the previous fill's light.
    const std::size_t stale = std::min(pad, m_capacity - m_kept);
    const std::size_t rows = (m_indirect.size() - kSlack) / stride;
    for (std::size_t i = 0; i < rows && stale > 0; ++i) {
        std::fill_n(m_indirect.data() + i * stride + (pad + m_kept) * 3, stale * 3, 0.0f);
        if (m_second_bounce) std::fill_n(m_first.data() + i * stride + (pad + m_kept) * 3, stale * 3, 0.0f);
    }
    if (m_second_bounce) {  // the light one link after its pulse, apart from the rest, for all the kept bins
        m_second_bounce->fill({m_first_bin, m_kept}, [this](int order) { return takes_order(order); },
                           m_first.data() + pad * 3, stride, m_first_lit, &m_first_read);
        parallel_for(rows, {m_threads, 64, true}, [&](std::size_t i) {
            if (!m_first_lit[i]) return;  // no second bounce read here: the rest is the whole profile
            float* rest = m_indirect.data() + i * stride + pad * 3;
            const float* first = m_first.data() + i * stride + pad * 3;
            // The rest is light of later orders: float cancellation must not make it negative.
            for (std::size_t e = 0; e < m_kept * 3; ++e) rest[e] = std::max(0.0f, rest[e] - first[e]);
        });
    }
    parallel_for(pixels, {m_threads, 64, true}, [&](std::size_t px) {
        add_taps(*m_taps, m_indirect, nullptr, px);
        if (m_second_bounce) add_taps(*m_shifted, m_first, &m_first_lit, px);
    });
    m_kept = 0;
}

std::vector<float> steady_image(const Gather& gather, const Illumination& illumination, const std::vector<Rgb>& steady) {
    const std::size_t pixels = std::size_t(gather.width) * std::size_t(gather.height);
    std::vector<Rgb> indirect(steady);
    for (std::size_t i = 0; i < indirect.size(); ++i)
        for (std::uint64_t k = illumination.row[i]; k < illumination.row[i + 1]; ++k)
            if (illumination.pulses[k].exact_at_sensors()) indirect[i] -= illumination.pulses[k].energy;
    std::vector<float> image(pixels * 3, 0.0f);
    for (std::size_t px = 0; px < pixels; ++px) {
        Rgb v = Rgb::Zero();
        for (std::uint64_t k = gather.row[px]; k < gather.row[px + 1]; ++k)
            v += double(gather.taps[k].weight) * indirect[gather.taps[k].patch] *
                 (gather.taps[k].tint != 0 ? gather.tints[gather.taps[k].tint] : Rgb::Ones());
        for (int c = 0; c < 3; ++c) image[px * 3 + std::size_t(c)] = float(v[c]);
    }
    for (const DirectArrival& a : gather.direct)
        for (int c = 0; c < 3; ++c) image[std::size_t(a.pixel) * 3 + std::size_t(c)] += float(a.radiance[c]);
    return image;
}

}  // namespace tprf
