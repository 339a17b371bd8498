#include "tprf/pipeline/info.h"

#include "staging.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/links.h"

#include <cstdio>
#include <fstream>

namespace tprf {

SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options) {
    SceneSummary s;
    auto t0 = std::chrono::steady_clock::now();
    PatchStats patch_stats;
    const PatchSet patches = build_patches(scene, {options.progress}, &patch_stats);
    s.patches = patches.size();
    s.dropped_degenerate = patch_stats.dropped_degenerate;
    s.max_edge = patch_stats.max_edge;
    s.seconds_patches = seconds_since(t0);

    t0 = std::chrono::steady_clock::now();
    const Visibility visibility(patches);
    LinkOptions link_options;
    link_options.threads = options.threads;
    link_options.progress = options.progress;
    LinkStats link_stats;
    const Links links = compute_links(patches, visibility, link_options, &link_stats);
    s.links = links.size();
    s.link_bytes = links.bytes();
    s.pairs_tested = link_stats.pairs_tested;
    s.seconds_links = seconds_since(t0);
    return s;
}

double peak_rss_mb() {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line))
        if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
    return 0.0;
}

std::string describe_time(const TimeAxis& time) {
    const double start = time.start_m(), width = time.bin_width_m();
    const double end = start + width * time.bins;
    const double ns = 1e9 / kSpeedOfLight;
    char buf[256];
    std::snprintf(buf, sizeof buf, "%d bins of %.6g m from %.6g m to %.6g m of optical path (%.6g ns to %.6g ns)",
                  time.bins, width, start, end, start * ns, end * ns);
    return buf;
}

}  // namespace tprf
