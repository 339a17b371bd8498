#pragma once
/// Seconds spent in each phase of a render: what render.json's `seconds` records and what `tprf info`
/// estimates.

namespace tprf {

/// Seconds spent in each phase of a render (render.json's `seconds`).
struct PhaseSeconds {
    double load = 0, patches = 0, links = 0, solve = 0, gather = 0, write = 0, total = 0;
    double illumination = 0;  ///< the part of `gather` that lights the patches (illuminate())
};

}  // namespace tprf
