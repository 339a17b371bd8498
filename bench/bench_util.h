#pragma once
/// What the link and solver benchmarks share: the Cornell box at a chosen patch count, and the
/// process's resident memory.

#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/scene/parse_json.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/light_sources.h"
#include "tprf/transport/link_set.h"

#include <malloc.h>
#include <sys/resource.h>

#include <cstddef>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>

namespace tprf::bench {

/// The patch counts the benchmarks are run at, and the patches.max_edge (metres) that gives about
/// that many patches of meshes/cornell-box.json (found by trying; the cases report the exact count).
inline double cornell_max_edge(int target_patches) {
    switch (target_patches) {
        // The blocks' faces are quads, kept whole since 2026-11-24 (before: 0.11, 0.054 and 0.0265 gave
        // 1088, 3941 and 16160 patches with the blocks in triangles).
        case 1000: return 0.087;    // 937 patches
        case 4000: return 0.0415;   // 4014
        case 16000: return 0.0202;  // 15750
        default: throw std::invalid_argument("no max_edge for " + std::to_string(target_patches) + " patches");
    }
}

/// meshes/cornell-box.json with patches.max_edge set for about `target_patches` patches.
inline Scene cornell_box(int target_patches) {
    Scene scene = load_scene(std::string(TPRF_SOURCE_DIR) + "/meshes/cornell-box.json");
    scene.max_edge = cornell_max_edge(target_patches);
    return scene;
}

/// A field of /proc/self/status in bytes ("VmRSS", "VmHWM"); 0 when it cannot be read.
/// The Cornell box built as a render builds it before the solve: patches, visibility, flat links, its
/// light sources and their pulses.
struct BuiltCornell {
    Scene scene;
    PatchSet patches;
    std::unique_ptr<Visibility> visibility;
    LinkSet links;
    LightSources sources;
    Illumination emission;
};

/// cornell_box(target_patches) on `bins` bins (0: the scene's), built on `threads` threads; the pulses
/// merged on the scene's bins when `merge_bins`, as a render merges them.
inline std::unique_ptr<BuiltCornell> built_cornell(int target_patches, int bins, int threads, bool merge_bins) {
    auto out = std::make_unique<BuiltCornell>();
    out->scene = cornell_box(target_patches);
    if (bins > 0) out->scene.time.bins = bins;
    out->patches = build_patches(out->scene);
    out->visibility = std::make_unique<Visibility>(out->patches);
    LinkOptions link_options;
    link_options.threads = threads;
    out->links = flat_link_set(out->patches, *out->visibility, link_options);
    IlluminationOptions light_options;
    light_options.threads = threads;
    if (merge_bins) light_options.merge_bins = &out->scene.time;
    out->sources = light_sources(out->scene, out->patches, *out->visibility);
    out->emission = illuminate(out->sources, out->patches, *out->visibility, light_options);
    return out;
}

inline double proc_status_bytes(const std::string& field) {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line)) {
        if (line.compare(0, field.size() + 1, field + ":") != 0) continue;
        return std::stod(line.substr(field.size() + 1)) * 1024.0;  // the kernel writes kB
    }
    return 0.0;
}

/// CPU time (user + system) used so far by every thread of the process, seconds. Set against
/// threads x wall time it tells whether a case had its cores to itself: another job on the machine
/// lowers the ratio (so do the stage's own serial parts, which are the same from run to run).
inline double process_cpu_seconds() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    auto seconds = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
    return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

/// Resets the process's peak RSS (VmHWM) to its current RSS (Linux >= 4.0), so that the next
/// VmHWM reading is the peak of what follows. False when the kernel refuses.
inline bool reset_peak_rss() {
    std::ofstream out("/proc/self/clear_refs");
    out << "5";
    out.flush();
    return bool(out);
}

/// Starts measuring a peak: returns the freed heap to the system (malloc would otherwise hand what an
/// earlier case freed to the next one unseen by RSS) and resets the peak RSS. Returns the RSS then,
/// bytes: VmHWM less it, read after the work, is the work's peak.
inline double start_peak() {
    malloc_trim(0);
    reset_peak_rss();
    return proc_status_bytes("VmRSS");
}

}  // namespace tprf::bench
