#pragma once
/// Options shared by the pipeline entry points (render, info, sensor, the Python module).

#include "tprf/core/progress.h"
#include "tprf/scene/parse_mitsuba.h"

#include <functional>
#include <string>

namespace tprf {

/// Options shared by the pipeline entry points.
struct PipelineOptions {
    int threads = 0;        ///< 0: all cores
    ProgressFn progress;    ///< may be empty
    /// Lines the user should read before the work goes on, each once (the patch size a scene without
    /// one gets: PatchOptions::notice); may be empty.
    std::function<void(const std::string&)> notice;
    /// Draw figures (sensor_plot.png) with python/tprf_plots.py in a child process. Off: only their
    /// data is written (sensor_plot.json), for callers that must not fork or draw themselves.
    bool draw_plots = true;
    /// The y scale of those figures: "auto" (logarithmic where the values span more than 1e3), "log"
    /// or "linear" (`--plot-scale`).
    std::string plot_scale = "auto";
    /// A render whose estimated peak memory (estimate_resources) exceeds this many GB (1e9 bytes) is
    /// refused before anything heavy is allocated (check_memory); 0: 80% of the memory available
    /// (MemAvailable in /proc/meminfo).
    double max_memory_gb = 0.0;
    /// `--max-edge L`: replaces the scene's patches.max_edge (metres) when > 0.
    double max_edge = 0.0;
    /// `-D name=value`: parameters of a Mitsuba XML scene (scene/parse_mitsuba.h); must be empty for JSON.
    XmlDefines defines;
};

}  // namespace tprf
