#include "tprf/core/time_axis.h"

#include <algorithm>
#include <cmath>

#include "tprf/core/types.h"

namespace tprf {

double TimeAxis::to_metres(double value_in_unit) const {
    // Picoseconds are of light travel, so a time converts to the optical path length it covers.
    return unit == TimeUnit::Picoseconds ? value_in_unit * 1e-12 * kSpeedOfLight : value_in_unit;
}

double TimeAxis::bin_width_m() const { return to_metres(bin_width); }

double TimeAxis::start_m() const { return to_metres(start); }

int bins_before_window(const TimeAxis& time, double longest_leg_m) {
    const double start = time.start_m();
    if (!(start > 0.0) || !(longest_leg_m > 0.0)) return 0;
    return int(std::ceil(std::min(longest_leg_m, start) / time.bin_width_m())) + 1;
}

}  // namespace tprf
