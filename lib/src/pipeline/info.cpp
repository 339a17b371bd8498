#include "tprf/pipeline/info.h"

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

SceneSummary describe_scene(const Scene& scene, const PipelineOptions& options) {
    SceneSummary s;
    auto t0 = std::chrono::steady_clock::now();
    PatchStats patch_stats;
    const PatchSet patches = build_patches(scene, {options.progress}, &patch_stats);
    s.patches = patches.size();
    s.max_edge = patch_stats.max_edge;
    s.seconds_patches = seconds_since(t0);

    t0 = std::chrono::steady_clock::now();
    const std::unique_ptr<Visibility> owned = scene_visibility(scene, patches);
    const Visibility& visibility = *owned;
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
    s.links = links.links.size();
    s.link_bytes = links.bytes();
    s.pairs_tested = link_stats.pairs_tested;
    s.seconds_links = seconds_since(t0);
    return s;
}

// ---- Resource estimate (SPEC.md v2, "Links and scale": `tprf info`, `--max-memory`) ----
//
// Every constant below was measured on the project's machine (AMD EPYC, 2 cores, 23.5 GiB; see
// bench/RESULTS.md for the runs the throughputs come from): bytes from VmRSS and VmHWM around each stage
// (meshes/corner.json and meshes/cornell-box.json at their own and at finer patch sizes), seconds on 2
// threads. Repeated runs on that shared machine vary by up to 30%; the estimate aims at a factor of 2.

namespace {

constexpr double kMB = 1e6;
constexpr double kGB = 1e9;

// Memory, bytes.
constexpr double kBaseBytes = 16 * kMB;          // the process before any stage: code, libraries, threads
constexpr double kPatchBytes = 108;              // a patch's arrays besides its corners (centroid ... object)
constexpr double kCornerBytes = 24;              // one corner (a Vec3)
constexpr double kMeshBytesPerFace = 150;        // a mesh file while it is loaded and triangulated (1M faces:
                                                 // 84 binary PLY, 87 OBJ, 183 binary STL; bench/RESULTS.md)
constexpr double kEmbreeBytesPerPatch = 180;     // Embree's quads and BVH (RTC_BUILD_QUALITY_HIGH), at its peak
constexpr double kLinkBytes = 12;                // a link: source u32, form factor f32, distance f32
constexpr double kRowBytes = 8;                  // a CSR row offset per receiver
constexpr double kLinkBuildBytes = 4;            // the link builder's pair lists, per link (8 bytes a pair)
constexpr double kHierarchicalLinkBuildBytes = 10;  // the hierarchical builder's records (20 bytes a pair
                                                    // of links; 16 a link until 2026-11-26, when a wavy
                                                    // sheet at 99k patches measured 15)
constexpr double kOracleBytesPerNode = 16 * 24;  // the hierarchical builder's stored points, 16 a node
constexpr double kTreeBytesPerNode = 100;        // a cluster tree node (bounds, cone, ranges, levels)
constexpr double kPulseBytes = 64;               // a pulse (40 bytes) and the per-patch lists it was built in
constexpr double kGatherBytesPerSample = 450;    // sensing point, neighbour lists, taps before and after assembly
constexpr double kGatherBytesPerPatch = 100;     // FLANN's index over the centroids
constexpr double kShortLinkBytes = 16;           // a link shorter than a block, in the solver's own list
constexpr double kSameBinLinkBytes = 8;          // a link within one bin
constexpr double kPackedLinkBytes = 12;          // a flat set's link packed for the march (solver_plan.cpp
                                                 // pack_links): source and lag u32, two taps f32
constexpr double kDenseRowLinks = 256;           // links a receiver from which the march packs them (kDenseRow)
constexpr int kDenseWindowBins = 64;             // the windows packed links are read in (kDenseLongestWindow)
const int kBlockBins = SolverOptions{}.block_bins;  // the solver's block (hierarchical sets: shorter)
constexpr int kPointSourcePulses = 2;            // pulses per patch and point source: its 16 samples' pulses are
                                                 // merged per bin (IlluminationOptions::merge_bins), 1-2 bins
// Area sources: a lit patch keeps a pulse per bin that the source's paths span from it (merged there).

// Link counts.
constexpr std::size_t kPairSamples = 1024;       // patches sampled to estimate which pairs face each other
/// Hierarchical links: c N^0.45 sqrt(0.003 / tolerance), a fit to what the builder made (bench/RESULTS.md,
/// third step): the Cornell box from 4k to 1M patches at tolerance 0.003 (1 cm bins: 2.7M to 51.5M
/// links, the fit within 0.6x-1.6x; at 5 mm bins up to 1.7x more), the statue at 0.01-0.001 (within
/// 1.3x). The count grows slower than N: far apart, the same cluster links serve finer patches.
constexpr double kHierarchicalLinksScale = 1.03e5;
constexpr double kHierarchicalLinksExponent = 0.45;
/// The share of a full ring (the scene's diagonal) that an average node of a hierarchical set keeps
/// (its longest outgoing link): (N / 16k)^(-1/3), at most 1. Measured on the Cornell box: 0.84 (4k),
/// 0.74 (16k), 0.47 (64k), 0.30 (256k), 0.20 (1M); the statue (57k): 0.9.
double hierarchical_ring_share(double n) { return std::min(1.0, std::cbrt(16000.0 / std::max(n, 1.0))); }

// Seconds on 2 threads.
constexpr double kPatchSeconds = 4e-7;               // per patch (110k patches in 0.04 s)
constexpr double kMeshSecondsPerFace = 4.5e-7;       // reading a mesh file and cutting it (1M faces: 0.14 s
                                                     // binary PLY to 0.42 s ASCII OFF, bench/RESULTS.md)
constexpr double kEmbreeSeconds = 1.2e-6;            // per patch (110k patches in 0.12 s)
constexpr double kPairsPerSecond = 4.2e6;            // flat links: unordered pairs considered (4.1-4.4 M/s)
/// Hierarchical link stage: s N^0.74 sqrt(0.003 / tolerance) (the Cornell box: 3.7 s at 4k patches, 42 s at
/// 64k, 262 s at 1M; the statue at 0.01: 12 s, 0.7x of it).
constexpr double kHierarchicalLinkSecondsScale = 9.5e-3;
constexpr double kHierarchicalLinkSecondsExponent = 0.74;
constexpr double kPulseSeconds = 2e-7;               // per pulse, shadow rays included
constexpr double kAreaSourceSeconds = 4e-5;          // per patch and area source that face each other (the
                                                     // Cornell box's light: 2.9e-5 at 4.5k patches and 5 mm
                                                     // bins, 4.4e-5 at 1M patches and 1 cm)
constexpr double kSampleSeconds = 2e-6;              // per camera sample (0.35-1.0 M samples/s)
constexpr double kTapBinSeconds = 1.0 / 1.5e9;       // the film: one tap applied to one bin
// camera.shift_second_bounce: the second bounce from the links, its shift and its own taps, per link
// (measured on the Cornell box: 0.15 s for 2.9M links, 2.1 s for 46M).
constexpr double kFirstLinkSecondsPerLink = 5e-8;
// The solve: link-bin updates a second, grey / colour. Flat 4k Cornell box, 2 Zen 5 cores, 2026-11-28:
// colour 11.6e9 with AVX-512, 7.8e9 with AVX2 (packed links); grey 19-22e9 with AVX-512. The AVX2
// rates, for machines without AVX-512 (grey: the colour one's 1.7x, as with AVX-512).
constexpr double kLinkBinSeconds[2] = {1.0 / 13e9, 1.0 / 7.5e9};
constexpr double kShortLinkBinSeconds = 1.0 / 1e9;   // a short link applied bin by bin
/// The hierarchical solve per patch and bin: 2.6e-7 to 1.4e-6 s on the Cornell box from 4k to 1M patches
/// (3 channels), 4.3e-7 on the statue (1 channel).
constexpr double kHierarchicalPatchBinSeconds = 5e-7;
/// Hierarchical links in the near field (single patches, all of them refined to): a wavy sheet of 99k
/// patches under 10 cm bins, 159M links in 88 s.
constexpr double kNearLinkSeconds = 5.5e-7;
constexpr double kWriteSeconds = 0.2;                // the images and render.json
constexpr double kCubeBytesPerSecond = 0.7e9;        // writing back the memory-mapped cubes
constexpr double kSpreadBuildBytes = 16;          // link_spread.cpp: each piece in its row's list while the CSR is made
constexpr double kSpreadSecondsPerLink = 2e-7;     // link_spread.cpp: 0.6 s for the Cornell box's 2.9M flat links
constexpr double kSteadySecondsPerLink = 3e-8;       // the steady state (BiCGSTAB on the links, 3 channels)
constexpr int kTapsPerSample = 8;                    // neighbouring patches a camera sample interpolates between
constexpr int kTapsPerPixel = 32;                    // at most, once the samples of a pixel are merged

// A count or a byte size from the model's doubles, held under 1e18 so that sums of them cannot overflow.
std::size_t to_size(double v) { return v >= 1e18 ? std::size_t(1e18) : v > 0.0 ? std::size_t(v) : 0; }

bool grey(const Rgb& c) { return c[0] == c[1] && c[1] == c[2]; }

// Whether the camera reads the second bounce at its samples' times (render.cpp, make_first_link_light):
// no mirror or glass.
bool shifts_second_bounce(const Scene& scene) {
    return scene.camera && scene.camera->shift_second_bounce &&
           std::none_of(scene.objects.begin(), scene.objects.end(), [](const Object& o) { return o.material.specular(); });
}

// Whether some mirror or glass reflects the channels unalike: its links are tinted (Links::tint).
bool tinted_mirrors(const Scene& scene) {
    return std::any_of(scene.objects.begin(), scene.objects.end(),
                       [](const Object& o) { return !grey(o.material.reflectance); });
}

// The solver marches one channel when every albedo, every source and every mirror's reflectance is grey
// (as the solver decides).
bool scene_grey(const Scene& scene) {
    if (tinted_mirrors(scene)) return false;
    for (const Object& o : scene.objects)
        if (!grey(o.albedo) || !grey(o.emission)) return false;
    for (const Light& l : scene.lights) {
        if (const auto* p = std::get_if<PointLight>(&l); p && !grey(p->intensity)) return false;
        if (const auto* p = std::get_if<Laser>(&l); p && !grey(p->power)) return false;
    }
    return true;
}

// A patch's circumradius from its area: about 0.75 sqrt(area) for the squares and near-equilateral
// triangles patches are cut into (0.71 for a square, 0.88 for an equilateral triangle).
double patch_size(double area) { return 0.75 * std::sqrt(area); }

// What the sampled patch pairs say: the share that face each other, the same among pairs with an
// emitter, and among the facing ones the share shorter than a block, within one bin, and in the near
// field of a hierarchical set (gaps under near_gap_m, which is kept with them).
struct PairShares {
    double facing = 0.0, emitter_facing = 0.0, shorter_than_block = 0.0, same_bin = 0.0, near = 0.0;
    double near_gap_m = 0.0;
};

PairShares pair_shares(const Scene& scene, const PatchCensus& census, double block_m, double bin_m, double gap_m) {
    PairShares s;
    s.near_gap_m = gap_m;
    std::uint64_t pairs = 0, facing = 0, emitter_pairs = 0, emitter_facing = 0, shorter = 0, same = 0, near = 0;
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
            near += r < gap_m + patch_size(v[i].area) + patch_size(v[j].area);
        }
    }
    if (pairs > 0) s.facing = double(facing) / double(pairs);
    s.emitter_facing = emitter_pairs > 0 ? double(emitter_facing) / double(emitter_pairs) : s.facing;
    if (facing > 0) {
        s.shorter_than_block = double(shorter) / double(facing);
        s.same_bin = double(same) / double(facing);
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

// The gap under which a hierarchical set links single patches only: clusters nearer than the shortest
// cluster link (default_min_lag_bins: four median patch sizes in bins, 1 to 32) are refined, so
// every facing pair of patches whose gap is shorter is a link of its own. The sampled patches' median
// size stands for the set's.
double near_gap_m(const PatchCensus& census, double bin_m) {
    if (census.samples.empty() || !(bin_m > 0.0)) return 0.0;
    return default_min_lag_bins(median_extent(census), bin_m) * bin_m;
}

// Solver layers and per-order terms, as the render asks for them (render.cpp bounce_terms, solver_plan.cpp
// plan_layers): {layers, solver terms, per-bounce cubes}.
std::array<int, 3> bounce_layout(const SolverSettings& s) {
    const int cubes = s.bounces ? (s.max_bounces >= 0 ? s.max_bounces + 1 : 5) : 0;
    if (s.max_bounces >= 0) return {s.max_bounces + 1, cubes > 0 ? s.max_bounces + 1 : 0, cubes};
    if (cubes > 1) return {cubes, cubes, cubes};
    return {1, 0, cubes};
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
    double build_bytes = kLinkBuildBytes;
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
        build_bytes = kHierarchicalLinkBuildBytes;
        e.nodes = census.patches > 0 ? 2 * census.patches - 1 : 0;
        rows = double(e.nodes);
        tree = kTreeBytesPerNode * rows;
        seconds = std::max(near * kNearLinkSeconds, kHierarchicalLinkSecondsScale *
                                                        std::pow(n, kHierarchicalLinkSecondsExponent) * tolerance_factor);
    }
    double build = build_bytes * links + (tree > 0.0 ? kOracleBytesPerNode * rows : 0.0);
    // links.spread_pieces (transport/link_spread.cpp): each patch link becomes up to that many pieces.
    const double pieces = spread_pieces(scene, census);
    if (pieces > 0.0) {
        const double patch_links = scene.links.method == LinkMethod::Hierarchical ? std::min(links, shares.near * flat) : links;
        links += patch_links * (pieces - 1.0);
        build = std::max(build, (kSpreadBuildBytes + kLinkBytes) * patch_links * pieces);
        seconds += patch_links * kSpreadSecondsPerLink;
    }
    e.links = to_size(links);
    e.link_bytes = to_size(kLinkBytes * links + kRowBytes * (rows + n) + tree);
    e.link_build_bytes = to_size(build);
    e.seconds.links = kEmbreeSeconds * n + seconds;
}

// Links through mirrors and glass (transport/mirror_links.cpp): every pair of patches in front of a
// specular rectangle's reflecting side, both facing it, is a link (one reflection; chains of more are
// left out). The share of the patches there comes from the census' samples.
constexpr double kMirrorPairsPerSecond = 1.0e6;   // ordered pairs (echo scene: 160k pairs in 0.15 s)
constexpr double kMirrorBuildBytes = 28;          // the pair records (16 bytes) and the rows' rebuilt copy

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
    e.link_bytes += to_size(kLinkBytes * pairs);
    e.link_build_bytes += to_size(kMirrorBuildBytes * pairs);
    e.seconds.links += pairs / kMirrorPairsPerSecond;
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
        const int films = 1 + bounce_layout(scene.solver)[2];
        seconds += kSampleSeconds * double(e.samples) + kTapBinSeconds * taps * scene.time.bins * films;
        if (shifts_second_bounce(scene)) seconds += kFirstLinkSecondsPerLink * double(e.links);
    }
    e.seconds.gather = seconds;
}

// The march: rings of every node that sends (the largest delay is the scene's diagonal), block buffers,
// the lists of links shorter than a block and the films' block scratch. Returns the part that grows
// with the lanes (rings, blocks, the blocks handed over): the bytes of one illumination's lanes.
double estimate_solver(const Scene& scene, const PatchCensus& census, const PairShares& shares, ResourceEstimate& e) {
    const auto [layers, terms, cubes] = bounce_layout(scene.solver);
    const double bin_m = scene.time.bin_width_m();
    const int max_lag = int(std::min(census.diagonal / bin_m, 1e8));
    e.channels = scene_grey(scene) ? 1 : 3;
    e.layers = layers;
    e.ring_bins = int(std::bit_ceil(unsigned(max_lag + kBlockBins + 2)));
    const double n = double(census.patches), nodes = double(e.nodes), C = e.channels, L = layers;
    const double share = scene.links.method == LinkMethod::Hierarchical ? hierarchical_ring_share(n) : 1.0;
    // Flat sets' dense rows: the march packs the links once more and reads them in longer windows,
    // which the rings' mirrors and the accumulators hold (a render's one illumination: 1 or 3 lanes).
    const bool packed = scene.links.method == LinkMethod::Flat && double(e.links) >= kDenseRowLinks * n;
    const int window = packed ? std::max(kBlockBins, kDenseWindowBins) : kBlockBins;
    const double rings = L * nodes * (share * e.ring_bins + window + 1) * C * 4;
    const double blocks = L * nodes * (kBlockBins + window) * C * 4 + 2 * L * nodes * C * 4;
    // The solver's blocks and the films' kept profiles (film_buffer_bytes).
    // A film that reads the second bounce apart keeps it in rows of its own.
    const double film_rows = shifts_second_bounce(scene) ? 2.0 : 1.0;
    // The blocks handed to the sink, each illumination's (kSinkBins bins at most); short blocks
    // (hierarchical sets) are kept a second time until the sink takes them, at most kSinkBytes.
    const double handed = (1.0 + terms) * n * kSinkBins * 3 * 4;
    const double outputs = handed + std::min(handed, double(kSinkBytes)) +
                           (1.0 + cubes) * film_rows * film_buffer_bytes(census.patches, kSinkBins);
    double lists = double(e.links) * (shares.shorter_than_block * kShortLinkBytes +
                                      shares.same_bin * kSameBinLinkBytes) + 2 * kRowBytes * n;
    // Tinted mirrors: the march keeps its own copy of the grey links (solver_plan.cpp plan_windows), the
    // packed one where it packs them.
    if (tinted_mirrors(scene) && !packed) lists += double(e.links) * kLinkBytes;
    if (packed) lists += double(e.links) * kPackedLinkBytes;
    e.solver_bytes = to_size(rings + blocks + outputs + lists);
    // Layers that gather from links (solver_plan.cpp plan_layers): all but the first order's, or the one total.
    const double fed = (layers == 1 && scene.solver.max_bounces < 0) ? 1 : layers - 1;
    const double link_bins = double(e.links) * scene.time.bins * fed;
    e.seconds.solve = link_bins * (kLinkBinSeconds[e.channels == 1 ? 0 : 1] +
                                   shares.shorter_than_block * kShortLinkBinSeconds * C / 3.0);
    // Hierarchical sets are bound by the bin-by-bin pass and the windows, per patch and bin.
    if (scene.links.method == LinkMethod::Hierarchical)
        e.seconds.solve = std::max(e.seconds.solve, kHierarchicalPatchBinSeconds * n * scene.time.bins);
    return rings + blocks + handed;
}

// The memory-mapped cubes the solve fills (the transient cube, per-bounce cubes, patch profiles), and
// what the write phase adds: the steady state, the images, the sensor's measurements.
void estimate_outputs(const Scene& scene, const PatchCensus& census, bool patch_profiles, ResourceEstimate& e) {
    const double n = double(census.patches), T = scene.time.bins;
    double cube = 0.0, image = 0.0, measurements = 0.0;
    if (scene.camera) {
        const double pixels = double(scene.camera->width) * double(scene.camera->height);
        cube = (1.0 + bounce_layout(scene.solver)[2]) * pixels * e.lit_pixels * T * 3 * 4;
        image = 4.0 * pixels * 3 * 4;  // the steady image, its preview and the writers' copies
        if (scene.sensor) measurements = pixels * (measurement_count(*scene.sensor, scene.time) * 3 + 1) * 4;
    }
    if (patch_profiles) cube += n * T * 3 * 4;
    e.cube_bytes = to_size(cube);
    const double steady = 12.0 * n * 8;  // BiCGSTAB's vectors, one channel at a time, and the N radiosities
    e.write_bytes = to_size(steady + image + measurements);
    e.seconds.write = kWriteSeconds + (cube + measurements) / kCubeBytesPerSecond +
                      kSteadySecondsPerLink * double(e.links);
}

// The peak: the largest sum of what is held at once, stage by stage in the order of a render.
// A capture's H (and its time-first copy while it is written); a scene with only a capture that stops at
// the third bounce builds no links and marches nothing. A capture that marches solves its laser points
// in batches of B illuminations, as pipeline/capture.cpp chooses B: the most, up to kMaxBatch, whose
// lanes fit in the limit beside everything else held then (B = 1 when none fit: the peak then exceeds
// the limit and the render is refused). A march of B lanes costs about 1 + (B - 1) / 15 single marches
// (a 16-lane march measured 2x one lane, bench/capture_bench.py); ceil(L / B) marches are run.
void estimate_capture(const Scene& scene, const PipelineOptions& options, double per_illumination,
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
    const double fixed = double(e.solver_bytes) - per_illumination;  // what does not grow with the batch
    const double held =
        double(e.base_bytes + e.patch_bytes + e.visibility_bytes + e.link_bytes + e.cube_bytes + e.solver_bytes);
    const double room = limit > 0 ? double(limit) - held : INFINITY;
    const int batch = int(std::clamp(1.0 + std::floor(room / std::max(per_illumination, 1.0)), 1.0, double(kMaxBatch)));
    e.capture_batch = batch;
    e.capture_marches = (lasers + std::size_t(batch) - 1) / std::size_t(batch);
    e.solver_bytes = to_size(fixed + batch * per_illumination);
    e.seconds.solve *= double(e.capture_marches) * (1.0 + (batch - 1) / 15.0);
}

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
    e.meshes = census.meshes;
    e.base_bytes = to_size(kBaseBytes);
    e.mesh_bytes = to_size(kMeshBytesPerFace * double(census.mesh_faces));
    e.patch_bytes = to_size(kPatchBytes * n + kCornerBytes * double(census.corners));
    e.visibility_bytes = to_size(kEmbreeBytesPerPatch * n);
    e.seconds.patches = kPatchSeconds * n + kMeshSecondsPerFace * double(census.mesh_faces);
    // The links and the march are on the march's bins (march_time: a capture's may be wider).
    Scene marched = scene;
    marched.time = march_time(scene);
    const double bin_m = marched.time.bin_width_m();
    const PairShares shares = pair_shares(marched, census, kBlockBins * bin_m, bin_m, near_gap_m(census, bin_m));
    e.facing_fraction = shares.facing;
    estimate_links(marched, census, shares, e);
    estimate_mirror_links(marched, census, e);
    estimate_camera(scene, census, shares, e);
    const double per_illumination = estimate_solver(marched, census, shares, e);
    estimate_outputs(scene, census, patch_profiles, e);
    estimate_capture(scene, options, per_illumination, e);
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
