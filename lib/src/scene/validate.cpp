#include "tprf/scene/validate.h"

#include "tprf/core/error.h"
#include "tprf/core/time_kernel.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

namespace tprf {
namespace {

// A pulse or jitter may reach at most this many render windows away from t = 0: beyond, its kernel
// and the convolved profile would be sized by the pulse rather than by the render.
constexpr double kMaxReachInWindows = 64.0;

}  // namespace

void validate_sensor(const SensorSettings& s, const TimeAxis& time) {
    const std::string root = s.json_path.empty() ? "" : s.json_path + ".";
    const double limit = kMaxReachInWindows * time.bins * time.bin_width;
    auto check_reach = [&](double reach, const std::string& path) {
        if (reach <= limit) return;
        std::ostringstream os;
        os << "reaches " << reach << " from t = 0, more than " << kMaxReachInWindows
           << " times the render's window (" << time.bins * time.bin_width << "): render a longer window";
        fail_input(s.file, root + path, os.str());
    };
    switch (s.pulse.shape) {
        case PulseShape::Delta: break;
        case PulseShape::Gaussian: check_reach(kGaussianReach * s.pulse.fwhm / kFwhmPerSigma, "pulse.fwhm"); break;
        case PulseShape::Box: check_reach(0.5 * s.pulse.width, "pulse.width"); break;
        case PulseShape::Table:
            check_reach(std::max(std::abs(s.pulse.table_time.front()), std::abs(s.pulse.table_time.back())), "pulse.file");
            break;
    }
    if (s.exposure.type == ExposureType::Spad)
        check_reach(kGaussianReach * s.exposure.jitter_fwhm / kFwhmPerSigma, "exposure.jitter_fwhm");
    if (s.exposure.type != ExposureType::Gates && s.exposure.type != ExposureType::Windows) return;
    const TimeKernel k = pulse_kernel(s.pulse, time.bin_width);
    const double reach_lo = time.start + k.first * k.step;
    const double reach_hi = time.start + time.bins * time.bin_width + (k.first + double(k.mass.size())) * k.step;
    for (const auto& [start, width] : s.exposure.windows)
        if (start < reach_hi && start + width > reach_lo) return;
    const std::string path = root + "exposure";
    std::ostringstream os;
    os << "every " << (s.exposure.type == ExposureType::Gates ? "gate" : "window")
       << " lies outside the render's time window [" << time.start << ", "
       << time.start + time.bins * time.bin_width << ") and the pulse's reach: it would measure nothing";
    fail_input(s.file, path, os.str());
}

}  // namespace tprf
