#include "tprf/pipeline/info.h"

#include "cubes.h"
#include "staging.h"
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/imaging/camera.h"
#include "tprf/imaging/film.h"
#include "tprf/pipeline/capture.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/transport/link_set.h"
#include "tprf/transport/solver.h"

#include <algorithm>
#include <bit>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <string>

#include <sys/resource.h>
#include <limits>
#include <sstream>
#include <utility>

namespace tprf {

std::vector<MeshReport> describe_meshes(const Scene& scene) { return count_patches(scene).meshes; }

std::string describe(const MeshReport& m) {
    std::string cells = counted(m.triangles, "triangle", "triangles");
    if (m.quads > 0) cells += (m.triangles > 0 ? " and " : "") + counted(m.quads, "quad", "quads");
    if (m.triangles == 0 && m.quads > 0) cells = counted(m.quads, "quad", "quads");
    char box[160];
    const Vec3 lo = m.bounds.min(), hi = m.bounds.max();
    std::snprintf(box, sizeof box, "box (%.6g, %.6g, %.6g) to (%.6g, %.6g, %.6g) m", lo.x(), lo.y(), lo.z(), hi.x(),
                  hi.y(), hi.z());
    const std::string repairs = describe(m.repairs);
    return "objects[" + std::to_string(m.object) + "] '" + m.file + "': " +
           counted(m.vertices, "vertex", "vertices") + ", " + counted(m.faces, "face", "faces") + " (cut into " +
           cells + "); " + box + "; " + (repairs.empty() ? "nothing dropped" : "dropped " + repairs);
}

namespace {

// An object this many times larger than the rest of the scene (bounding-box diagonals) is probably in
// another unit.
constexpr double kOutsizeRatio = 100.0;

// Per object, its bounding box: rectangles from the scene, meshes from their reports.
std::vector<Eigen::AlignedBox3d> object_boxes(const Scene& scene, const std::vector<MeshReport>& meshes) {
    std::vector<Eigen::AlignedBox3d> boxes(scene.objects.size());
    for (std::size_t k = 0; k < scene.objects.size(); ++k)
        if (const auto* r = std::get_if<RectangleShape>(&scene.objects[k].shape))
            for (const Vec3& p : {r->origin, Vec3(r->origin + r->u), Vec3(r->origin + r->v), Vec3(r->origin + r->u + r->v)})
                boxes[k].extend(p);
    for (const MeshReport& m : meshes)
        if (m.object < boxes.size()) boxes[m.object] = m.bounds;
    return boxes;
}

// The object whose bounding box is over kOutsizeRatio times the rest of the scene's (diagonals), as a
// sentence that names it, both sizes and the unit it is probably in; empty when there is none.
std::string outsize_object(const Scene& scene, const std::vector<Eigen::AlignedBox3d>& boxes) {
    if (boxes.size() < 2) return {};
    std::vector<double> diagonal(boxes.size(), 0.0);
    for (std::size_t k = 0; k < boxes.size(); ++k)
        if (!boxes[k].isEmpty()) diagonal[k] = boxes[k].diagonal().norm();
    const std::size_t big = std::size_t(std::max_element(diagonal.begin(), diagonal.end()) - diagonal.begin());
    Eigen::AlignedBox3d rest;
    for (std::size_t k = 0; k < boxes.size(); ++k)
        if (k != big && !boxes[k].isEmpty()) rest.extend(boxes[k]);
    if (rest.isEmpty()) return {};
    const double size = diagonal[big], others = rest.diagonal().norm();
    if (!(others > 0.0) || size <= kOutsizeRatio * others) return {};
    const double ratio = size / others;
    const double factor = std::pow(10.0, std::round(std::log10(ratio) / 3.0) * 3.0);  // 1000: mm for m, ...
    std::string name = scene.object_path(big);
    if (const auto* m = std::get_if<MeshShape>(&scene.objects[big].shape)) name += " ('" + m->file.filename().string() + "')";
    char text[400];
    std::snprintf(text, sizeof text,
                  "%s is %.4g m across, %.3g times the rest of the scene (%.4g m): is it in %s? A scale of %g in its "
                  "transform makes it %.4g m",
                  name.c_str(), size, ratio, others, factor >= 1e3 && factor < 1e6 ? "millimetres" : "another unit",
                  1.0 / factor, size / factor);
    return text;
}

}  // namespace

std::vector<std::string> unit_warnings(const Scene& scene, const std::vector<MeshReport>& meshes) {
    std::vector<std::string> out;
    char text[400];
    if (scene.camera && scene.camera->fov_deg < 1.0) {
        std::snprintf(text, sizeof text,
                      "camera.fov is %.6g degrees: fov is in degrees (if %.6g was meant in radians, it is %.4g degrees)",
                      scene.camera->fov_deg, scene.camera->fov_deg, scene.camera->fov_deg * 180.0 / M_PI);
        out.push_back(text);
    }
    const std::vector<Eigen::AlignedBox3d> boxes = object_boxes(scene, meshes);
    if (std::string outsize = outsize_object(scene, boxes); !outsize.empty()) out.push_back(std::move(outsize));
    Eigen::AlignedBox3d all;
    for (const Eigen::AlignedBox3d& b : boxes)
        if (!b.isEmpty()) all.extend(b);
    if (all.isEmpty()) return out;
    const double size = all.diagonal().norm(), bin = scene.time.bin_width_m();
    if (size > 0.0 && (bin > 0.5 * size || bin < 1e-5 * size)) {
        char width[120];
        if (scene.time.unit == TimeUnit::Metres)
            std::snprintf(width, sizeof width, "%.6g m", scene.time.bin_width);
        else
            std::snprintf(width, sizeof width, "%.6g ps (%.3g m of light travel)", scene.time.bin_width, bin);
        std::snprintf(text, sizeof text,
                      "time.bin_width %s against a scene %.3g m across (its bounding box's diagonal): %s; is it in "
                      "time.unit?",
                      width, size, bin > 0.5 * size ? "all its light falls within a few bins" : "light takes over 10^5 bins to cross it");
        out.push_back(text);
    }
    return out;
}

SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options) {
    SceneSummary s;
    auto t0 = std::chrono::steady_clock::now();
    PatchStats patch_stats;
    const PatchSet patches = build_patches(scene, {options.progress, options.notice}, &patch_stats);
    s.patches = patches.size();
    s.max_edge = patch_stats.max_edge;
    s.warnings = unit_warnings(scene, patch_stats.meshes);
    s.seconds_patches = seconds_since(t0);

    t0 = std::chrono::steady_clock::now();
    const std::unique_ptr<Visibility> owned = scene_visibility(scene, patches);
    const Visibility& visibility = *owned;
    // What render checks before its links: every capture point lies on a surface its device sees.
    if (scene.capture) locate_capture_points(scene, patches, visibility);
    LinkOptions link_options;
    link_options.threads = options.threads;
    link_options.progress = options.progress;
    LinkStats link_stats;
    HierarchyStats stats;
    const double bin_m = march_time(scene).bin_width_m();
    LinkSet links = make_link_set(patches, visibility, scene.links, bin_m, link_options, {&stats, &link_stats});
    if (scene.links.method != LinkMethod::Flat) {
        s.clusters = links.tree.clusters();
        s.cluster_links = stats.cluster_links;
        s.patch_links = stats.leaf_links;
        s.candidates = stats.candidates;
    }
    s.mirror_links = add_mirror_links(links, patches, visibility, link_options, bin_m);
    s.glossy_patches = links.glossy.glossy.size();
    s.glossy_rows = links.glossy.rows();
    s.glossy_rings = links.glossy.rings;
    s.links = links.links.size();
    s.link_bytes = links.bytes();
    s.pairs_tested = link_stats.pairs_tested;
    s.seconds_links = seconds_since(t0);
    return s;
}

// ---- Resource estimate (`tprf info`, `--max-memory`) ----
//
// Sizes come from the stages' own rules wherever a stage has one: the patch set's and the link set's
// arrays (PatchSet::bytes_for, ClusterTree::bytes_for, Links::kLinkBytes), the link builders' records
// (link_build_sizes), the march's shape and working memory (march_shape, march_working_bytes), the
// films' buffers (film_buffer_bytes) and the cubes (render_cubes). What remains is measured: each
// constant below names, after `//`, the benchmark of bench/ that measures it and the counter that
// benchmark reports in the constant's unit. `python3 bench/estimate_constants.py` runs them all, prints
// each measured value beside the constant, and checks the estimate against renders of the sample scenes
// (within a factor of 2 in peak memory and seconds). Seconds are for 2 threads; the estimate aims at a
// factor of 2.

namespace {

constexpr double kMB = 1e6;
constexpr double kGB = 1e9;

// Memory, bytes.
// The process before any stage: code, libraries, threads.
constexpr double kBaseBytes = 16 * kMB;  // tprf_tiny_render: peak_bytes
// A mesh file while it is loaded and triangulated, per face.
constexpr double kMeshBytesPerFace = 150;  // BM_LoadBinaryStl: bytes_per_face
// Embree's quads and BVH (RTC_BUILD_QUALITY_HIGH) at its peak, per patch.
constexpr double kEmbreeBytesPerPatch = 180;  // BM_Visibility: bytes_per_patch
// A pulse, with the per-patch lists it is built in.
constexpr double kPulseBytes = 64;  // BM_Illuminate/area_light:0: bytes_per_pulse
// The camera's gather per sample: sensing point, neighbour lists, taps before and after assembly.
constexpr double kGatherBytesPerSample = 450;  // BM_PrepareCamera/96/0: bytes_per_sample
// The camera's gather per patch: the neighbour index over the centroids.
constexpr double kGatherBytesPerPatch = 100;  // BM_NeighbourIndex: bytes_per_patch

// Counts.
// Patches sampled to estimate which pairs face each other (a parameter of the estimate).
constexpr std::size_t kPairSamples = 1024;
// Pulses per patch and point source: a patch's samples' pulses merged per bin
// (IlluminationOptions::merge_bins). An area source's lit patch keeps a pulse per bin its paths span.
constexpr double kPointSourcePulses = 2;  // BM_Illuminate/area_light:0: pulses_per_patch_source
// Taps of a camera sample (its neighbouring patches), and of a pixel once its samples' are merged.
constexpr double kTapsPerSample = 8;  // BM_PrepareCamera/96/1: taps_per_pixel
constexpr double kTapsPerPixel = 32;  // BM_PrepareCamera/96/0: taps_per_pixel
// Hierarchical links: c N^e sqrt(0.003 / tolerance). The exponent is a fit over 4k to 1M patches
// (bench/scaling_sweep.py: the count grows slower than N, as far apart the same cluster links serve
// finer patches); the scale is measured at one size.
constexpr double kHierarchicalLinksExponent = 0.45;
constexpr double kHierarchicalLinksScale = 1.03e5;  // BM_HierarchicalLinkStage/near_field:0: links_scale
// The share of a full ring (the scene's diagonal) that an average node of a hierarchical set keeps (its
// longest outgoing link): (N / R)^(-1/3), at most 1, R patches being where it reaches 1. The exponent is
// a fit over 4k to 1M patches (bench/scaling_sweep.py).
constexpr double kRingSharePatches = 16000;  // BM_HierarchicalLinkStage/near_field:0: ring_share_patches
double hierarchical_ring_share(double n) { return std::min(1.0, std::cbrt(kRingSharePatches / std::max(n, 1.0))); }

// Seconds on 2 threads.
constexpr double kPatchSeconds = 4e-7;  // BM_BuildPatches: seconds_per_patch
// Reading a mesh file and cutting it, per face (ASCII OFF: the slowest reader).
constexpr double kMeshSecondsPerFace = 4.5e-7;  // BM_LoadAsciiOff: seconds_per_face
constexpr double kEmbreeSeconds = 1.2e-6;  // BM_Visibility: seconds_per_patch
// Flat links: unordered pairs considered a second.
constexpr double kPairsPerSecond = 4.2e6;  // BM_LinkStage/4000: pairs_per_s
// Hierarchical link stage: s N^e sqrt(0.003 / tolerance); the exponent a fit as above.
constexpr double kHierarchicalLinkSecondsExponent = 0.74;
constexpr double kHierarchicalLinkSecondsScale = 9.5e-3;  // BM_HierarchicalLinkStage/near_field:0: seconds_scale
// Hierarchical links in the near field (single patches, all of them refined to), per link.
constexpr double kNearLinkSeconds = 5.5e-7;  // BM_HierarchicalLinkStage/near_field:1: seconds_per_link
// Per pulse of a point source, shadow rays included.
constexpr double kPulseSeconds = 2e-7;  // BM_Illuminate/area_light:0: seconds_per_pulse
// Per patch and area source that face each other.
constexpr double kAreaSourceSeconds = 4e-5;  // BM_Illuminate/area_light:1: seconds_per_patch_source
constexpr double kSampleSeconds = 2e-6;  // BM_PrepareCamera/96/0: seconds_per_sample
// The film: one tap applied to one bin.
constexpr double kTapBinSeconds = 1.0 / 1.5e9;  // BM_FilmBlock/96/0: seconds_per_tap_bin
// camera.shift_second_bounce: the second bounce from the links, its shift and its own taps, per link.
constexpr double kSecondBounceSecondsPerLink = 5e-8;  // BM_SecondBounceLight: seconds_per_link
// The solve's link-bin updates, flat sets, with the kernels every x86-64-v3 machine runs (AVX2).
constexpr double kGreyLinkBinSeconds = 1.0 / 13e9;  // BM_TransientSolveGrey/wide:0: seconds_per_link_bin
constexpr double kColourLinkBinSeconds = 1.0 / 7.5e9;  // BM_TransientSolve/wide:0: seconds_per_link_bin
// A link shorter than a block, applied bin by bin (3 channels).
constexpr double kShortLinkBinSeconds = 1.0 / 1e9;  // BM_MeshSceneSolve/wide:0: seconds_per_short_link_bin
// The hierarchical solve per patch and bin.
constexpr double kHierarchicalPatchBinSeconds = 4e-7;  // BM_MeshSceneSolve/wide:0: seconds_per_patch_bin
// A march of B lanes costs 1 + (B - 1) x this many single marches.
constexpr double kBatchLaneCost = 1.0 / 15.0;  // BM_TransientSolveBatch/K:16/grey:1: extra_cost_per_lane
// The write phase's own work besides the cubes: the images, render.json, moving the files in place.
constexpr double kWriteSeconds = 0.01;  // tprf_tiny_render: write_seconds
// Writing back the memory-mapped cubes.
constexpr double kCubeBytesPerSecond = 1.0e9;  // BM_WriteCube: bytes_per_s
// links.spread_pieces, per link spread.
constexpr double kSpreadSecondsPerLink = 2e-7;  // BM_SpreadPatchLinks: seconds_per_link
// The steady state (BiCGSTAB on the links, 3 channels), per link.
constexpr double kSteadySecondsPerLink = 3e-8;  // BM_SteadyState: seconds_per_link
// Links through mirrors: ordered pairs of patches judged a second.
constexpr double kMirrorPairsPerSecond = 1.0e6;  // BM_MirrorLinks: pairs_per_s
// Glossy cells (links.glossy_resolution), measured on the glossy Cornell box of bench/RESULTS.md at R = 4:
// one incoming direction of a lobe's cell reflectance (16 per cell), one multiply-add of a lobe in the
// march per channel, and a glossy row's bin in the bin-by-bin pass and the rings besides.
constexpr double kCellDirectionSeconds = 1.3e-3;
constexpr double kLobeSeconds = 4e-10;
constexpr double kGlossyRowBinSeconds = 1.9e-8;

// A count or a byte size from the model's doubles, held under 1e18 so that sums of them cannot overflow.
std::size_t to_size(double v) { return v >= 1e18 ? std::size_t(1e18) : v > 0.0 ? std::size_t(v) : 0; }

// Whether the camera reads the second bounce at its samples' times (render.cpp, make_second_bounce_light):
// no mirror or glass.
bool shifts_second_bounce(const Scene& scene) {
    return scene.camera && scene.camera->shift_second_bounce &&
           std::none_of(scene.objects.begin(), scene.objects.end(), [](const Object& o) { return o.material.specular(); });
}

// Whether some mirror or glass reflects the channels unalike: its links are tinted (Links::tint).
bool tinted_mirrors(const Scene& scene) {
    return std::any_of(scene.objects.begin(), scene.objects.end(),
                       [](const Object& o) { return !is_grey(o.material.reflectance); });
}

// A patch's circumradius from its area: about 0.75 sqrt(area) for the squares and near-equilateral
// triangles patches are cut into (0.71 for a square, 0.88 for an equilateral triangle).
double patch_size(double area) { return 0.75 * std::sqrt(area); }

// What the sampled patch pairs say: the share that face each other, the same among pairs with an
// emitter, and among the facing ones the share shorter than a block, within one bin, between one and two
// blocks (the long pass's shortest window), and in the near field of a hierarchical set (gaps under
// near_gap_m, which is kept with them).
struct PairShares {
    double facing = 0.0, emitter_facing = 0.0, shorter_than_block = 0.0, same_bin = 0.0, first_window = 0.0;
    double near = 0.0;
    double near_gap_m = 0.0;
};

PairShares pair_shares(const Scene& scene, const PatchCensus& census, double block_m, double bin_m, double gap_m) {
    PairShares s;
    s.near_gap_m = gap_m;
    std::uint64_t pairs = 0, facing = 0, emitter_pairs = 0, emitter_facing = 0, shorter = 0, same = 0, window = 0;
    std::uint64_t near = 0;
    const auto& v = census.samples;
    for (std::size_t i = 0; i < v.size(); ++i) {
        const bool emits_i = (scene.objects[v[i].object].emission > 0.0).any();
        for (std::size_t j = i + 1; j < v.size(); ++j) {
            const Vec3 d = v[j].point - v[i].point;
            const double r = d.norm(), tol = 1e-9 * r;
            const bool faces = d.dot(v[i].normal) > tol && -d.dot(v[j].normal) > tol;
            const bool emits = emits_i || (scene.objects[v[j].object].emission > 0.0).any();
            ++pairs;
            emitter_pairs += emits;
            if (!faces) continue;
            ++facing;
            emitter_facing += emits;
            shorter += r < block_m;
            same += r < bin_m;
            window += r >= block_m && r < 2.0 * block_m;
            near += r < gap_m + patch_size(v[i].area) + patch_size(v[j].area);
        }
    }
    if (pairs > 0) s.facing = double(facing) / double(pairs);
    s.emitter_facing = emitter_pairs > 0 ? double(emitter_facing) / double(emitter_pairs) : s.facing;
    if (facing > 0) {
        s.shorter_than_block = double(shorter) / double(facing);
        s.same_bin = double(same) / double(facing);
        s.first_window = double(window) / double(facing);
        s.near = double(near) / double(facing);
    }
    return s;
}

// Twice the size of the median sampled patch (census.samples, not empty): the extent of a typical patch.
double median_extent(const PatchCensus& census) {
    std::vector<double> areas;
    for (const PatchSample& s : census.samples) areas.push_back(s.area);
    std::nth_element(areas.begin(), areas.begin() + std::ptrdiff_t(areas.size() / 2), areas.end());
    return 2.0 * patch_size(areas[areas.size() / 2]);
}

// The shortest cluster link of a hierarchical set, bins (LinkSet::block_bins; default_min_lag_bins: four
// median patch sizes in bins, 1 to 32); 0 for flat links. The sampled patches' median size stands for
// the set's.
int cluster_block_bins(const PatchCensus& census, double bin_m) {
    if (census.samples.empty() || !(bin_m > 0.0)) return 0;
    return default_min_lag_bins(median_extent(census), bin_m);
}

// The gap under which a hierarchical set links single patches only: clusters nearer than the shortest
// cluster link are refined, so every facing pair of patches whose gap is shorter is a link of its own.
double near_gap_m(const PatchCensus& census, double bin_m) { return cluster_block_bins(census, bin_m) * bin_m; }

// The options of the march a render runs: its camera's (per-bounce cubes as the solver's terms), or
// without a camera its capture's.
SolverOptions march_options(const Scene& scene, int threads) {
    SolverOptions o;
    o.delay = scene.solver.delay;
    o.threads = threads;
    if (scene.camera) {
        o.max_bounces = scene.solver.max_bounces;
        o.bounce_terms = bounce_cubes(scene.solver);
    } else if (scene.capture) {
        o.max_bounces = capture_march_bounces(*scene.capture);
    }
    return o;
}

// Whether a ray from `o` along `d` meets the object from its front (a rectangle exactly; a mesh: its
// bounding box, either side).
bool ray_meets(const Object& object, const Eigen::AlignedBox3d& box, const Vec3& o, const Vec3& d) {
    if (const auto* r = std::get_if<RectangleShape>(&object.shape)) {
        const Vec3 n = r->u.cross(r->v);
        const double along = d.dot(n);
        if (along == 0.0 || (along > 0.0 && !object.two_sided)) return false;
        const double t = (r->origin - o).dot(n) / along;
        if (!(t > 0.0)) return false;
        const Vec3 w = o + t * d - r->origin;
        const double uu = r->u.dot(r->u), uv = r->u.dot(r->v), vv = r->v.dot(r->v);
        const double wu = w.dot(r->u), wv = w.dot(r->v), det = uu * vv - uv * uv;
        const double a = (wu * vv - wv * uv) / det, b = (wv * uu - wu * uv) / det;
        return a >= 0.0 && a <= 1.0 && b >= 0.0 && b <= 1.0;
    }
    double near = 0.0, far = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) {
        double t0 = (box.min()[k] - o[k]) / d[k], t1 = (box.max()[k] - o[k]) / d[k];
        if (t0 > t1) std::swap(t0, t1);
        near = std::max(near, t0);
        far = std::min(far, t1);
    }
    return near <= far;
}

// The share of pixels that see some object (occlusion left out), from the centre rays of at most
// 64 x 64 pixels: a pixel that sees nothing gets no taps, and its part of the cube is never touched.
double lit_share(const Scene& scene, const PatchCensus& census) {
    const Camera& camera = *scene.camera;
    const int gx = std::min(camera.width, 64), gy = std::min(camera.height, 64);
    int lit = 0;
    for (int y = 0; y < gy; ++y)
        for (int x = 0; x < gx; ++x) {
            const Vec3 d = camera_ray(camera, (x + 0.5) * camera.width / gx, (y + 0.5) * camera.height / gy);
            if (d.isZero()) continue;  // a distortion's fold: the pixel sees nothing
            for (std::size_t k = 0; k < scene.objects.size(); ++k)
                if (ray_meets(scene.objects[k], census.bounds[k], camera.position, d)) {
                    ++lit;
                    break;
                }
        }
    return double(lit) / double(gx * gy);
}

// The pieces a patch link becomes under links.spread_pieces (0 when off): one per two bins of the
// median sampled patch's extent (median_extent), at most spread_pieces. The Cornell box at
// 2,520 patches and 5 mm bins: 4 estimated, 2.9 made (bench/RESULTS.md).
double spread_pieces(const Scene& scene, const PatchCensus& census) {
    const double bin_m = scene.time.bin_width_m();
    if (scene.links.spread_pieces <= 0 || census.samples.empty() || !(bin_m > 0.0)) return 0.0;
    return std::clamp(std::floor(median_extent(census) / (2.0 * bin_m)), 1.0, double(scene.links.spread_pieces));
}

// Links and the cluster tree, their bytes and the builder's seconds, for the scene's method.
void estimate_links(const Scene& scene, const PatchCensus& census, const PairShares& shares, ResourceEstimate& e) {
    const double n = double(census.patches), others = std::max(n - 1.0, 0.0);
    const double flat = shares.facing * n * others;  // facing pairs, both directions (visibility not removed)
    double links = flat, rows = n, tree = 0.0, seconds = 0.5 * n * others / kPairsPerSecond;
    const LinkBuildSizes record = link_build_sizes();
    double build_bytes = 0.5 * double(record.flat_pair);
    e.nodes = census.patches;
    if (scene.links.method == LinkMethod::Hierarchical) {
        const double tolerance_factor = std::sqrt(0.003 / scene.links.tolerance);
        // The fit holds where the near field is a small part; where coarse bins make it large (every pair
        // of patches within a bin of each other is a link), its facing pairs are the count.
        const double near = shares.near * flat;
        e.near_links = to_size(near);
        e.near_gap_m = shares.near_gap_m;
        links = std::min(flat, std::max(near, kHierarchicalLinksScale * std::pow(n, kHierarchicalLinksExponent) *
                                                  tolerance_factor));
        build_bytes = 0.5 * double(record.hierarchical_pair);
        e.nodes = census.patches > 0 ? 2 * census.patches - 1 : 0;
        rows = double(e.nodes);
        tree = double(ClusterTree::bytes_for(census.patches, e.nodes));
        // Where the tolerance refines every pair to patches the builder does the flat builder's work, and
        // no more: the fit is for the scenes where clusters take most pairs.
        seconds = std::min(seconds, std::max(near * kNearLinkSeconds,
                                             kHierarchicalLinkSecondsScale *
                                                 std::pow(n, kHierarchicalLinkSecondsExponent) * tolerance_factor));
    }
    double build = build_bytes * links + (tree > 0.0 ? double(record.oracle_node) * rows : 0.0);
    // links.spread_pieces (transport/link_spread.cpp): each patch link becomes up to that many pieces.
    const double pieces = spread_pieces(scene, census);
    if (pieces > 0.0) {
        const double patch_links = scene.links.method == LinkMethod::Hierarchical ? std::min(links, shares.near * flat) : links;
        links += patch_links * (pieces - 1.0);
        build = std::max(build, double(record.spread_link + Links::kLinkBytes) * patch_links * pieces);
        seconds += patch_links * kSpreadSecondsPerLink;
    }
    e.links = to_size(links);
    e.link_bytes = to_size(double(Links::kLinkBytes) * links + double(Links::kRowBytes) * (rows + n) + tree);
    e.link_build_bytes = to_size(build);
    e.seconds.links = kEmbreeSeconds * n + seconds;
}

// Links through mirrors and glass (transport/mirror_links.cpp): every pair of patches in front of a
// specular rectangle's reflecting side, both facing it, is a link (one reflection; chains of more are
// left out). The share of the patches there comes from the census' samples.

void estimate_mirror_links(const Scene& scene, const PatchCensus& census, ResourceEstimate& e) {
    if (census.samples.empty()) return;
    double pairs = 0.0;
    for (std::size_t o = 0; o < scene.objects.size(); ++o) {
        const Object& object = scene.objects[o];
        const auto* r = std::get_if<RectangleShape>(&object.shape);
        if (!r || !object.material.specular() || !(object.material.reflectance.maxCoeff() > 0.0)) continue;
        const Vec3 n = r->u.cross(r->v).normalized(), centre = r->origin + 0.5 * (r->u + r->v);
        for (const int side : {1, -1}) {
            if (side < 0 && object.material.type != MaterialType::Glass) continue;
            std::size_t in_front = 0;
            for (const PatchSample& s : census.samples)
                in_front += s.object != o && side * n.dot(s.point - centre) > 0.0 && s.normal.dot(centre - s.point) > 0.0;
            const double m = double(census.patches) * double(in_front) / double(census.samples.size());
            pairs += m * m;
        }
    }
    e.links += to_size(pairs);
    e.mirror_links = to_size(pairs);
    e.link_bytes += to_size(double(Links::kLinkBytes) * pairs);
    e.link_build_bytes += to_size(double(link_build_sizes().mirror_link) * pairs);
    e.seconds.links += pairs / kMirrorPairsPerSecond;
}

// The glossy patches build_patches makes: the census' counts of the glossy objects' patches.
std::size_t census_glossy_patches(const Scene& scene, const PatchCensus& census) {
    std::size_t n = 0;
    for (std::size_t k = 0; k < scene.objects.size() && k < census.object_patches.size(); ++k)
        if (scene.objects[k].material.glossy()) n += census.object_patches[k];
    return n;
}

// The glossy patches' cells (transport/glossy_rows.h) at the rings glossy_rings gives: 2 M rows per glossy
// patch, links from every patch each faces into its in-cells and from its out-cells to every
// patch facing it, M^2 multiply-adds per glossy patch and bin; each distinct lobe's cell reflectance.
void estimate_glossy(const Scene& scene, const PatchCensus& census, const PairShares& shares, ResourceEstimate& e) {
    const std::size_t glossy = census_glossy_patches(scene, census);
    const int rings = glossy_rings(scene.links.glossy_resolution, glossy, census.patches);
    e.glossy_rings = rings;
    if (rings <= 0) return;
    const double g = double(glossy);
    const double m = 4.0 * rings * rings;
    std::vector<std::array<double, 3>> lobes;  // the distinct lobes: model, roughness, ior
    for (const Object& o : scene.objects)
        if (o.material.glossy()) {
            const std::array<double, 3> key{double(o.material.type == MaterialType::Plastic), o.material.roughness,
                                            o.material.ior};
            if (std::find(lobes.begin(), lobes.end(), key) == lobes.end()) lobes.push_back(key);
        }
    const double links = 2.0 * shares.facing * g * double(census.patches);
    e.glossy_rows = to_size(2.0 * m * g);
    e.glossy_lobe_fmas = g * m * m;
    e.links += to_size(links);
    e.link_bytes += to_size(double(Links::kLinkBytes) * links + double(Links::kRowBytes) * 2.0 * m * g);
    e.link_build_bytes = std::max(e.link_build_bytes, to_size(double(link_build_sizes().mirror_link) * links));
    e.seconds.links += 0.5 * links / kPairsPerSecond + double(lobes.size()) * 16.0 * m * kCellDirectionSeconds;
}

// Area sources as illuminate() makes them (light_sources.h): one per side of an emissive rectangle,
// one per emissive patch of a mesh. Returns their count and, summed over them, the bins their paths
// span from a patch (their diameter in bins, plus one for where the patch's points fall).
std::array<double, 2> area_source_bins(const Scene& scene, const PatchCensus& census) {
    double sources = 0.0, bins = 0.0;
    const double bin_m = scene.time.bin_width_m();
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        const Object& o = scene.objects[k];
        if (!(o.emission > 0.0).any()) continue;
        const double sides = o.two_sided ? 2.0 : 1.0;
        if (const auto* r = std::get_if<RectangleShape>(&o.shape)) {
            sources += sides;
            bins += sides * ((r->u + r->v).norm() / bin_m + 2.0);
        } else {
            const double patches = double(census.object_patches[k]);
            sources += patches;
            bins += patches * (census.max_edge / bin_m + 2.0);
        }
    }
    return {sources, bins};
}

// The illumination's pulses and the camera's gather; the film's seconds (taps x bins) are counted here
// too, as render.json counts them.
void estimate_camera(const Scene& scene, const PatchCensus& census, const PairShares& shares, ResourceEstimate& e) {
    const double n = double(census.patches);
    const auto [area_sources, area_bins] = area_source_bins(scene, census);
    const double pulses = kPointSourcePulses * n * double(scene.lights.size()) +
                          shares.emitter_facing * n * area_bins + double(census.emissive);
    e.illumination_bytes = to_size(kPulseBytes * pulses);
    double seconds = kPulseSeconds * pulses + kAreaSourceSeconds * shares.emitter_facing * n * area_sources;
    if (scene.camera) {
        e.lit_pixels = lit_share(scene, census);
        const double pixels = double(scene.camera->width) * double(scene.camera->height) * e.lit_pixels;
        const int spp = std::max(1, scene.camera->spp);
        e.samples = to_size(pixels * spp);
        const double taps = pixels * std::min(kTapsPerSample * spp, kTapsPerPixel);
        e.gather_bytes = to_size(kGatherBytesPerSample * double(e.samples) + kGatherBytesPerPatch * n);
        const int films = 1 + bounce_cubes(scene.solver);
        seconds += kSampleSeconds * double(e.samples) + kTapBinSeconds * taps * scene.time.bins * films;
        if (shifts_second_bounce(scene)) seconds += kSecondBounceSecondsPerLink * double(e.links);
    }
    e.seconds.gather = seconds;
}

// The march as the solver would plan it: its inputs from the census and the estimated links, its shape
// by the solver's own rule (march_shape), the lengths of its lists from the sampled pairs, its working
// bytes by the solver's own sum (march_working_bytes). The largest delay is the scene's diagonal.
struct MarchEstimate {
    MarchInputs inputs;
    MarchShape shape;
    std::size_t working_bytes = 0;
    int max_lag = 0;  // bins
};

MarchEstimate estimate_march(const Scene& scene, const PatchCensus& census, const PairShares& shares,
                             const ResourceEstimate& e, const SolverOptions& options, int illuminations) {
    const bool hierarchical = scene.links.method == LinkMethod::Hierarchical;
    const double bin_m = scene.time.bin_width_m(), links = double(e.links);
    MarchEstimate m;
    m.max_lag = int(std::min(census.diagonal / bin_m, 1e8));
    MarchInputs in;
    in.patches = census.patches + e.glossy_rows;
    in.nodes = e.nodes + e.glossy_rows;
    in.links = e.links;
    in.clusters = hierarchical && e.nodes > census.patches;
    in.cluster_block_bins = hierarchical ? cluster_block_bins(census, bin_m) : 0;
    in.longest_lag = m.max_lag;
    in.illuminations = illuminations;
    in.channels = e.channels;
    m.inputs = in;
    m.shape = march_shape(in, options);
    const MarchShape& s = m.shape;
    const bool packed = s.lag_bits > 0, tinted = tinted_mirrors(scene);
    MarchLists l;
    // Every node keeps a ring as long as its longest outgoing link needs (a share of the diagonal in a
    // hierarchical set; packed links: every ring the longest), and a mirror for its long links' windows.
    const double share = hierarchical && !packed ? hierarchical_ring_share(double(census.patches)) : 1.0;
    l.ring_bins = to_size(double(s.nodes) * (share * ring_bins(m.max_lag, s.block_bins) + ring_mirror_bins(s.window_bins)));
    l.short_links = to_size(shares.shorter_than_block * links);
    l.same_bin_links = to_size(shares.same_bin * links);
    l.sweep_rows = std::min(census.patches, l.same_bin_links);
    l.chebyshev = s.layers.layers == 1 && s.layers.fed == 1;
    l.tinted = tinted;
    l.tinted_long = tinted ? e.mirror_links : 0;
    // A copy of the grey links, by window: rows of a flat set are by source, a hierarchical set's by octave.
    l.sorted = !packed && (tinted || (!hierarchical && s.windows > 1));
    l.sorted_links = l.sorted ? e.links - l.tinted_long : 0;
    l.near_links = s.near_list ? to_size(shares.first_window * links) : 0;
    l.packed_links = packed ? to_size((1.0 - shares.shorter_than_block) * links) : 0;
    m.working_bytes = march_working_bytes(s, l);
    return m;
}

// The march and the films' kept profiles; the seconds of the solve. Returns the march's inputs for one
// illumination.
MarchInputs estimate_solver(const Scene& scene, const PatchCensus& census, const PairShares& shares,
                                               const SolverOptions& options, ResourceEstimate& e) {
    e.channels = march_channels(scene_keeps_grey(scene));
    const MarchEstimate one = estimate_march(scene, census, shares, e, options, 1);
    const MarchShape& s = one.shape;
    e.march = s;
    e.layers = s.layers.layers;
    e.ring_bins = ring_bins(one.max_lag, s.block_bins);
    // The films' kept profiles (film_buffer_bytes); a film that reads the second bounce apart keeps it in
    // rows of its own.
    const double film_rows = shifts_second_bounce(scene) ? 2.0 : 1.0;
    const double films = (1.0 + bounce_cubes(scene.solver)) * film_rows * film_buffer_bytes(census.patches, kSinkBins);
    e.solver_bytes = to_size(double(one.working_bytes) + films);
    const double link_bins = double(e.links) * scene.time.bins * s.layers.fed;
    e.seconds.solve = link_bins * ((e.channels == 1 ? kGreyLinkBinSeconds : kColourLinkBinSeconds) +
                                   shares.shorter_than_block * kShortLinkBinSeconds * s.lanes / 3.0);
    // Hierarchical sets are bound by the bin-by-bin pass and the windows, per patch and bin.
    if (scene.links.method == LinkMethod::Hierarchical)
        e.seconds.solve = std::max(e.seconds.solve, kHierarchicalPatchBinSeconds * double(census.patches) * scene.time.bins);
    e.seconds.solve += (e.glossy_lobe_fmas * s.lanes * kLobeSeconds + double(e.glossy_rows) * kGlossyRowBinSeconds) *
                       scene.time.bins * s.layers.fed;
    return one.inputs;
}

// The memory-mapped cubes the solve fills (render_cubes: the transient cube, per-bounce cubes, patch
// profiles; a camera's only where its pixels see something), and what the write phase adds: the steady
// state, the images, the sensor's measurements.
void estimate_outputs(const Scene& scene, const PatchCensus& census, bool patch_profiles, ResourceEstimate& e) {
    const double n = double(census.patches);
    double cube = 0.0, image = 0.0, measurements = 0.0;
    if (scene.camera) {
        for (const RenderCube& c : render_cubes(scene, census.patches, patch_profiles)) {
            cube += double(c.floats()) * sizeof(float) * (c.kind == RenderCube::Kind::Patches ? 1.0 : e.lit_pixels);
            e.cubes.push_back({c.name, c.shape});
        }
        const double pixels = double(scene.camera->width) * double(scene.camera->height);
        image = 4.0 * pixels * 3 * 4;  // the steady image, its preview and the writers' copies
        if (scene.sensor) {
            // K x 3 measurements and a depth per pixel, and for AMCW its K raw samples too.
            const double K = measurement_count(*scene.sensor, scene.time);
            const bool amcw = scene.sensor->exposure.type == ExposureType::Amcw;
            measurements = pixels * (K * 3 + 1 + (amcw ? K : 0.0)) * 4;
        }
    }
    e.cube_bytes = to_size(cube);
    // BiCGSTAB's vectors, one channel at a time, and the radiosities (of the glossy rows too)
    const double steady = 12.0 * (n + double(e.glossy_rows)) * 8;
    e.write_bytes = to_size(steady + image + measurements);
    e.seconds.write = kWriteSeconds + (cube + measurements) / kCubeBytesPerSecond +
                      kSteadySecondsPerLink * double(e.links);
}

// A capture's H (and its time-first copy while it is written); a scene with only a capture that stops at
// the third bounce builds no links and marches nothing. A capture that marches solves its laser points
// in batches of B illuminations, B by the capture's own rule (capture_batch) applied to this model of
// its march (`marched(B)`: working bytes) within the limit less everything else held then (B = 1 when
// none fit: the peak then exceeds the limit and the render is refused). ceil(L / B) marches are run,
// each costing 1 + (B - 1) x kBatchLaneCost single ones.
void estimate_capture(const Scene& scene, const PipelineOptions& options, const std::function<double(int)>& marched,
                      ResourceEstimate& e) {
    if (!scene.capture) return;
    e.cube_bytes += to_size(2.0 * double(scene.capture->pairs()) * scene.time.bins * 4);
    if (!render_needs_links(scene)) {
        e.links = 0;
        e.link_bytes = e.link_build_bytes = e.solver_bytes = 0;
        e.seconds.links = e.seconds.solve = 0.0;
        return;
    }
    if (scene.camera) return;  // the camera's render is estimated; the capture's marches come on top
    const std::size_t lasers = marched_laser_points(*scene.capture);
    // A marched lattice (march_grid_step) keeps every lattice point's later light and a 16-byte record
    // per patch that light came back from (at most every patch) until the scan's points take it.
    if (scene.capture->march_grid_step > 1)
        e.solver_bytes += to_size(double(lasers) * (double(scene.time.bins) * 4.0 + double(e.patches) * 16.0));
    const std::size_t limit = memory_limit_bytes(options);
    const double fixed = double(e.solver_bytes) - marched(1);  // what does not grow with the batch
    const double beside = double(e.base_bytes + e.patch_bytes + e.visibility_bytes + e.link_bytes + e.cube_bytes);
    const int batch = limit > 0 ? capture_batch(marched, double(limit) - beside - fixed) : kMaxBatch;
    e.capture_batch = batch;
    e.capture_marches = (lasers + std::size_t(batch) - 1) / std::size_t(batch);
    e.solver_bytes = to_size(fixed + marched(batch));
    e.seconds.solve *= double(e.capture_marches) * (1.0 + (batch - 1) * kBatchLaneCost);
}

// The peak: the largest sum of what is held at once, stage by stage in the order of a render.
void sum_peak(ResourceEstimate& e) {
    const std::size_t held = e.base_bytes + e.patch_bytes + e.visibility_bytes + e.link_bytes;
    const std::pair<std::size_t, const char*> stages[] = {
        {e.base_bytes + e.mesh_bytes + e.patch_bytes, "patches"},
        {held + e.link_build_bytes, "links"},
        {held + e.illumination_bytes + e.gather_bytes, "gather"},
        {held + e.illumination_bytes + e.gather_bytes + e.solver_bytes + e.cube_bytes, "solve"},
        {held + e.illumination_bytes + e.gather_bytes + e.cube_bytes + e.write_bytes, "write"},
    };
    e.link_stage_bytes = std::max(stages[0].first, stages[1].first);
    for (const auto& [bytes, stage] : stages)
        if (bytes > e.peak_bytes) {
            e.peak_bytes = bytes;
            e.peak_stage = stage;
        }
}

// The value of the line of `file` that starts with `key` (a /proc file's "Key:   123 kB"), times
// `unit`; 0 when there is none.
double proc_value(const char* file, const char* key, double unit) {
    std::ifstream in(file);
    std::string line;
    const std::size_t n = std::char_traits<char>::length(key);
    while (std::getline(in, line))
        if (line.compare(0, n, key) == 0) return std::strtod(line.c_str() + n, nullptr) * unit;
    return 0.0;
}

// The first number in `file` (a cgroup file: "123456", or "max"); 0 when none.
double file_number(const char* file) {
    std::ifstream in(file);
    double v = 0.0;
    return in >> v ? v : 0.0;
}

// The memory this process may still take, bytes (0 when nothing can be read): the least of the
// system's MemAvailable, what its cgroup (a container, a batch job) leaves under its limit, and what
// the address-space limit (ulimit -v) leaves beyond the process's present size and what `threads`
// worker threads reserve besides the estimate's bytes.
std::size_t memory_available(int threads) {
    // A limit already reached still reads as a limit (1 MB of room), not as "nothing known" (0).
    constexpr double kNoRoom = 1e6;
    double free = proc_value("/proc/meminfo", "MemAvailable:", 1024.0);
    auto least = [&](double v) {
        if (v > 0.0) free = free > 0.0 ? std::min(free, v) : v;
    };
    // The process's cgroups (/proc/self/cgroup: "0::/path" for v2, "N:memory:/path" for v1) and every
    // group above them, for a batch job's limit is often a level up. v2's "no limit" reads "max" (0
    // here), v1's is a huge number.
    std::ifstream groups("/proc/self/cgroup");
    for (std::string line; std::getline(groups, line);) {
        const bool v2 = line.rfind("0::", 0) == 0;
        const std::size_t at = line.find(":memory:");
        if (!v2 && at == std::string::npos) continue;
        const std::filesystem::path root = v2 ? "/sys/fs/cgroup" : "/sys/fs/cgroup/memory";
        const char* limit = v2 ? "memory.max" : "memory.limit_in_bytes";
        const char* usage = v2 ? "memory.current" : "memory.usage_in_bytes";
        std::filesystem::path g = root / std::filesystem::path(line.substr(v2 ? 3 : at + 8)).relative_path();
        for (;; g = g.parent_path()) {
            if (const double max = file_number((g / limit).c_str()); max > 0.0 && max < 1e18)
                least(std::max(kNoRoom, max - file_number((g / usage).c_str())));
            if (g == root || g.string().size() <= root.string().size()) break;
        }
    }
    // An address-space limit counts reserved, not used, memory: every worker thread of OpenMP and of
    // Embree's TBB may reserve a 64 MB malloc arena and an 8 MB stack (measured: the Cornell-size
    // corner, 80 MB estimated, needs ulimit -v above 300 MB with 2 threads).
    rlimit as{};
    if (::getrlimit(RLIMIT_AS, &as) == 0 && as.rlim_cur != RLIM_INFINITY)
        least(std::max(kNoRoom, double(as.rlim_cur) - proc_value("/proc/self/status", "VmSize:", 1024.0) -
                                2.0 * thread_count(threads) * 72e6));
    return to_size(free);
}

// "0.425 GB", "18.8 GB", "20011234 GB".
std::string gb(double bytes) {
    char buf[48];
    std::snprintf(buf, sizeof buf, bytes < 1e3 * kGB ? "%.3g GB" : "%.0f GB", bytes / kGB);
    return buf;
}

}  // namespace

ResourceEstimate estimate_resources(const Scene& scene, const PipelineOptions& options, bool patch_profiles) {
    ResourceEstimate e;
    const PatchCensus census = count_patches(scene, kPairSamples);
    const double n = double(census.patches);
    e.patches = census.patches;
    e.max_edge = census.max_edge;
    e.diagonal = census.diagonal;
    e.meshes = census.meshes;
    e.base_bytes = to_size(kBaseBytes);
    e.mesh_bytes = to_size(kMeshBytesPerFace * double(census.mesh_faces));
    e.patch_bytes = PatchSet::bytes_for(census.patches, census.corners);
    e.visibility_bytes = to_size(kEmbreeBytesPerPatch * n);
    e.seconds.patches = kPatchSeconds * n + kMeshSecondsPerFace * double(census.mesh_faces);
    // The links and the march are on the march's bins (march_time: a capture's may be wider).
    Scene marched = scene;
    marched.time = march_time(scene);
    const double bin_m = marched.time.bin_width_m();
    const SolverOptions solver = march_options(scene, options.threads);
    const bool hierarchical = scene.links.method == LinkMethod::Hierarchical;
    const int block_bins = march_block_bins(solver, hierarchical ? cluster_block_bins(census, bin_m) : 0);
    const PairShares shares = pair_shares(marched, census, block_bins * bin_m, bin_m, near_gap_m(census, bin_m));
    e.facing_fraction = shares.facing;
    estimate_links(marched, census, shares, e);
    estimate_mirror_links(marched, census, e);
    estimate_glossy(marched, census, shares, e);
    estimate_camera(scene, census, shares, e);
    const MarchInputs march = estimate_solver(marched, census, shares, solver, e);
    estimate_outputs(scene, census, patch_profiles, e);
    estimate_capture(
        scene, options,
        [&](int batch) { return double(estimate_march(marched, census, shares, e, solver, batch).working_bytes); }, e);
    if (e.capture_batch > 1) {
        MarchInputs batch = march;
        batch.illuminations = e.capture_batch;
        e.march = march_shape(batch, solver);
    }
    sum_peak(e);
    // The throughputs are for 2 threads; every stage but loading the meshes runs in parallel.
    const double scale = 2.0 / double(thread_count(options.threads));
    PhaseSeconds& s = e.seconds;
    for (double* phase : {&s.links, &s.solve, &s.gather, &s.write}) *phase *= scale;
    s.total = s.load + s.patches + s.links + s.solve + s.gather + s.write;
    return e;
}

std::size_t memory_limit_bytes(const PipelineOptions& options) {
    if (options.max_memory_gb > 0.0) return to_size(options.max_memory_gb * kGB);
    return to_size(0.8 * double(memory_available(options.threads)));
}

void check_memory(const Scene& scene, const PipelineOptions& options, bool patch_profiles) {
    const std::size_t limit = memory_limit_bytes(options);
    if (limit == 0) return;  // no /proc/meminfo and no --max-memory: nothing to check against
    const ResourceEstimate e = estimate_resources(scene, options, patch_profiles);
    if (e.peak_bytes <= limit) return;
    std::ostringstream what;
    // A mesh in millimetres among metres is the likeliest cause of an absurd estimate: it comes first.
    if (const std::string outsize = outsize_object(scene, object_boxes(scene, e.meshes)); !outsize.empty())
        what << outsize << "; ";
    char links[32];
    std::snprintf(links, sizeof links, "%.3g", double(e.links));
    what << "estimated peak memory " << gb(double(e.peak_bytes)) << " (" << e.patches << " patches, about "
         << links << " links: links " << gb(double(e.link_bytes)) << ", solver " << gb(double(e.solver_bytes))
         << ", cubes " << gb(double(e.cube_bytes)) << ") exceeds the limit of " << gb(double(limit))
         << (options.max_memory_gb > 0.0 ? " (--max-memory)" : " (80% of the memory available: MemAvailable, the cgroup's limit and ulimit -v; --max-memory GB)")
         << "; nothing was rendered. To shrink it: raise patches.max_edge, lower time.bins or camera.width and "
            "camera.height, "
         << (scene.links.method == LinkMethod::Flat ? "set links.method to \"hierarchical\" or " : "")
         << "raise links.tolerance";
    if (scene.links.method == LinkMethod::Hierarchical && e.near_links > e.links / 2) {
        char gap[32];
        std::snprintf(gap, sizeof gap, "%.3g", e.near_gap_m);
        what << ". Most of the links join single patches less than " << gap
             << " m apart (a bin or more: a cluster link is never shorter), which patches much smaller than a "
                "bin make many: a smaller time.bin_width shortens that reach";
    }
    fail_input(scene.file, "", what.str());
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
