#pragma once
/// The film: turns solved patch profiles and the camera's gather into the (H, W, T, 3) cube and the
/// steady image.

#include "tprf/core/types.h"
#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace tprf {

struct Gather;
struct Illumination;
struct SolveBlock;

/// A gather's taps as the films apply them: each split between two bins as the delay mode says, and a
/// pixel's taps merged wherever they share a patch, a lag and a first bin (a pixel's samples mostly
/// do), so that each profile is read a few times per pixel, not once per sample and neighbour. The
/// films' work is linear in the two weights: the merge changes only float rounding.
struct FilmTaps {
    /// out[t + lag] += w0 B[t] and out[t + lag + 1] += w1 B[t]; light before bin `first` is moved to it
    /// (the earliest bound of its samples).
    struct Tap {
        std::uint32_t patch;
        std::int32_t lag;    ///< whole bins of the leg
        std::int64_t first;  ///< the earliest bin any of its light may reach
        float w0, w1;
        std::uint16_t tint;  ///< index into `tints` (0: grey): channel c's weights are w0, w1 times tints[tint][c]
    };
    std::vector<std::uint64_t> row;  ///< pixels + 1 offsets into `taps`
    std::vector<Tap> taps;
    std::vector<std::array<float, 3>> tints;  ///< Gather::tints
};

/// The film taps of `gather` on `time` (in an order that does not depend on `threads`).
FilmTaps film_taps(const Gather& gather, const TimeAxis& time, DelayMode delay, int threads = 0);

/// Accumulates radiance into a transient cube of shape (H, W, T, 3), pixel-major (each pixel's time
/// profile contiguous), which the caller owns (typically a memory-mapped .npy). Bin values are
/// radiance times seconds (W s / (m^2 sr)) arriving in the bin.
class TransientFilm {
public:
    /// `order`: -1 for all orders; k >= 0 to film one per-order term (SolveBlock::per_order[k]), the
    /// last term holding every order >= k when `last_is_tail`.
    /// `taps`: film_taps(gather, time, delay), when another film of the same gather has them; made here
    /// when null.
    TransientFilm(const Gather& gather, const Illumination& illumination, const TimeAxis& time, DelayMode delay,
                  float* cube, int order = -1, bool last_is_tail = false, int threads = 0,
                  std::shared_ptr<const FilmTaps> taps = nullptr);

    /// The taps this film applies (to share with the other films of the same gather).
    const std::shared_ptr<const FilmTaps>& taps() const { return m_taps; }

    /// Adds the exact direct-light arrivals (once).
    void add_direct();
    /// Adds one solved block's light of later bounces: each tap reads its patch's profile (less the
    /// pulses the camera evaluates exactly) and shifts it by the camera leg, split between two bins.
    void add_block(const SolveBlock& block);

private:
    bool takes_order(int order) const;
    void copy_indirect(const SolveBlock& block);
    void add_taps(std::size_t pixel, int first_bin, std::size_t bins);

    const Gather& m_gather;
    const Illumination& m_illumination;
    TimeAxis m_time;
    float* m_cube;
    int m_order;
    bool m_last_is_tail;
    int m_threads;
    std::vector<float> m_indirect;  ///< N x bins x 3 scratch, one block
    std::shared_ptr<const FilmTaps> m_taps;
};

/// The steady image, H x W x 3 (radiance, W/(m^2 sr)), from steady patch radiosities: the same
/// taps and exact direct light, without time.
std::vector<float> steady_image(const Gather& gather, const Illumination& illumination, const std::vector<Rgb>& steady);

}  // namespace tprf
