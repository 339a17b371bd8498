#include "tprf/imaging/film.h"

#include "tprf/core/parallel.h"
#include "tprf/imaging/gather.h"
#include "tprf/transport/illumination.h"
#include "tprf/core/error.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace tprf {

FilmTaps film_taps(const Gather& gather, const TimeAxis& time, DelayMode delay, int threads) {
    const double inv_bin = 1.0 / time.bin_width_m(), start = time.start_m();
    const std::size_t pixels = gather.row.empty() ? 0 : gather.row.size() - 1;
    using Tap = FilmTaps::Tap;
    std::vector<std::vector<Tap>> per_pixel(pixels);
    parallel_for(pixels, {thread_count(threads), 256, true}, [&](std::size_t px) {
        std::vector<Tap>& out = per_pixel[px];
        for (std::uint64_t k = gather.row[px]; k < gather.row[px + 1]; ++k) {
            const PixelTap& tap = gather.taps[k];
            const double lag = double(tap.leg) * inv_bin;
            Tap t{tap.patch, 0, std::int64_t(std::floor((double(tap.earliest) - start) * inv_bin)), tap.weight, 0.0f,
                  tap.tint};
            if (delay == DelayMode::Nearest) {
                t.lag = std::int32_t(std::floor(lag + 0.5));
            } else {
                t.lag = std::int32_t(std::floor(lag));
                const double f = lag - double(t.lag);
                t.w0 = float(tap.weight * (1.0 - f));
                t.w1 = float(tap.weight * f);
            }
            out.push_back(t);
        }
        // In a fixed order (the gather's, then the key's), so that the sums do not depend on threads.
        std::stable_sort(out.begin(), out.end(), [](const Tap& a, const Tap& b) {
            return std::tie(a.patch, a.lag, a.first, a.tint) < std::tie(b.patch, b.lag, b.first, b.tint);
        });
        std::size_t kept = 0;
        for (const Tap& t : out) {
            const Tap* last = kept > 0 ? &out[kept - 1] : nullptr;
            if (last && last->patch == t.patch && last->lag == t.lag && last->first == t.first && last->tint == t.tint) {
                out[kept - 1].w0 += t.w0;
                out[kept - 1].w1 += t.w1;
            } else {
                out[kept++] = t;
            }
        }
        out.resize(kept);
    });
    FilmTaps merged;
    for (const Rgb& t : gather.tints) merged.tints.push_back({float(t[0]), float(t[1]), float(t[2])});
    merged.row.assign(pixels + 1, 0);
    for (std::size_t px = 0; px < pixels; ++px) merged.row[px + 1] = merged.row[px] + per_pixel[px].size();
    merged.taps.reserve(merged.row[pixels]);
    for (auto& v : per_pixel) {
        merged.taps.insert(merged.taps.end(), v.begin(), v.end());
        std::vector<Tap>().swap(v);
    }
    return merged;
}

TransientFilm::TransientFilm(const Gather& gather, const Illumination& illumination, const TimeAxis& time,
                             DelayMode delay, float* cube, int order, bool last_is_tail, int threads,
                             std::shared_ptr<const FilmTaps> taps)
    : m_gather(gather), m_illumination(illumination), m_time(time), m_cube(cube), m_order(order),
      m_last_is_tail(last_is_tail), m_threads(thread_count(threads)),
      m_taps(taps ? std::move(taps) : std::make_shared<const FilmTaps>(film_taps(gather, time, delay, threads))) {}

bool TransientFilm::takes_order(int order) const {
    return m_order < 0 || order == m_order || (m_last_is_tail && order > m_order);
}

void TransientFilm::add_direct() {
    const double inv_bin = 1.0 / m_time.bin_width_m(), start = m_time.start_m();
    const std::size_t T = std::size_t(m_time.bins);
    for (const DirectArrival& a : m_gather.direct) {
        if (!takes_order(a.order)) continue;
        // A delta at an exact path lies wholly in the bin that contains it.
        const double b = std::floor((a.path - start) * inv_bin);
        if (b < 0 || b >= double(T)) continue;
        float* v = m_cube + (std::size_t(a.pixel) * T + std::size_t(b)) * 3;
        for (int c = 0; c < 3; ++c) v[c] += float(a.radiance[c]);
    }
}

// The block's profiles less the pulses of point and area sources, which the gather evaluates exactly at
// each sensing point.
void TransientFilm::copy_indirect(const SolveBlock& block) {
    const std::size_t n = block.patches, bins = std::size_t(block.bins);
    const float* source = block.radiosity;
    if (m_order >= 0) {
        TPRF_CHECK_LT(m_order, block.terms);
        source = block.per_order + std::size_t(m_order) * n * bins * 3;
    }
    m_indirect.assign(source, source + n * bins * 3);
    const double inv_bin = 1.0 / m_time.bin_width_m(), start = m_time.start_m();
    for (std::size_t i = 0; i < n; ++i)
        for (std::uint64_t k = m_illumination.row[i]; k < m_illumination.row[i + 1]; ++k) {
            const Pulse& p = m_illumination.pulses[k];
            if (!p.exact_at_sensors() || !takes_order(p.order)) continue;
            const double b = std::floor((p.path - start) * inv_bin) - block.first_bin;
            if (b < 0 || b >= double(bins)) continue;
            float* v = m_indirect.data() + (i * bins + std::size_t(b)) * 3;
            // What is left is the light of other orders in that bin; float cancellation must not
            // turn an exact zero into a small negative radiance.
            for (int c = 0; c < 3; ++c) v[c] = std::max(0.0f, v[c] - float(p.energy[c]));
        }
}

// One pixel's taps over the block: each reads its patch's profile and shifts it by the last leg,
// split between two bins.
void TransientFilm::add_taps(std::size_t px, int first_bin, std::size_t bins) {
    const std::int64_t T = m_time.bins;
    float* out = m_cube + px * std::size_t(T) * 3;
    for (std::uint64_t k = m_taps->row[px]; k < m_taps->row[px + 1]; ++k) {
        const FilmTaps::Tap& tap = m_taps->taps[k];
        const std::int64_t whole = tap.lag, first = tap.first;
        const float w0 = tap.w0, w1 = tap.w1;
        const float* tint = tap.tint != 0 ? m_taps->tints[tap.tint].data() : nullptr;
        // Light the patch average puts ahead of the earliest possible arrival goes to that bin.
        const std::int64_t base = first_bin + whole;  // output bin of the block's bin 0 (w0 tap)
        const float* b = m_indirect.data() + std::size_t(tap.patch) * bins * 3;
        // Bins t whose w0 target base + t lies before `first` (and their w1 targets up to it).
        const std::int64_t early = std::clamp<std::int64_t>(first - base, 0, std::int64_t(bins));
        if (early > 0 && first >= 0 && first < T) {
            float carried[3] = {0, 0, 0};
            for (std::int64_t t = 0; t < early; ++t) {
                const float w = w0 + (base + t + 1 <= first ? w1 : 0.0f);
                for (int c = 0; c < 3; ++c) carried[c] += w * b[std::size_t(t) * 3 + std::size_t(c)];
            }
            for (int c = 0; c < 3; ++c) out[std::size_t(first) * 3 + std::size_t(c)] += (tint ? tint[c] : 1.0f) * carried[c];
        }
        // The rest: two contiguous multiply-adds over bins, each clipped to the window [0, T).
        auto add = [&](float w, std::int64_t shift, std::int64_t from) {
            if (w == 0.0f) return;
            const std::int64_t lo = std::max<std::int64_t>(from, -(base + shift));
            const std::int64_t hi = std::min<std::int64_t>(std::int64_t(bins), T - (base + shift));
            if (lo >= hi) return;
            float* __restrict o = out + std::size_t(base + shift + lo) * 3;
            const float* __restrict in = b + std::size_t(lo) * 3;
            const std::size_t len = std::size_t(hi - lo) * 3;
            if (tint) {  // through tinted mirrors: a weight per channel
                const float wc[3] = {w * tint[0], w * tint[1], w * tint[2]};
                for (std::size_t e = 0; e < len; e += 3)
                    for (int c = 0; c < 3; ++c) o[e + std::size_t(c)] += wc[c] * in[e + std::size_t(c)];
                return;
            }
            for (std::size_t e = 0; e < len; ++e) o[e] += w * in[e];
        };
        add(w0, 0, early);
        // A w1 tap at base + t + 1 was carried above when it fell at or before `first`.
        add(w1, 1, std::max<std::int64_t>(0, first - base));
    }
}

void TransientFilm::add_block(const SolveBlock& block) {
    copy_indirect(block);
    const std::size_t pixels = m_gather.row.size() - 1, bins = std::size_t(block.bins);
    parallel_for(pixels, {m_threads, 64, true}, [&](std::size_t px) { add_taps(px, block.first_bin, bins); });
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
