#pragma once
/// The light one link after its pulse: the second bounce of a scene lit by point and area sources
/// (the first bounce's exitance, sent once through the links), apart from the rest of the profiles,
/// and where in time it reaches a point of a patch rather than the patch's centroid.
///
/// A patch profile is the light at the patch's centroid: sender j's first bounce reaches it
/// |c_k - c_j| after leaving j. A point x = c_k + d of patch k gets it |x - c_j| after, so the light
/// that the camera reads at x through patch k's profile is early or late by up to the patch's size in
/// path. For light that left its sender as a pulse (the first bounce: sharp in time), that error is
/// the streak bands at patch size (docs/method.md, "The second bounce at the sample's own time"). The
/// film takes this part out of the profiles and reads it at the sample's own shift: the mean over k's senders,
/// weighted by what each sends, of |x - c_j| - |c_k - c_j|, to second order in d:
///     shift_k(x) = D_k . d + d^T H_k d / 2,   D_k = mean u_j,   H_k = mean (I - u_j u_j^T) / r_j,
/// with u_j = (c_k - c_j) / r_j, r_j = |c_k - c_j|. Later bounces come from senders whose light is
/// spread over time already and keep the centroid's timing.
///
/// Only patch-to-patch links are taken apart: in a hierarchical set, what reaches a patch through a
/// cluster link (its light shared by all the cluster's members, sent from a cluster's mean) stays in
/// the profile with the centroid's timing. No mirrors (make_second_bounce_light says when it applies).

#include "tprf/core/types.h"
#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

namespace tprf {

struct PatchSet;
struct LinkSet;
struct Illumination;

/// How the light one link after its pulse is taken: as the solver places a delay between bins, of the
/// pulses that max_bounces lets on.
struct SecondBounceOptions {
    DelayMode delay = DelayMode::Linear;
    int max_bounces = -1;  ///< the solver's: -1 for all
    int threads = 0;       ///< 0: all cores
};

/// Bins [first, first + count) of a time axis.
struct BinSpan {
    std::int64_t first = 0;
    std::size_t count = 0;
};

class SecondBounceLight {
public:
    SecondBounceLight(const PatchSet& patches, const LinkSet& links, const Illumination& illumination,
                      const TimeAxis& time, const SecondBounceOptions& options = {});

    /// Writes into `rows` the light of the bins `span` that every patch receives through one
    /// patch-to-patch link from a propagating pulse whose onward order `takes(order)` accepts, times the
    /// receiver's albedo: B_i(t) = albedo_i sum_links ff B_pulse(t - delay), the delay split between
    /// bins as the solver splits it. Patch i's bin b (from span.first) is rows[i * stride + b * 3 + c].
    /// lit[i] (resized to N) is 0 where patch i's row is all zero. With `wanted`, only the rows of
    /// patches i with wanted[i] != 0 are computed (the others are zero, and not lit).
    void fill(BinSpan span, const std::function<bool(int)>& takes, float* rows, std::size_t stride,
              std::vector<char>& lit, const std::vector<char>* wanted = nullptr) const;

    /// Extra path, metres, at which point x of patch k receives the light that fill() gives k (its
    /// senders' weighted mean of |x - c_j| - |c_k - c_j|, to second order). 0 for a patch that
    /// receives none.
    double shift(std::uint32_t k, const Vec3& x) const;

    /// The bins [first, second) outside which patch i receives none of that light.
    std::pair<std::int64_t, std::int64_t> bins_of(std::size_t i) const { return {m_lo[i], m_hi[i]}; }

    /// Whether any patch receives such light.
    bool empty() const { return m_any == false; }

private:
    // A sender's pulses of one order, as bins [first, first + length) on the time axis (placed as the
    // solver places them): their exitance times one second, 3 floats per bin at `offset` of m_energy.
    // The light it sends through a link is of order `order` + 1.
    struct Run {
        std::int64_t first;
        std::uint32_t length;
        std::size_t offset;
        std::uint8_t order;
    };
    // Per sender: what it sends in all (the mean over channels, its weight in the shift) and the bins
    // of its first and last pulse.
    struct Senders {
        std::vector<double> weight;
        std::vector<std::int64_t> first, last;
    };
    // The pulses that the links send on, as runs (m_row, m_runs, m_energy).
    Senders take_pulses(const Illumination& illumination, int max_bounces);
    // Receiver i's bins and shift coefficients, from its links; false when it receives nothing.
    bool plan_receiver(std::size_t i, const Senders& senders);

    const PatchSet& m_patches;
    const LinkSet& m_links;
    TimeAxis m_time;
    DelayMode m_delay;
    int m_threads;
    std::vector<std::uint64_t> m_row;    // N + 1 offsets into m_runs
    std::vector<Run> m_runs;
    std::vector<float> m_energy;
    std::vector<std::int64_t> m_lo, m_hi;  // per receiver: the bins [lo, hi) its light can reach
    std::vector<std::array<float, 3>> m_gradient;  // D_k
    std::vector<std::array<float, 6>> m_hessian;   // H_k: xx, yy, zz, xy, xz, yz
    bool m_any = false;
};

/// The second bounce's light of a camera render, or null when it does not apply: mirrors (a link through
/// one does not run from c_j), tinted links, or no light sent through a patch-to-patch link as pulses
/// that max_bounces lets on.
std::unique_ptr<SecondBounceLight> make_second_bounce_light(const PatchSet& patches, const LinkSet& links,
                                                            const Illumination& illumination, const TimeAxis& time,
                                                            const SecondBounceOptions& options, bool mirrors);

}  // namespace tprf
