#pragma once
/// The scene's time axis (SPEC.md, "Scene file": `time`).

namespace tprf {

/// The unit the scene's time axis is written in.
enum class TimeUnit { Metres, Picoseconds };

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
    /// Converts a length in `unit` to metres of optical path.
    double to_metres(double value_in_unit) const;
};

/// Bins before the window whose light a sensor still sees inside it, when what leaves a surface at
/// path p reaches the sensor at p + leg and the longest such leg is `longest_leg_m`: from start less
/// that leg (not before path 0), one bin more for a linear split's second tap. 0 when the window
/// starts at 0 or there is no leg.
int bins_before_window(const TimeAxis& time, double longest_leg_m);

}  // namespace tprf
