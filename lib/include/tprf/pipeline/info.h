#pragma once
/// `tprf info`: a scene's size without rendering it, and its resource estimate.

#include "tprf/core/phase_seconds.h"
#include "tprf/core/time_axis.h"
#include "tprf/geometry/patches.h"
#include "tprf/pipeline/options.h"
#include "tprf/scene/scene.h"
#include "tprf/transport/solver.h"

#include <cstdint>
#include <string>
#include <vector>

namespace tprf {

/// What `tprf info` prints: the scene's size without rendering it.
struct SceneSummary {
    std::size_t patches = 0;
    double max_edge = 0.0;          ///< patch size used, metres
    std::size_t links = 0;
    std::size_t link_bytes = 0;
    std::uint64_t pairs_tested = 0; ///< unordered pairs facing each other (flat)
    std::uint64_t mirror_links = 0; ///< of `links`, those through mirrors and glass (both directions)
    std::size_t glossy_patches = 0; ///< patches with directional cells (links.glossy_resolution > 0)
    std::size_t glossy_rows = 0;    ///< their rows in the march (2 x 4 R^2 each)
    int glossy_rings = 0;           ///< R of their cells (links.glossy_resolution, "auto" resolved)
    std::size_t clusters = 0;       ///< clusters of the tree (hierarchical)
    std::uint64_t cluster_links = 0;///< links with a cluster at either end, pieces counted once (hierarchical)
    std::uint64_t patch_links = 0;  ///< patch-to-patch links (hierarchical)
    std::uint64_t candidates = 0;   ///< node pairs the oracle judged (hierarchical)
    double seconds_patches = 0.0;
    double seconds_links = 0.0;
    std::vector<std::string> warnings;  ///< unit_warnings
};

/// What in the scene is probably written in another unit than it means, as warnings: an object over 100
/// times the rest of the scene's size (a mesh in millimetres among metres: named with the scale that
/// fixes it), a camera whose fov is under 1 degree (radians meant for degrees), a time bin wider than
/// half the scene's size (the diagonal of its objects' bounding box: all its light within a couple of
/// bins) or narrower than 1e-5 of it. From the scene and its meshes' reports (`meshes`: the patch
/// stage's or the estimate's), so that render and info say them before anything large is built.
std::vector<std::string> unit_warnings(const Scene& scene, const std::vector<MeshReport>& meshes);

/// Loads the scene's mesh files and nothing else: per mesh its size, bounds and repairs (`tprf info
/// --meshes`).
std::vector<MeshReport> describe_meshes(const Scene& scene);

/// One line about a mesh file: "objects[2] 'bunny.ply': 35,947 vertices, 69,451 faces (cut into
/// 69,451 triangles); box (x, y, z) to (x, y, z) m; nothing dropped".
std::string describe(const MeshReport& mesh);

/// Builds patches and links of a scene and measures them.
SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options = {});

/// An array the solve fills, as a camera render opens it: its name (the .npy file's stem) and shape.
struct CubeShape {
    std::string name;
    std::vector<std::size_t> shape;
};

/// What a render will cost, estimated from the scene alone before anything heavy runs: patches are
/// counted by build_patches' rules (mesh files are loaded to count their triangles), links are
/// modelled, nothing is built. Bytes are what each stage holds once it has run (the builders' scratch
/// is counted in their own stage's peak only); seconds are for the phases of render.json, from
/// throughputs measured on the project's 2-core machine (see info.cpp) and scaled by the thread count.
struct ResourceEstimate {
    std::size_t patches = 0;             ///< N (counted exactly)
    double max_edge = 0.0;               ///< the patch size, metres
    double diagonal = 0.0;               ///< of every object's bounding box, metres
    std::size_t nodes = 0;               ///< nodes the solver marches: N, or the 2N - 1 of a cluster tree
    std::size_t links = 0;               ///< estimated links (flat: facing pairs, both directions)
    std::size_t near_links = 0;          ///< hierarchical: facing patch pairs nearer than its shortest cluster link
    double near_gap_m = 0.0;             ///< hierarchical: that distance, metres
    std::size_t mirror_links = 0;        ///< of `links`, those through mirrors and glass
    int glossy_rings = 0;                ///< the rings of their cells (glossy_rings of links.glossy_resolution)
    std::size_t glossy_rows = 0;         ///< rows of the glossy patches' cells (links.glossy_resolution)
    double glossy_lobe_fmas = 0.0;       ///< the march's multiply-adds of their lobes per bin and channel
    double facing_fraction = 0.0;        ///< share of sampled patch pairs that face each other
    int channels = 3;                    ///< 1 for a grey scene
    int ring_bins = 0;                   ///< history per node and layer
    int layers = 1;                      ///< solver layers (bounce orders kept apart)
    /// The march as the solver would plan it (march_shape) from the estimated sizes: a camera render's
    /// one illumination, or a capture's batch of capture_batch.
    MarchShape march;
    std::vector<CubeShape> cubes;        ///< the cubes a camera render fills (and their shapes)
    double lit_pixels = 1.0;             ///< share of pixels that see an object (occlusion left out)
    std::size_t samples = 0;             ///< camera samples that meet the scene (lit pixels x spp)

    std::size_t base_bytes = 0;          ///< the process before any stage (code, libraries, threads)
    std::size_t mesh_bytes = 0;          ///< mesh files while they are loaded (patch stage only)
    std::size_t patch_bytes = 0;         ///< the patch set
    std::size_t visibility_bytes = 0;    ///< Embree's BVH and its copy of the geometry
    std::size_t link_bytes = 0;          ///< links (and cluster tree), kept to the end
    std::size_t link_build_bytes = 0;    ///< the link builder's scratch (pair lists), at its end
    std::size_t illumination_bytes = 0;  ///< pulses
    std::size_t gather_bytes = 0;        ///< sensing points, neighbours and taps of the camera
    std::size_t solver_bytes = 0;        ///< rings, block buffers, short-link lists, the films' blocks
    std::size_t cube_bytes = 0;          ///< memory-mapped outputs filled by the solve (all resident at the end)
    std::size_t write_bytes = 0;         ///< the steady state and images, and sensor outputs
    std::size_t peak_bytes = 0;          ///< the largest sum of what is held at once
    std::size_t link_stage_bytes = 0;    ///< the peak up to the end of the link stage (what `tprf info` builds)
    std::string peak_stage;              ///< where the peak is: "patches", "links", "gather", "solve" or "write"

    int capture_batch = 0;               ///< a capture that marches: illuminations per march (0: none)
    std::size_t capture_marches = 0;     ///< ... and the marches, ceil(laser points / capture_batch)

    PhaseSeconds seconds;                ///< load, patches, links, solve, gather, write, total
    std::vector<MeshReport> meshes;      ///< the mesh files, as loaded to count their triangles
};

/// Estimates the peak memory and the seconds of a render of `scene` (`patch_profiles`: with
/// patch_transient.npy). Cheap: milliseconds, plus loading the scene's mesh files.
ResourceEstimate estimate_resources(const Scene& scene, const PipelineOptions& options, bool patch_profiles = false);

/// The memory limit in bytes: options.max_memory_gb, or, when that is 0, 80% of the memory available
/// to the process: the least of MemAvailable, its cgroups' room under their limits and ulimit -v's.
std::size_t memory_limit_bytes(const PipelineOptions& options);

/// Throws tprf::Error (exit 2) when the estimated peak of a render of `scene` exceeds the limit,
/// naming the estimate, the limit and the scene keys that shrink it. Allocates nothing heavy.
void check_memory(const Scene& scene, const PipelineOptions& options, bool patch_profiles = false);

/// Peak resident memory of this process so far, MB (VmHWM).
double peak_rss_mb();

/// The scene's time window in words, e.g. "1024 bins of 0.005 m from 0 m to 5.12 m (0 to 17.08 ns)".
std::string describe_time(const TimeAxis& time);

}  // namespace tprf
