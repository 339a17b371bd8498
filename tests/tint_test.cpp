// Tinted links (Links::tint): links through tinted mirrors carry ff x tints[t][c] in colour c. By
// linearity, colour c of a tinted solve is the grey solve of the same links with every tinted link's
// form factor times tints[t][c]; that fixes every answer here in advance.

#include "tprf/transport/solver.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/steady.h"

#include "test_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace tprf {
namespace {

using test::time_axis;

// A gold mirror's reflectance: red most, blue least.
constexpr std::array<float, 3> kGold = {0.9f, 0.5f, 0.2f};

struct Corner {
    PatchSet patches;
    LinkSet links;
};

// A 1 m floor (z = 0) and a 1 m wall (x = 0) meeting along the y axis, grey (albedo 0.6), cut into
// squares of `max_edge`: every link joins the floor and the wall. Flat links, or hierarchical ones for
// bins of 2 cm.
Corner corner(double max_edge, bool hierarchical = false) {
    Scene scene;
    scene.max_edge = max_edge;
    scene.objects.push_back(test::rectangle(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY(), 0.6));  // normal +z
    scene.objects.push_back(test::rectangle(Vec3::Zero(), Vec3::UnitY(), Vec3::UnitZ(), 0.6));  // normal +x
    Corner c;
    c.patches = build_patches(scene);
    const Visibility vis(c.patches);
    LinkSettings settings;
    settings.method = hierarchical ? LinkMethod::Hierarchical : LinkMethod::Flat;
    if (hierarchical) settings.tolerance = 0.05;
    c.links = make_link_set(c.patches, vis, settings, 0.02);
    return c;
}

// Tints with palette entry 1 = `tint` every link between patches whose floor end lies in the floor's
// half y < 0.5, both ways (a path through a mirror is the same either way): about half of every row.
// Returns how many.
std::uint64_t tint_half(LinkSet& set, const PatchSet& patches, const std::array<float, 3>& tint) {
    Links& l = set.links;
    l.tints = {{1.0f, 1.0f, 1.0f}, tint};
    l.tint.assign(l.size(), 0);
    std::uint64_t count = 0;
    for (std::size_t i = 0; i < patches.size(); ++i)
        for (std::uint64_t k = l.row[i]; k < l.row[i + 1]; ++k) {
            const std::uint32_t s = l.source[k];
            if (s >= patches.size()) continue;  // a cluster link: never tinted
            const std::size_t floor_end = patches.object[i] == 0 ? i : s;
            if (patches.centroid[floor_end].y() < 0.5) {
                l.tint[k] = 1;
                ++count;
            }
        }
    return count;
}

// The tinted set made grey for colour c: every tinted link's form factor times its tint's colour c
// (in float, as the solvers take it).
LinkSet grey_for(const LinkSet& tinted, int c) {
    LinkSet out = tinted;
    for (std::uint64_t k = 0; k < out.links.size(); ++k)
        out.links.ff[k] = tinted.links.ff[k] * tinted.links.tint_factor(k, c);
    out.links.tint.clear();
    out.links.tints.clear();
    return out;
}

// Tinted links by where the solver applies them with bins of `bin` metres and blocks of `block` bins:
// within one bin (lag 0), bin by bin (0 < lag < block), a block at a time (lag >= block).
struct LagCounts {
    std::uint64_t same = 0, shorter = 0, longer = 0;
};
LagCounts tinted_lags(const LinkSet& set, double bin, int block) {
    LagCounts n;
    for (std::uint64_t k = 0; k < set.links.size(); ++k) {
        if (set.links.tint[k] == 0) continue;
        const int lag = int(set.links.distance[k] / float(bin));
        (lag == 0 ? n.same : lag < block ? n.shorter : n.longer)++;
    }
    return n;
}

// Grey pulses by hand, illumination k of a batch: three on floor and wall patches, of orders 0 to 2,
// at paths and energies that differ with k.
Illumination pulses(std::size_t n, int k) {
    struct Spec {
        std::size_t patch;
        Pulse pulse;
    };
    std::vector<Spec> specs;
    for (int j = 0; j < 3; ++j) {
        Pulse p;
        p.path = 0.013 + 0.03 * k + 0.21 * j;
        p.energy = Rgb::Constant((1.0 + 0.5 * j) * (k + 1));
        p.order = std::uint8_t(j);
        specs.push_back({(std::size_t(k) * 37 + std::size_t(j) * 53 + 5) % n, p});
    }
    std::stable_sort(specs.begin(), specs.end(), [](const Spec& a, const Spec& b) { return a.patch < b.patch; });
    Illumination e;
    e.row.assign(n + 1, 0);
    for (const Spec& s : specs) {
        e.pulses.push_back(s.pulse);
        ++e.row[s.patch + 1];
    }
    std::partial_sum(e.row.begin(), e.row.end(), e.row.begin());
    return e;
}

// Every illumination's output of one march: the total, then each per-order term, N x bins x 3 each.
struct Marched {
    std::vector<std::vector<float>> out;  // per illumination: (1 + terms) x N x bins x 3
    int terms = 0;
    SolveStats stats;
};

Marched march(const Corner& c, const LinkSet& set, const std::vector<Illumination>& batch, const TimeAxis& time,
          const SolverOptions& options) {
    const std::size_t K = batch.size(), n = c.patches.size(), bins = std::size_t(time.bins);
    std::vector<const Illumination*> pointers;
    for (const Illumination& e : batch) pointers.push_back(&e);
    Marched run;
    run.out.resize(K);
    run.stats = solve_transient(c.patches, set, std::span<const Illumination* const>(pointers), time, options,
                                [&](const SolveBlock& b) {
        run.terms = b.terms;
        const std::size_t layer = b.patches * std::size_t(b.bins) * K * 3;
        for (std::size_t k = 0; k < K; ++k) {
            run.out[k].resize((1 + std::size_t(b.terms)) * n * bins * 3);
            for (int term = 0; term <= b.terms; ++term) {
                const float* from = term == 0 ? b.radiosity : b.per_order + std::size_t(term - 1) * layer;
                for (std::size_t i = 0; i < n; ++i)
                    for (int t = 0; t < b.bins; ++t)
                        for (std::size_t ch = 0; ch < 3; ++ch)
                            run.out[k][((std::size_t(term) * n + i) * bins + std::size_t(b.first_bin + t)) * 3 + ch] =
                                from[((i * std::size_t(b.bins) + std::size_t(t)) * K + k) * 3 + ch];
            }
        }
    });
    return run;
}

// The largest difference between colour c of `tinted` and colour c of `grey` over every profile (patch,
// illumination and term), relative to that profile's peak in `grey`; infinite where `grey` has no light
// and `tinted` has some. `tail`: the last term is every order from its index on, the total less the
// exact orders, so its rounding is the total's: it is measured against the patch's total peak (as in
// the solver's batch tests).
double worst_relative(const Marched& tinted, const Marched& grey, int c, std::size_t n, bool tail = false) {
    EXPECT_EQ(tinted.terms, grey.terms);
    const std::size_t terms = 1 + std::size_t(grey.terms);
    double worst = 0.0;
    for (std::size_t k = 0; k < grey.out.size(); ++k) {
        const std::size_t bins = grey.out[k].size() / (3 * n * terms);
        auto peak_diff = [&](std::size_t profile) {
            double peak = 0.0, diff = 0.0;
            for (std::size_t t = 0; t < bins; ++t) {
                const std::size_t at = (profile * bins + t) * 3 + std::size_t(c);
                peak = std::max(peak, double(std::abs(grey.out[k][at])));
                diff = std::max(diff, double(std::abs(tinted.out[k][at] - grey.out[k][at])));
            }
            return std::pair{peak, diff};
        };
        for (std::size_t profile = 0; profile < n * terms; ++profile) {
            auto [peak, diff] = peak_diff(profile);
            if (tail && terms > 1 && profile / n == terms - 1) peak = peak_diff(profile % n).first;
            if (diff > 0.0) worst = std::max(worst, peak > 0.0 ? diff / peak : INFINITY);
        }
    }
    return worst;
}

// How far apart two colours of one run are, as worst_relative measures: the tint has to show.
double colour_spread(const Marched& run, std::size_t n) {
    Marched red = run;
    for (std::vector<float>& v : red.out)
        for (std::size_t e = 0; e < v.size(); e += 3) v[e + 2] = v[e];  // red into the blue channel
    return worst_relative(run, red, 2, n);
}

// Why 2e-6: colour c of a tinted link has the very taps that a grey link of form factor ff x tint[c]
// has (the same float product, split by the same delay_taps_f), and every other link is the same in both
// solves. What differs is the order of the float sums: the tinted links are summed after the grey ones
// of their row, in lists of their own. A sum of a row's 64 positive terms in another order moves by a
// few units of float epsilon (1.2e-7), and that compounds over the bounces (measured: at most 8.7e-7 of
// a profile's peak, on a faint third-order term). Where the same-bin sweeps stop may differ too: the
// tinted solve judges its three colours together, so a colour may take a sweep more or less than in its
// grey solve, each moving a value by at most 1e-7 of the bin's largest (the solver's batch tests argue
// the same). Gold's red and blue differ by most of a profile's peak (colour_spread: 0.78 and more).
constexpr double kTolerance = 2e-6;

// Colour c of the tinted set's march equals the grey march of grey_for(c), for every c; the tint shows.
void expect_channels_are_grey_solves(const Corner& c, const LinkSet& tinted, const std::vector<Illumination>& batch,
                                     const TimeAxis& time, const SolverOptions& options, const std::string& name) {
    const Marched run = march(c, tinted, batch, time, options);
    EXPECT_EQ(run.stats.channels, 3) << name;
    EXPECT_EQ(run.stats.working_bytes,
              solve_working_bytes(c.patches, tinted, time, options, int(batch.size()), 3)) << name;
    for (int ch = 0; ch < 3; ++ch) {
        const Marched grey = march(c, grey_for(tinted, ch), batch, time, options);
        ASSERT_EQ(grey.stats.channels, 1) << name;
        const bool tail = options.max_bounces < 0 && options.bounce_terms > 1;
        const double worst = worst_relative(run, grey, ch, c.patches.size(), tail);
        MEASURED("%s, colour %d: %.3g\n", name.c_str(), ch, worst);
        EXPECT_LE(worst, kTolerance) << name << ", colour " << ch;
    }
    // Gold: red and blue differ by a sizeable share of the profiles' peaks.
    const double spread = colour_spread(run, c.patches.size());
    MEASURED("%s, red - blue: %.3g\n", name.c_str(), spread);
    EXPECT_GT(spread, 0.05) << name;
}

// Schedules that put the tinted links within one bin, bin by bin and a block at a time: on the corner of
// 8 x 8 squares, delays of 4 to 75 bins of 2 cm (blocks of 32: short and long; of 4: long, in windows of
// 4 to 32 for the grey links); bins of 10 cm put the squares along the edge (8.8 cm apart) within one bin.
struct Schedule {
    const char* name;
    TimeAxis time;
    int block_bins;
    bool same, shorter, longer;  // which kinds of tinted links it has
};
const Schedule kSchedules[] = {
    {"2 cm bins, blocks of 32", time_axis(250, 0.02), 32, false, true, true},
    {"2 cm bins, blocks of 4", time_axis(250, 0.02), 4, false, false, true},
    {"10 cm bins", time_axis(50, 0.1), 32, true, true, false},
};

TEST(SolverTint, EachColourIsTheGreySolveOfItsTint) {
    Corner c = corner(0.125);
    ASSERT_EQ(c.patches.size(), 128u);
    const std::uint64_t tinted = tint_half(c.links, c.patches, kGold);
    EXPECT_GT(tinted, c.links.links.size() / 4);
    EXPECT_LT(tinted, c.links.links.size() * 3 / 4);
    const std::vector<Illumination> one = {pulses(c.patches.size(), 0)};
    for (const Schedule& s : kSchedules) {
        const LagCounts lags = tinted_lags(c.links, s.time.bin_width, s.block_bins);
        EXPECT_EQ(lags.same > 0, s.same) << s.name;
        EXPECT_EQ(lags.shorter > 0, s.shorter) << s.name;
        EXPECT_EQ(lags.longer > 0, s.longer) << s.name;
        for (DelayMode mode : {DelayMode::Linear, DelayMode::Nearest}) {
            SolverOptions options;
            options.block_bins = s.block_bins;
            options.delay = mode;
            expect_channels_are_grey_solves(c, c.links, one, s.time, options,
                                            std::string(s.name) + (mode == DelayMode::Linear ? ", linear" : ", nearest"));
        }
    }
}

TEST(SolverTint, BatchesAndPerOrderTermsAreTheGreySolves) {
    // Two illuminations in one march (6 lanes), the total alone, orders 0..3 exactly (max_bounces), and
    // orders 0..3 plus the tail.
    Corner c = corner(0.125);
    tint_half(c.links, c.patches, kGold);
    const std::vector<Illumination> two = {pulses(c.patches.size(), 0), pulses(c.patches.size(), 1)};
    SolverOptions total, exact, tail;
    exact.max_bounces = 3;
    exact.bounce_terms = 1;
    tail.bounce_terms = 5;
    for (const Schedule& s : kSchedules)
        for (SolverOptions options : {total, exact, tail}) {
            options.block_bins = s.block_bins;
            const std::string name = std::string(s.name) + ", max_bounces " + std::to_string(options.max_bounces) +
                                     ", bounce_terms " + std::to_string(options.bounce_terms);
            expect_channels_are_grey_solves(c, c.links, two, s.time, options, name);
        }
}

TEST(SolverTint, HierarchicalLinksAreTheGreySolves) {
    // 512 patches with cluster links, K = 2; the tinted ones are patch-to-patch links, bin by bin and a
    // block at a time (the set keeps blocks as short as its shortest cluster link).
    Corner c = corner(0.0625, true);
    ASSERT_GT(c.links.nodes(), c.links.patches());
    const std::uint64_t tinted = tint_half(c.links, c.patches, kGold);
    ASSERT_GT(tinted, 0u);
    const TimeAxis time = time_axis(200, 0.02);
    SolverOptions options;
    const std::vector<Illumination> two = {pulses(c.patches.size(), 0), pulses(c.patches.size(), 1)};
    const int block = solve_transient(c.patches, c.links, two[0], time, options, {}).block_bins;
    const LagCounts lags = tinted_lags(c.links, time.bin_width, block);
    MEASURED("hierarchical: blocks of %d, tinted links %llu short, %llu long\n", block,
             (unsigned long long)lags.shorter, (unsigned long long)lags.longer);
    EXPECT_GT(lags.shorter, 0u);
    EXPECT_GT(lags.longer, 0u);
    expect_channels_are_grey_solves(c, c.links, two, time, options, "hierarchical");
}

TEST(SolverTint, SteadyStateOfEachColourIsTheGreyOne) {
    // BiCGSTAB stops at a relative residual of 1e-8 on each system; the corner's systems are well
    // conditioned (albedo 0.6, rows summing to at most 1), so each solution is within about 1e-7 of its
    // exact value: 1e-6 of the largest radiosity. The Neumann sums (max_bounces) differ by rounding only.
    for (const bool hierarchical : {false, true}) {
        Corner c = corner(hierarchical ? 0.0625 : 0.125, hierarchical);
        tint_half(c.links, c.patches, kGold);
        const Illumination e = pulses(c.patches.size(), 1);
        for (const int bounces : {-1, 3}) {
            const std::vector<Rgb> tinted = solve_steady(c.patches, c.links, e, bounces);
            std::vector<double> largest(3, 0.0);
            for (int ch = 0; ch < 3; ++ch) {
                const std::vector<Rgb> grey = solve_steady(c.patches, grey_for(c.links, ch), e, bounces);
                double worst = 0.0;
                for (std::size_t i = 0; i < grey.size(); ++i) {
                    largest[std::size_t(ch)] = std::max(largest[std::size_t(ch)], grey[i][ch]);
                    worst = std::max(worst, std::abs(tinted[i][ch] - grey[i][ch]));
                }
                MEASURED("steady, hierarchical %d, bounces %d, colour %d: %.3g\n", int(hierarchical), bounces, ch,
                         worst / largest[std::size_t(ch)]);
                EXPECT_LE(worst, 1e-6 * largest[std::size_t(ch)])
                    << "hierarchical " << hierarchical << ", bounces " << bounces << ", colour " << ch;
            }
            // The tint shows: some patches' reflected light (less the pulses' exitance) is markedly
            // redder than blue.
            double spread = 0.0, peak = 0.0;
            for (std::size_t i = 0; i < tinted.size(); ++i) {
                Rgb reflected = tinted[i];
                for (std::uint64_t k = e.row[i]; k < e.row[i + 1]; ++k) reflected -= e.pulses[k].energy;
                spread = std::max(spread, reflected[0] - reflected[2]);
                peak = std::max(peak, reflected[0]);
            }
            MEASURED("steady, hierarchical %d, bounces %d: red - blue up to %.3g of the peak\n", int(hierarchical),
                     bounces, spread / peak);
            // (measured: a third flat, 1% to 9% hierarchical, whose cluster links carry most of the light).
            EXPECT_GT(spread, 0.005 * peak) << "hierarchical " << hierarchical << ", bounces " << bounces;
        }
    }
}

TEST(SolverTint, GreyTintsMarchOneColour) {
    // A tint of {1, 1, 1} changes nothing, to the bit; {0.5, 0.5, 0.5} marches one lane, as the grey set
    // with those form factors halved does.
    const Corner plain = corner(0.125);
    const std::vector<Illumination> one = {pulses(plain.patches.size(), 0)};
    for (const Schedule& s : kSchedules) {
        SolverOptions options;
        options.block_bins = s.block_bins;
        Corner c = plain;
        tint_half(c.links, c.patches, {1.0f, 1.0f, 1.0f});
        const Marched untinted = march(plain, plain.links, one, s.time, options), white = march(c, c.links, one, s.time, options);
        EXPECT_EQ(white.stats.channels, 1) << s.name;
        EXPECT_TRUE(white.out == untinted.out) << s.name;
        EXPECT_EQ(white.stats.working_bytes, untinted.stats.working_bytes) << s.name;
        const std::vector<Rgb> a = solve_steady(c.patches, c.links, one[0]), b = solve_steady(plain.patches, plain.links, one[0]);
        EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin(), b.end(), [](const Rgb& x, const Rgb& y) { return (x == y).all(); }))
            << s.name;

        tint_half(c.links, c.patches, {0.5f, 0.5f, 0.5f});
        const Marched half = march(c, c.links, one, s.time, options), grey = march(c, grey_for(c.links, 0), one, s.time, options);
        EXPECT_EQ(half.stats.channels, 1) << s.name;
        const double worst = worst_relative(half, grey, 0, c.patches.size());
        MEASURED("grey tint, %s: %.3g\n", s.name, worst);
        EXPECT_LE(worst, kTolerance) << s.name;
        // Halving half the links dims the light: the comparison is not between two untinted solves.
        EXPECT_GT(worst_relative(half, untinted, 0, c.patches.size()), 0.01) << s.name;
    }
}

TEST(SolverTint, RejectsMalformedTints) {
    Corner c = corner(0.25);
    const std::vector<Illumination> one = {pulses(c.patches.size(), 0)};
    const TimeAxis time = time_axis(20, 0.1);
    tint_half(c.links, c.patches, kGold);
    LinkSet short_tint = c.links, bad_index = c.links, bad_grey = c.links;
    short_tint.links.tint.pop_back();
    bad_index.links.tint[0] = 2;
    bad_grey.links.tints[0] = {0.5f, 1.0f, 1.0f};
    for (const LinkSet* set : {&short_tint, &bad_index, &bad_grey}) {
        EXPECT_THROW(march(c, *set, one, time, {}), InternalError);
        EXPECT_THROW(solve_steady(c.patches, *set, one[0]), InternalError);
    }
}

}  // namespace
}  // namespace tprf
