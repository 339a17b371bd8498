#pragma once
/// The film: turns solved patch profiles and the camera's gather into the (H, W, T, 3) cube and the
/// steady image.

#include "tprf/core/types.h"
#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace tprf {

struct Gather;
struct Illumination;
struct SolveBlock;
class SecondBounceLight;

/// A gather's taps as the films apply them: one short delay kernel per patch (and tint) a pixel
/// reads. Each gather tap is split between two bins as the delay mode says (or put in the nearest),
/// and a pixel's taps of one patch are summed into one kernel over the bins their legs span (a
/// pixel's samples' legs differ by a few bins at most), so that each profile is read once per pixel
/// and each of its bins costs one multiply-add per bin of the kernel, not two per sample and
/// neighbour. The films' work is linear in the weights: the merge changes only float rounding.
struct FilmTaps {
    /// out[t + lag + k] += weights[offset + k] B[t] for k < length; light that would reach a bin
    /// before `first` is moved to it (the earliest bound of the pixel's samples that read the patch).
    struct Tap {
        std::uint32_t patch;
        std::int32_t lag;      ///< whole bins of the shortest leg
        std::int64_t first;    ///< the earliest bin any of its light may reach
        std::uint64_t offset;  ///< of its kernel in `weights`
        std::uint32_t length;  ///< bins of the kernel (>= 1)
        std::uint16_t tint;    ///< index into `tints` (0: grey): channel c's weights times tints[tint][c]
    };
    std::vector<std::uint64_t> row;  ///< pixels + 1 offsets into `taps`
    std::vector<Tap> taps;
    std::vector<float> weights;      ///< the taps' kernels, one after another
    std::uint32_t longest = 1;       ///< the longest kernel's length
    std::vector<std::array<float, 3>> tints;  ///< Gather::tints
};

/// The film taps of `gather` on `time` (in an order that does not depend on `threads`): at each
/// tap's leg, or (`shifted`) at its leg plus its shift (PixelTap::shift).
FilmTaps film_taps(const Gather& gather, const TimeAxis& time, DelayMode delay, int threads = 0,
                   bool shifted = false);

/// How much of the solve's output a film keeps before filming it (TransientFilm::add_block).
inline constexpr std::size_t kFilmBufferBytes = std::size_t(16) << 20;
inline constexpr std::size_t kFilmBufferBins = 256;
/// Kernels of up to this many bins plus one are applied in one pass (the film's rows are padded with
/// this many zero bins on each side); longer ones, rare, a bin of the kernel at a time.
inline constexpr std::size_t kFilmPadBins = 31;

/// Bins of the solve's output a film keeps for `patches` patches and solver blocks of up to `block_bins`
/// (TransientFilm asks for kSinkBins, the solver's longest): as many whole blocks as kFilmBufferBytes
/// hold, up to kFilmBufferBins, at least one.
inline std::size_t film_buffer_bins(std::size_t patches, std::size_t block_bins) {
    const std::size_t fit = kFilmBufferBytes / std::max<std::size_t>(1, patches * 3 * sizeof(float));
    return std::max(block_bins, std::min(fit, kFilmBufferBins) / block_bins * block_bins);
}

/// Bytes of one film's kept profiles (an upper bound: its rows' padding as if some kernel were long).
inline double film_buffer_bytes(std::size_t patches, std::size_t block_bins) {
    return double(patches) * 3 * sizeof(float) * double(film_buffer_bins(patches, block_bins) + 2 * kFilmPadBins);
}

/// What the solver's block sink feeds (film_sink): a film turns the solved patch profiles, block by
/// block in time order, into its outputs. TransientFilm films a camera's pixels and CaptureFilm
/// (imaging/capture_film.h) a capture's sensor points alike: each reads every profile less the pulses
/// that its sensing points take exactly (it adds their light at its exact paths) through its outputs'
/// taps, each tap's leg split between two bins.
class Film {
public:
    virtual ~Film() = default;
    /// One solved block (blocks come in order, without gaps).
    virtual void add_block(const SolveBlock& block) = 0;
    /// Films what it kept: call it after the last block.
    virtual void finish() = 0;
};

/// The solver's sink (solve_transient) that hands every block to each of `films` in turn, adding the
/// seconds they take to `seconds`.
BlockSink film_sink(std::span<Film* const> films, double& seconds);

/// How a TransientFilm reads the profiles.
struct FilmOptions {
    DelayMode delay = DelayMode::Linear;  ///< how a tap's leg is split between bins
    /// -1 for all orders; k >= 0 to film one per-order term (SolveBlock::per_order[k]), the last term
    /// holding every order >= k when `last_is_tail`.
    int order = -1;
    bool last_is_tail = false;
    int threads = 0;                      ///< 0: all cores
    /// film_taps(gather, time, delay), when another film of the same gather has them; made here when null.
    std::shared_ptr<const FilmTaps> taps = nullptr;
};

/// Accumulates radiance into a transient cube of shape (H, W, T, 3), pixel-major (each pixel's time
/// profile contiguous), which the caller owns (typically a memory-mapped .npy). Bin values are
/// radiance times seconds (W s / (m^2 sr)) arriving in the bin.
class TransientFilm : public Film {
public:
    TransientFilm(const Gather& gather, const Illumination& illumination, const TimeAxis& time, float* cube,
                  FilmOptions options = {});

    /// The taps this film applies (to share with the other films of the same gather).
    const std::shared_ptr<const FilmTaps>& taps() const { return m_taps; }

    /// Reads the light one link after its pulse (`light`: SecondBounceLight::fill of the orders this film
    /// takes) apart from the rest of each profile, at each tap's leg plus its shift: `shifted` is
    /// film_taps(..., true) of the same gather, when another film has them (made here when null).
    /// Call before the first block. The light filmed is the same; only its timing at each sample moves.
    void read_second_bounce_apart(const SecondBounceLight* light, std::shared_ptr<const FilmTaps> shifted = nullptr);
    /// The shifted taps (null unless read_second_bounce_apart was called).
    const std::shared_ptr<const FilmTaps>& shifted_taps() const { return m_shifted; }

    /// Adds the exact direct-light arrivals (once).
    void add_direct();
    /// Adds one solved block's light of later bounces: each tap reads its patch's profile (less the
    /// pulses the camera evaluates exactly) and spreads it over the pixel's legs (its kernel). Blocks
    /// come in order; they are kept until kFilmBufferBytes of them (at most kFilmBufferBins bins) are
    /// there and filmed together, so that each pixel's profile is visited in fewer, longer runs.
    void add_block(const SolveBlock& block) override;
    /// Films the blocks still kept: call it after the last add_block.
    void finish() override;

private:
    bool takes_order(int order) const;
    void copy_indirect(const SolveBlock& block);
    /// One pixel's taps over the kept bins (`rows`: m_indirect or m_first; `lit`: m_first_lit, or null).
    void add_taps(const FilmTaps& taps, const std::vector<float>& rows, const std::vector<char>* lit,
                  std::size_t pixel);
    void add_kernel(const FilmTaps& taps, const FilmTaps::Tap& tap, const float* profile, std::int64_t base,
                    std::int64_t bins, float* out) const;
    void add_fused(const FilmTaps& taps, const FilmTaps::Tap& tap, const float* profile, std::int64_t base,
                   std::int64_t bins, float* out) const;

    const Gather& m_gather;
    const Illumination& m_illumination;
    TimeAxis m_time;
    float* m_cube;
    int m_order;
    bool m_last_is_tail;
    int m_threads;
    DelayMode m_delay;
    /// The kept blocks' profiles: N rows of `m_pad` zero bins, `m_capacity` bins (the kept ones, then
    /// zeros) and `m_pad` zero bins (x 3), so that a kernel of up to m_pad + 1 bins reads every bin it
    /// needs without a test.
    std::vector<float> m_indirect;
    int m_first_bin = 0;          ///< the first kept bin
    std::size_t m_kept = 0;       ///< bins kept
    std::size_t m_capacity = 0;   ///< bins a row holds (0 until the first block)
    std::shared_ptr<const FilmTaps> m_taps;
    std::int64_t m_pad = 0;
    /// read_second_bounce_apart: the light one link after its pulse, in rows laid out as m_indirect's
    /// (which then hold the rest), and the taps that read it.
    const SecondBounceLight* m_second_bounce = nullptr;
    std::shared_ptr<const FilmTaps> m_shifted;
    std::vector<float> m_first;
    std::vector<char> m_first_lit;  // per patch: whether its row of m_first holds any light
    std::vector<char> m_first_read; // per patch: whether a shifted tap reads it
};

/// The steady image, H x W x 3 (radiance, W/(m^2 sr)), from steady patch radiosities: the same
/// taps and exact direct light, without time.
std::vector<float> steady_image(const Gather& gather, const Illumination& illumination, const std::vector<Rgb>& steady);

}  // namespace tprf
