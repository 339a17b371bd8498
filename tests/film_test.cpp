// The film (imaging/film.h) against its definition, tap by tap: each gather tap reads its patch's
// profile and puts it `leg` later, split between two bins (or in the nearest), and light that would
// come before the earliest bin of the pixel's samples that read that patch is moved to that bin. The
// film merges a pixel's taps of a patch into one kernel, keeps several solver blocks, pads its rows
// and applies short grey kernels in one pass (tinted or long ones a bin of the kernel at a time): none
// of that may change the sums beyond float rounding.

#include "tprf/core/time_axis.h"
#include "tprf/imaging/film.h"
#include "tprf/imaging/gather.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/solver.h"
#include "test_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <tuple>
#include <vector>

namespace {

using tprf::DelayMode;
using tprf::Gather;
using tprf::PixelTap;

constexpr int kPatches = 7, kWidth = 9, kBins = 300, kBlock = 32;
constexpr double kBin = 0.01;

// A gather of kWidth x 1 pixels with taps of every kind: several samples per patch at legs a few bins
// apart (short kernels), one pixel whose taps of a patch span 60 bins (a kernel longer than the
// padding), earliest bins before, inside and after the light, and a tinted pixel.
Gather made_up_gather() {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    Gather g;
    g.width = kWidth;
    g.height = 1;
    g.tints = {tprf::Rgb::Ones(), tprf::Rgb(0.9, 0.5, 0.2)};
    g.row.push_back(0);
    for (int px = 0; px < kWidth; ++px) {
        const double base = 0.3 + 1.5 * unit(rng);  // metres of leg
        for (int s = 0; s < 12; ++s) {
            PixelTap t;
            t.patch = std::uint32_t(rng() % kPatches);
            t.weight = float(0.05 + unit(rng));
            const double spread = px == 4 ? 0.6 : 0.03;  // pixel 4: 60 bins of legs
            t.leg = float(base + spread * unit(rng));
            t.earliest = float(t.leg + (px % 3 == 0 ? 0.4 : px % 3 == 1 ? 1.2 : -0.5) + 0.2 * unit(rng));
            t.tint = std::uint16_t(px == 6 ? 1 : 0);
            g.taps.push_back(t);
        }
        g.row.push_back(g.taps.size());
    }
    return g;
}

// The cube by definition, in double.
std::vector<double> by_definition(const Gather& g, const std::vector<float>& profile, int first_bin, int bins,
                                  const tprf::TimeAxis& time, DelayMode delay) {
    std::vector<double> cube(std::size_t(kWidth) * kBins * 3, 0.0);
    for (int px = 0; px < kWidth; ++px) {
        // The earliest bin of a patch (and tint) is the least over the pixel's samples that read it.
        std::map<std::pair<std::uint32_t, std::uint16_t>, std::int64_t> earliest;
        for (std::uint64_t k = g.row[std::size_t(px)]; k < g.row[std::size_t(px) + 1]; ++k) {
            const PixelTap& t = g.taps[k];
            const auto e = std::int64_t(std::floor((double(t.earliest) - time.start_m()) / time.bin_width_m()));
            auto [it, fresh] = earliest.try_emplace({t.patch, t.tint}, e);
            if (!fresh) it->second = std::min(it->second, e);
        }
        for (std::uint64_t k = g.row[std::size_t(px)]; k < g.row[std::size_t(px) + 1]; ++k) {
            const PixelTap& t = g.taps[k];
            const std::int64_t first = earliest.at({t.patch, t.tint});
            const double lag = double(t.leg) / time.bin_width_m();
            std::vector<std::pair<std::int64_t, double>> split;
            if (delay == DelayMode::Nearest) {
                split = {{std::int64_t(std::floor(lag + 0.5)), 1.0}};
            } else {
                const auto whole = std::int64_t(std::floor(lag));
                split = {{whole, 1.0 - (lag - double(whole))}, {whole + 1, lag - double(whole)}};
            }
            for (int b = 0; b < bins; ++b)
                for (const auto& [shift, share] : split) {
                    std::int64_t u = first_bin + b + shift;
                    if (u < first) u = first;
                    if (u < 0 || u >= kBins) continue;
                    for (int c = 0; c < 3; ++c)
                        cube[(std::size_t(px) * kBins + std::size_t(u)) * 3 + std::size_t(c)] +=
                            double(t.weight) * share * g.tints[t.tint][c] *
                            double(profile[(std::size_t(t.patch) * std::size_t(bins) + std::size_t(b)) * 3 +
                                           std::size_t(c)]);
                }
        }
    }
    return cube;
}

// Films `g` over made-up profiles (from 240 bins before the window to its end, in solver blocks of 32).
struct Filmed {
    std::vector<float> profile, cube;
    int first_bin = -240, bins = kBins + 240;
};

// `lengths`: the blocks' lengths in turn (repeated), or solver blocks of kBlock bins.
Filmed film_of(const Gather& g, const tprf::TimeAxis& time, DelayMode delay, const std::vector<int>& lengths = {}) {
    Filmed f;
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    f.profile.resize(std::size_t(kPatches) * std::size_t(f.bins) * 3);
    for (float& v : f.profile) v = unit(rng);
    tprf::Illumination none;
    none.row.assign(kPatches + 1, 0);
    f.cube.assign(std::size_t(kWidth) * kBins * 3, 0.0f);
    tprf::TransientFilm film(g, none, time, f.cube.data(), {.delay = delay, .threads = 2});
    std::vector<float> block;
    std::size_t turn = 0;
    for (int b0 = 0, n = 0; b0 < f.bins; b0 += n) {
        n = std::min(lengths.empty() ? kBlock : lengths[turn++ % lengths.size()], f.bins - b0);
        block.assign(std::size_t(kPatches) * std::size_t(n) * 3, 0.0f);
        for (int i = 0; i < kPatches; ++i)
            std::copy_n(f.profile.begin() + std::ptrdiff_t((std::size_t(i) * std::size_t(f.bins) + std::size_t(b0)) * 3),
                        n * 3, block.begin() + std::ptrdiff_t(std::size_t(i) * std::size_t(n) * 3));
        tprf::SolveBlock sb;
        sb.first_bin = f.first_bin + b0;
        sb.bins = n;
        sb.patches = kPatches;
        sb.radiosity = block.data();
        film.add_block(sb);
    }
    film.finish();
    return f;
}

tprf::TimeAxis window() {
    tprf::TimeAxis time;
    time.bins = kBins;
    time.bin_width = kBin;
    return time;
}

void check_film(DelayMode delay, const std::vector<int>& lengths = {}) {
    const Gather g = made_up_gather();
    const tprf::TimeAxis time = window();
    const tprf::FilmTaps taps = tprf::film_taps(g, time, delay, 1);
    EXPECT_GT(taps.longest, tprf::kFilmPadBins + 1);  // pixel 4 takes the general path
    ASSERT_LT(taps.taps.size(), g.taps.size());       // merged
    const Filmed f = film_of(g, time, delay, lengths);
    const std::vector<float>& cube = f.cube;
    const std::vector<double> expected = by_definition(g, f.profile, f.first_bin, f.bins, time, delay);
    double peak = 0.0, worst = 0.0;
    for (double v : expected) peak = std::max(peak, v);
    for (std::size_t k = 0; k < cube.size(); ++k) worst = std::max(worst, std::abs(double(cube[k]) - expected[k]));
    ASSERT_GT(peak, 1.0);
    MEASURED("film (%s): worst bin %.2e of the peak, %zu gather taps as %zu kernels\n",
             delay == DelayMode::Linear ? "linear" : "nearest", worst / peak, g.taps.size(), taps.taps.size());
    EXPECT_LT(worst, 2e-6 * peak) << "worst difference " << worst << " of a peak " << peak;
    // Light moved to a pixel's earliest bin: none before it.
    for (int px = 0; px < kWidth; ++px) {
        std::int64_t first = kBins;
        for (std::uint64_t k = g.row[std::size_t(px)]; k < g.row[std::size_t(px) + 1]; ++k)
            first = std::min(first, std::int64_t(std::floor(double(g.taps[k].earliest) / kBin)));
        for (std::int64_t u = 0; u < std::min<std::int64_t>(first, kBins); ++u)
            EXPECT_EQ(cube[(std::size_t(px) * kBins + std::size_t(u)) * 3], 0.0f) << px << " " << u;
    }
}

TEST(Film, KernelsApplyEachSamplesLegSplitBetweenTwoBins) { check_film(DelayMode::Linear); }

TEST(Film, KernelsApplyEachSamplesLegInTheNearestBin) { check_film(DelayMode::Nearest); }

// The solver hands over a short first block and then up to kSinkBins bins (blocks of short solver
// blocks together), longer ones when asked: a film keeps and films any sequence of lengths, filming
// early when the next block would not fit, growing when one is longer than it was sized for.
TEST(Film, BlocksOfChangingLengthsFilmTheSameCube) {
    check_film(DelayMode::Linear, {15, 16, 16, 32, 7, 32, 1, 31, 32, 32, 2});
    check_film(DelayMode::Linear, {3, 32, 32, 300});
}

// gather_points merges a pixel's taps that the film cannot tell apart (merge_taps): the cube must not
// change beyond a float leg's precision (a leg of 2 m is a float to 1.2e-7 m, 1.2e-5 of a 1 cm bin).
TEST(Film, MergedTapsFilmTheSameCube) {
    const Gather g = made_up_gather();
    const tprf::TimeAxis time = window();
    Gather merged = g;
    merged.taps.clear();
    merged.row = {0};
    for (int px = 0; px < kWidth; ++px) {
        std::vector<PixelTap> taps(g.taps.begin() + std::ptrdiff_t(g.row[std::size_t(px)]),
                                   g.taps.begin() + std::ptrdiff_t(g.row[std::size_t(px) + 1]));
        // Each sample twice more, at legs a hundredth and a third of a bin on: the first merges with
        // it (same half bin, unless it crosses into the next), the second mostly not.
        for (std::size_t k = 0, n = taps.size(); k < n; ++k)
            for (const double step : {0.01, 0.33}) {
                PixelTap t = taps[k];
                t.leg = float(double(t.leg) + step * kBin);
                t.weight *= 0.5f;
                taps.push_back(t);
            }
        merged.taps.insert(merged.taps.end(), taps.begin(), taps.end());
        merged.row.push_back(merged.taps.size());
    }
    Gather by_one = merged;  // the same taps, not merged
    std::size_t before = merged.taps.size();
    std::vector<PixelTap> all;
    std::vector<std::uint64_t> row = {0};
    for (int px = 0; px < kWidth; ++px) {
        std::vector<PixelTap> taps(merged.taps.begin() + std::ptrdiff_t(merged.row[std::size_t(px)]),
                                   merged.taps.begin() + std::ptrdiff_t(merged.row[std::size_t(px) + 1]));
        tprf::merge_taps(taps, time);
        all.insert(all.end(), taps.begin(), taps.end());
        row.push_back(all.size());
    }
    merged.taps = all;
    merged.row = row;
    MEASURED("merge_taps: %zu taps -> %zu\n", before, merged.taps.size());
    EXPECT_LT(merged.taps.size(), before * 3 / 4);
    for (const DelayMode delay : {DelayMode::Linear, DelayMode::Nearest}) {
        const Filmed a = film_of(by_one, time, delay), b = film_of(merged, time, delay);
        double peak = 0.0, worst = 0.0;
        for (std::size_t k = 0; k < a.cube.size(); ++k) {
            peak = std::max(peak, double(a.cube[k]));
            worst = std::max(worst, std::abs(double(a.cube[k]) - double(b.cube[k])));
        }
        MEASURED("merged taps (%s): worst bin %.2e of the peak\n", delay == DelayMode::Linear ? "linear" : "nearest",
                 worst / peak);
        EXPECT_LT(worst, 1e-5 * peak);
    }
}

}  // namespace
