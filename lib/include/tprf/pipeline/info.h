#pragma once
/// `tprf info`: a scene's size without rendering it, and what every pipeline entry point shares.

#include "tprf/core/progress.h"
#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"

#include <cstdint>
#include <string>

namespace tprf {

/// Options shared by the pipeline entry points.
struct PipelineOptions {
    int threads = 0;        ///< 0: all cores
    ProgressFn progress;    ///< may be empty
    /// Draw figures (sensor_plot.png) with python/tprf_plots.py in a child process. Off: only their
    /// data is written (sensor_plot.json), for callers that must not fork or draw themselves.
    bool draw_plots = true;
};

/// What `tprf info` prints: the scene's size without rendering it.
struct SceneSummary {
    std::size_t patches = 0;
    int dropped_degenerate = 0;     ///< mesh faces dropped (zero area, repeated vertices)
    double max_edge = 0.0;          ///< patch size used, metres
    std::size_t links = 0;
    std::size_t link_bytes = 0;
    std::uint64_t pairs_tested = 0; ///< unordered pairs facing each other
    double seconds_patches = 0.0;
    double seconds_links = 0.0;
};

/// Builds patches and links of a scene and measures them.
SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options = {});

/// Peak resident memory of this process so far, MB (VmHWM).
double peak_rss_mb();

/// The scene's time window in words, e.g. "1024 bins of 0.005 m from 0 m to 5.12 m (0 to 17.08 ns)".
std::string describe_time(const TimeAxis& time);

}  // namespace tprf
