#pragma once
/// The film: turns solved patch profiles and the camera's gather into the (H, W, T, 3) cube and the
/// steady image.

#include "tprf/core/types.h"
#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"

#include <cstdint>
#include <vector>

namespace tprf {

struct Gather;
struct Illumination;
struct SolveBlock;

/// Accumulates radiance into a transient cube of shape (H, W, T, 3), pixel-major (each pixel's time
/// profile contiguous), which the caller owns (typically a memory-mapped .npy). Bin values are
/// radiance times seconds (W s / (m^2 sr)) arriving in the bin.
class TransientFilm {
public:
    /// `order`: -1 for all orders; k >= 0 to film one per-order term (SolveBlock::per_order[k]), the
    /// last term holding every order >= k when `last_is_tail`.
    TransientFilm(const Gather& gather, const Illumination& illumination, const TimeAxis& time, DelayMode delay,
                  float* cube, int order = -1, bool last_is_tail = false, int threads = 0);

    /// Adds the exact direct-light arrivals (once).
    void add_direct();
    /// Adds one solved block's light of later bounces: each tap reads its patch's profile (less the
    /// pulses the camera evaluates exactly) and shifts it by the camera leg, split between two bins.
    void add_block(const SolveBlock& block);

private:
    /// A pixel's taps on one patch that land alike, summed: out[t + lag] += w0 B[t], out[t + lag + 1]
    /// += w1 B[t], light before bin `first` moved to it (the earliest bound of its samples).
    struct Tap {
        std::uint32_t patch;
        std::int32_t lag;    ///< whole bins of the leg
        std::int64_t first;  ///< the earliest bin any of its light may reach
        float w0, w1;
    };

    bool takes_order(int order) const;
    void merge_taps();
    void copy_indirect(const SolveBlock& block);
    void add_taps(std::size_t pixel, int first_bin, std::size_t bins);

    const Gather& m_gather;
    const Illumination& m_illumination;
    TimeAxis m_time;
    DelayMode m_delay;
    float* m_cube;
    int m_order;
    bool m_last_is_tail;
    int m_threads;
    std::vector<float> m_indirect;  ///< N x bins x 3 scratch, one block
    /// The gather's taps split between bins as the delay mode says and merged per pixel wherever they
    /// share a patch, a lag and a first bin (a pixel's samples mostly do): each profile is read a
    /// few times per pixel, not once per sample and neighbour.
    std::vector<std::uint64_t> m_row;
    std::vector<Tap> m_taps;
};

/// The steady image, H x W x 3 (radiance, W/(m^2 sr)), from steady patch radiosities: the same
/// taps and exact direct light, without time.
std::vector<float> steady_image(const Gather& gather, const Illumination& illumination, const std::vector<Rgb>& steady);

}  // namespace tprf
