#pragma once
/// The scene's time axis (docs/scene.md: `time`), and the one rule that places an optical path
/// or a delay on its bins: every stage that bins light (pulses, arrivals, taps, links) calls these.

#include <cmath>
#include <cstdint>

namespace tprf {

/// The unit the scene's time axis is written in.
enum class TimeUnit { Metres, Picoseconds };

/// The unit as the scene file writes it: "m" or "ps".
inline const char* unit_name(TimeUnit u) { return u == TimeUnit::Picoseconds ? "ps" : "m"; }

/// How a delay that falls between two bins is placed.
enum class DelayMode { Nearest, Linear };

/// A delay of a fractional number of bins on two bins: bin `first` takes 1 - `frac` of it and bin
/// first + 1 takes `frac`. Linear spreads a bin of the source (taken as uniform over the bin) over the
/// two bins it overlaps once shifted, so that the mean arrival is exact and no energy is lost; Nearest
/// rounds to one bin (`frac` 0).
struct BinSplit {
    std::int64_t first = 0;
    double frac = 0.0;
};

/// The split of a delay of `lag` bins, in double precision (films, captures).
inline BinSplit split_lag(double lag, DelayMode mode) {
    if (mode == DelayMode::Nearest) return {std::int64_t(std::floor(lag + 0.5)), 0.0};
    const double whole = std::floor(lag);
    return {std::int64_t(whole), lag - whole};
}

/// A delay as two taps of a weight: B[t - lag] * w0 + B[t - lag - 1] * w1 (the split of BinSplit, times
/// the weight), in single precision for the solver's per-link loops.
struct DelayTaps {
    int lag;
    float w0;
    float w1;
};

/// Whole bins of a delay of `delay_m` metres in single precision, `inv_bin` being the reciprocal of the
/// bin width in float: truncation, the floor of a non-negative delay.
inline int delay_bins_f(float delay_m, float inv_bin) { return int(delay_m * inv_bin); }

/// The taps of a delay of `delay_m` metres and weight `weight`, in single precision (`inv_bin` as
/// delay_bins_f): it runs once per link and block in the solver's hot loops. Delays stay below 2^24
/// bins, so the fraction keeps at least a few thousandths of a bin.
inline DelayTaps delay_taps_f(float delay_m, float inv_bin, DelayMode mode, float weight) {
    const float d = delay_m * inv_bin;
    if (mode == DelayMode::Nearest) return {int(d + 0.5f), weight, 0.0f};
    const int lag = int(d);  // d >= 0: truncation is the floor
    const float frac = d - float(lag);
    return {lag, weight * (1.0f - frac), weight * frac};
}

/// A time axis's bins in metres of optical path, with the reciprocal of the bin width worked out once
/// (TimeAxis::bin_map): inline, for loops over pulses, arrivals and taps.
struct BinMap {
    double start_m = 0.0;  ///< start of bin 0, metres of optical path
    double inv_bin = 0.0;  ///< bins per metre: the reciprocal of the bin width

    /// Where path `path_m` lies on the axis, in bins: bin k holds the positions [k, k + 1).
    double position(double path_m) const { return (path_m - start_m) * inv_bin; }
    /// The bin that holds path `path_m` (exact containment: a delta at that path lies wholly in it), as
    /// a whole double: < 0 before the window, >= bins after it.
    double bin_floor(double path_m) const { return std::floor(position(path_m)); }
    /// bin_floor as an integer.
    std::int64_t bin(double path_m) const { return std::int64_t(bin_floor(path_m)); }
    /// A delay of `leg_m` metres, in (fractional) bins.
    double lag(double leg_m) const { return leg_m * inv_bin; }
    /// A delay of `leg_m` metres on two bins (split_lag).
    BinSplit split(double leg_m, DelayMode mode) const { return split_lag(lag(leg_m), mode); }
};

/// The time axis: bin k holds optical paths with start + k*bin_width <= path < start + (k+1)*bin_width.
struct TimeAxis {
    int bins = 0;                        ///< T > 0
    double bin_width = 0.0;              ///< > 0, in `unit`
    double start = 0.0;                  ///< in `unit`
    TimeUnit unit = TimeUnit::Metres;

    /// Bin width as an optical path length, metres.
    double bin_width_m() const;
    /// Start of bin 0 as an optical path length, metres.
    double start_m() const;
    /// The end of the last bin, in `unit`.
    double end() const { return start + bins * bin_width; }
    /// Converts a length in `unit` to metres of optical path.
    double to_metres(double value_in_unit) const;
    /// The axis's bins in metres (BinMap): where paths and delays fall.
    BinMap bin_map() const { return {start_m(), 1.0 / bin_width_m()}; }
    /// The reciprocal of the bin width in single precision, as the solver's loops take it (delay_taps_f).
    float inv_bin_f() const { return float(1.0 / bin_width_m()); }
};

/// Bins before the window whose light a sensor still sees inside it, when what leaves a surface at
/// path p reaches the sensor at p + leg and the longest such leg is `longest_leg_m`: from start less
/// that leg (not before path 0), one bin more for a linear split's second tap. 0 when the window
/// starts at 0 or there is no leg.
int bins_before_window(const TimeAxis& time, double longest_leg_m);

}  // namespace tprf
