#pragma once
/// Progress reporting: long stages call a callback that the app turns into a progress bar.

#include <functional>
#include <string_view>

namespace tprf {

/// Called with the phase name and the fraction done in [0, 1]; may be empty. Called from one thread
/// at a time, at most a few hundred times per phase.
using ProgressFn = std::function<void(std::string_view phase, double fraction)>;

}  // namespace tprf
