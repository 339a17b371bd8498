// The resource estimate (docs/resources.md): `tprf info` prints it, and `--max-memory`
// refuses a render whose estimate exceeds the limit, with exit status 2, before anything is allocated.
#include "test_process.h"
#include "test_scenes.h"
#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/link_set.h"
#include "tprf/pipeline/capture.h"
#include "tprf/pipeline/info.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"
#include "tprf/transport/solver.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

namespace {

namespace fs = std::filesystem;
using tprf::test::Outcome;

fs::path sample_scene(const std::string& name) { return fs::path(TPRF_SOURCE_DIR) / "meshes" / name; }

class Estimate : public ::testing::Test {
protected:
    void SetUp() override {
        m_dir = fs::temp_directory_path() / ("tprf_estimate_" + std::to_string(std::random_device{}()));
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }
    fs::path m_dir;
};

// A floor and a back wall under a point light, cut at `max_edge`.
std::string corner_scene(double max_edge, int bins = 200) {
    return R"({"time": {"bins": )" + std::to_string(bins) + R"(, "bin_width": 0.01},
      "camera": {"position": [0.5, -1.1, 0.9], "look_at": [0.5, 0.55, 0.25], "up": [0, 0, 1], "fov": 45,
                 "width": 64, "height": 48, "spp": 4},
      "lights": [{"type": "point", "position": [0.3, 0.45, 0.35], "intensity": 1.0}],
      "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]},
                  {"type": "rectangle", "origin": [0, 1, 0], "u": [1, 0, 0], "v": [0, 0, 1]}],
      "patches": {"max_edge": )" + std::to_string(max_edge) + "}}";
}

TEST(PatchCensus, CountsWhatBuildPatchesBuilds) {
    for (const char* name : {"corner.json", "cornell-box.json", "mesh-on-floor.json", "plates.json"}) {
        const tprf::Scene scene = tprf::load_scene(sample_scene(name));
        tprf::PatchStats stats;
        const tprf::PatchSet patches = tprf::build_patches(scene, {}, &stats);
        const tprf::PatchCensus census = tprf::count_patches(scene, 256);
        EXPECT_EQ(census.patches, patches.size()) << name;
        EXPECT_EQ(census.corners, patches.vertices.size()) << name;
        EXPECT_EQ(census.max_edge, stats.max_edge) << name;
        EXPECT_EQ(tprf::dropped_faces(census.meshes), tprf::dropped_faces(stats.meshes)) << name;
        std::size_t emissive = 0;
        for (const tprf::Rgb& e : patches.emission) emissive += (e > 0.0).any();
        EXPECT_EQ(census.emissive, emissive) << name;
        EXPECT_EQ(census.samples.size(), 256u) << name;
    }
}

TEST(PatchCensus, SamplesLieOnTheirObjectsWithTheirSide) {
    tprf::Scene scene;
    scene.time = tprf::test::time_axis(10, 0.1);
    scene.objects.push_back(tprf::test::rectangle({0, 0, 0}, {1, 0, 0}, {0, 1, 0}));
    scene.objects.push_back(tprf::test::rectangle({0, 0, 1}, {0, 2, 0}, {2, 0, 0}));
    scene.objects[1].two_sided = true;
    scene.max_edge = 0.25;
    const tprf::PatchCensus census = tprf::count_patches(scene, 300);
    EXPECT_EQ(census.patches, 16u + 2 * 64u);
    ASSERT_EQ(census.samples.size(), 300u);
    int back = 0;
    for (const tprf::PatchSample& s : census.samples) {
        EXPECT_NEAR(s.point.z(), s.object == 0 ? 0.0 : 1.0, 1e-12);
        if (s.object == 0) {
            EXPECT_EQ(s.normal, tprf::Vec3(0, 0, 1));
        }
        back += s.object == 1 && s.normal.z() > 0;
    }
    // 300 x 128 / 144 draws on the two-sided square, about half of them on its back (its front faces -z).
    EXPECT_GT(back, 90);
    EXPECT_LT(back, 177);
}

TEST(ResourceEstimate, FollowsTheScene) {
    tprf::Scene scene = tprf::load_scene(sample_scene("corner.json"));
    const tprf::ResourceEstimate e = tprf::estimate_resources(scene, {});
    // Two perpendicular squares: every floor patch faces every wall patch, so half of all ordered pairs.
    EXPECT_EQ(e.patches, 2312u);
    EXPECT_NEAR(double(e.links), 2672672.0, 0.05 * 2672672.0);
    EXPECT_EQ(e.channels, 1);  // grey albedo, grey light
    EXPECT_EQ(e.ring_bins, 512);
    EXPECT_GT(e.peak_bytes, e.link_bytes + e.cube_bytes);
    EXPECT_GT(e.seconds.total, 0.0);

    // More bins: a larger cube; per-bounce cubes: five of them; patch profiles: N x T x 3 floats more.
    scene.time.bins *= 2;
    const tprf::ResourceEstimate longer = tprf::estimate_resources(scene, {});
    EXPECT_NEAR(double(longer.cube_bytes), 2.0 * double(e.cube_bytes), 1.0);
    scene.solver.bounces = true;
    const tprf::ResourceEstimate bounces = tprf::estimate_resources(scene, {});
    EXPECT_NEAR(double(bounces.cube_bytes), 6.0 * double(longer.cube_bytes), 6.0);
    EXPECT_EQ(bounces.layers, 5);
    const tprf::ResourceEstimate profiles = tprf::estimate_resources(scene, {}, true);
    EXPECT_NEAR(double(profiles.cube_bytes - bounces.cube_bytes), 2312.0 * scene.time.bins * 12, 2.0);

    // Hierarchical links grow like N log N: far fewer than the flat ones at a million patches.
    scene.max_edge = 0.002;
    scene.links.method = tprf::LinkMethod::Flat;
    const tprf::ResourceEstimate flat = tprf::estimate_resources(scene, {});
    scene.links.method = tprf::LinkMethod::Hierarchical;
    const tprf::ResourceEstimate hierarchical = tprf::estimate_resources(scene, {});
    EXPECT_EQ(hierarchical.patches, 500000u);
    EXPECT_LT(double(hierarchical.links), 1e-2 * double(flat.links));
    EXPECT_LT(hierarchical.peak_bytes, flat.peak_bytes);
}

TEST(ResourceEstimate, CountsTheNearFieldOfHierarchicalLinks) {
    // A hierarchical set refines every pair of clusters nearer than its shortest cluster link (at least
    // one bin) down to single patches, so with 10 cm bins and 1 mm patches each patch of the corner
    // is linked to every patch of the other square within about 10 cm. For points uniform on the
    // floor and the wall (unit squares meeting at an edge) the share of pairs nearer than D is the
    // volume of a quarter ball of radius D along the unit edge, pi D^3 / 3; half of all ordered pairs
    // are floor-wall pairs, and all of those face each other.
    tprf::Scene scene = tprf::load_scene(sample_scene("corner.json"));
    scene.max_edge = 0.001;
    scene.time.bin_width = 0.1;
    scene.time.unit = tprf::TimeUnit::Metres;
    scene.links.method = tprf::LinkMethod::Hierarchical;
    scene.links.tolerance = 0.01;
    const tprf::ResourceEstimate e = tprf::estimate_resources(scene, {});
    ASSERT_EQ(e.patches, 2000000u);
    // D: one bin of gap plus the two patches' circumradii (0.75 sqrt(area) each, info.cpp patch_size).
    const double d = 0.1 + 2 * 0.75 * 0.001, n = double(e.patches);
    const double near = 0.5 * n * (n - 1) * M_PI * d * d * d / 3.0;
    // The estimate's 1024 sampled patches put about 51 per square within D of the edge, and the near
    // pairs come from those few: a relative noise of about 20% (seeds 1-8 at 4096 samples: 0.86 to 1.23
    // of the formula, which the ends of the edge lower by 4%). The estimate aims at a factor of 2.
    EXPECT_GT(double(e.links), 0.5 * near);
    EXPECT_LT(double(e.links), 2.0 * near);
    // 2.2e9 links: far over any machine's memory, so a render is refused before it starts.
    EXPECT_GT(e.peak_bytes, std::size_t(20e9));
}

TEST(ResourceEstimate, CountsThePiecesOfSpreadPatchLinks) {
    // links.spread_pieces turns each patch link into up to that many pieces, one per two bins of the
    // sender's extent (transport/link_spread.cpp). The Cornell box at 10 cm patches and 5 mm bins: the
    // estimate against the links a build makes, both without and with 4 pieces, within the factor of 2
    // the estimate aims at.
    tprf::Scene scene = tprf::load_scene(sample_scene("cornell-box.json"));
    scene.links.method = tprf::LinkMethod::Flat;
    scene.max_edge = 0.1;
    scene.time.bin_width = 0.005;
    scene.time.unit = tprf::TimeUnit::Metres;
    const tprf::PatchSet patches = tprf::build_patches(scene);
    const tprf::Visibility visibility(patches);
    for (const int pieces : {0, 4}) {
        scene.links.spread_pieces = pieces;
        const tprf::ResourceEstimate e = tprf::estimate_resources(scene, {});
        const tprf::LinkSet made =
            tprf::make_link_set(patches, visibility, scene.links, scene.time.bin_width_m(), tprf::LinkOptions{});
        MEASURED("spread_pieces %d: %zu links estimated, %zu made\n", pieces, e.links, made.links.size());
        EXPECT_GT(double(e.links), 0.5 * double(made.links.size())) << pieces << " pieces";
        EXPECT_LT(double(e.links), 2.0 * double(made.links.size())) << pieces << " pieces";
    }
}

// A capture without a camera that marches solves its laser points in batches: 12 x 12 = 144 points make
// 9 marches of 16 with room to spare, the solver's bytes growing by one illumination's lanes a laser point
// in the batch; a limit with room for about 4 illuminations beside the rest gives batches of 4 (36
// marches); with no room for one, a batch of 1 and a peak over the limit (refused). A capture that stops
// at the third bounce marches nothing.
TEST(ResourceEstimate, ModelsTheBatchesOfACapture) {
    tprf::Scene scene = tprf::load_scene(std::string(TPRF_SOURCE_DIR) + "/examples/nlos/letter.json");
    ASSERT_TRUE(scene.capture);
    scene.capture->laser_grid.nu = scene.capture->laser_grid.nv = 12;
    scene.capture->sensor_grid = scene.capture->laser_grid;
    EXPECT_EQ(tprf::estimate_resources(scene, {}).capture_batch, 0);  // max_bounces 3: no march
    scene.capture->max_bounces = -1;
    tprf::PipelineOptions roomy;
    roomy.max_memory_gb = 1000.0;
    const tprf::ResourceEstimate all = tprf::estimate_resources(scene, roomy);
    EXPECT_EQ(all.capture_batch, 16);
    EXPECT_EQ(all.capture_marches, 9u);
    tprf::PipelineOptions one = roomy;
    one.max_memory_gb = 1e-6;
    const tprf::ResourceEstimate single = tprf::estimate_resources(scene, one);
    EXPECT_EQ(single.capture_batch, 1);
    EXPECT_EQ(single.capture_marches, 144u);
    EXPECT_GT(single.peak_bytes, std::size_t(1000));
    const double per_illumination = double(all.solver_bytes - single.solver_bytes) / 15.0;
    ASSERT_GT(per_illumination, 0.0);
    tprf::PipelineOptions four = roomy;
    four.max_memory_gb = (double(single.peak_bytes) + 3.5 * per_illumination) / 1e9;
    const tprf::ResourceEstimate some = tprf::estimate_resources(scene, four);
    EXPECT_EQ(some.capture_batch, 4);
    EXPECT_EQ(some.capture_marches, 36u);
    EXPECT_LE(some.peak_bytes, std::size_t(four.max_memory_gb * 1e9));
    // Four times the marches of four lanes cost more than nine of sixteen (a march of B lanes: 1 + (B - 1) / 15).
    EXPECT_GT(some.seconds.solve, all.seconds.solve);
}

// ---- The estimate and the stages agree on their rules ----
//
// The estimate models counts (links, pairs, ring lengths), but the rules it applies to them are the
// stages' own: a camera render's lanes, block, terms and cube shapes are what the render made, the
// march's whole shape is what the solver's plan made of the built scene (solve_sizing), and with the
// plan's own list lengths the estimate's shape gives the plan's working bytes.

// The march the solver plans for `scene` once built (patches, links on the march's bins, mirrors).
tprf::MarchSizing planned_march(const tprf::Scene& scene, const tprf::SolverOptions& options, int illuminations,
                                int channels) {
    const tprf::TimeAxis time = tprf::march_time(scene);
    const tprf::PatchSet patches = tprf::build_patches(scene);
    const std::unique_ptr<tprf::Visibility> owned = tprf::scene_visibility(scene, patches);
    const tprf::Visibility& visibility = *owned;
    tprf::LinkOptions link_options;
    link_options.threads = options.threads;
    tprf::LinkSet links = tprf::make_link_set(patches, visibility, scene.links, time.bin_width_m(), link_options);
    tprf::add_mirror_links(links, patches, visibility, link_options, time.bin_width_m());
    return tprf::solve_sizing(patches, links, time, options, illuminations, channels);
}

void expect_same_shape(const tprf::MarchShape& estimated, const tprf::MarchShape& planned, const std::string& what) {
    EXPECT_EQ(estimated.patches, planned.patches) << what;
    EXPECT_EQ(estimated.nodes, planned.nodes) << what;
    EXPECT_EQ(estimated.threads, planned.threads) << what;
    EXPECT_EQ(estimated.illuminations, planned.illuminations) << what;
    EXPECT_EQ(estimated.channels, planned.channels) << what;
    EXPECT_EQ(estimated.lanes, planned.lanes) << what;
    EXPECT_EQ(estimated.layers.layers, planned.layers.layers) << what;
    EXPECT_EQ(estimated.layers.terms, planned.layers.terms) << what;
    EXPECT_EQ(estimated.layers.fed, planned.layers.fed) << what;
    EXPECT_EQ(estimated.block_bins, planned.block_bins) << what;
    EXPECT_EQ(estimated.emit_blocks, planned.emit_blocks) << what;
    EXPECT_EQ(estimated.source_tile, planned.source_tile) << what;
    EXPECT_EQ(estimated.lag_bits > 0, planned.lag_bits > 0) << what << ": packed links";
    EXPECT_EQ(estimated.windows, planned.windows) << what;
    EXPECT_EQ(estimated.window_bins, planned.window_bins) << what;
    EXPECT_EQ(estimated.recent_bins, planned.recent_bins) << what;
    EXPECT_EQ(estimated.near_list, planned.near_list) << what;
    EXPECT_EQ(estimated.tile_sum_floats, planned.tile_sum_floats) << what;
}

// Small camera scenes, grey and coloured, flat (sparse and dense rows) and hierarchical, with per-bounce
// cubes and patch profiles: each rendered in memory and estimated.
TEST(EstimateRules, AgreeWithTheRenderAndThePlan) {
    struct Case {
        std::string name;
        tprf::Scene scene;
    };
    std::vector<Case> cases;
    const auto small = [](tprf::Scene s, double max_edge, tprf::LinkMethod method) {
        s.max_edge = max_edge;
        s.links.method = method;
        s.time.bins = 64;
        s.camera->width = 24;
        s.camera->height = 16;
        s.camera->spp = 1;
        return s;
    };
    const tprf::Scene corner = tprf::load_scene(sample_scene("corner.json"));
    const tprf::Scene cornell = tprf::load_scene(sample_scene("cornell-box.json"));
    cases.push_back({"grey flat", small(corner, 0.1, tprf::LinkMethod::Flat)});
    cases.push_back({"colour flat, dense rows", small(cornell, 0.087, tprf::LinkMethod::Flat)});
    cases.push_back({"grey hierarchical", small(corner, 0.05, tprf::LinkMethod::Hierarchical)});
    cases.push_back({"colour hierarchical, every bounce's cube", small(cornell, 0.15, tprf::LinkMethod::Hierarchical)});
    cases.back().scene.solver.bounces = true;
    cases.push_back({"grey flat, bounces 0 to 2", small(corner, 0.1, tprf::LinkMethod::Flat)});
    cases.back().scene.solver.bounces = true;
    cases.back().scene.solver.max_bounces = 2;
    for (const Case& c : cases) {
        tprf::RenderOptions render;
        render.threads = 2;
        render.patch_profiles = true;
        render.max_memory_gb = 1000.0;
        const tprf::RenderResult r = tprf::render_scene(c.scene, render);
        const nlohmann::json solver = nlohmann::json::parse(r.record).at("solver");
        const tprf::ResourceEstimate e = tprf::estimate_resources(c.scene, render, true);
        EXPECT_EQ(e.channels, solver.at("channels").get<int>()) << c.name;
        EXPECT_EQ(e.march.block_bins, solver.at("block_bins").get<int>()) << c.name;
        EXPECT_EQ(e.march.layers.terms, solver.at("bounce_terms").get<int>()) << c.name;
        std::size_t cubes = 0;
        for (const auto& [name, array] : r.arrays)
            cubes += name == "transient" || name == "patch_transient" || name.rfind("transient_bounce_", 0) == 0;
        EXPECT_EQ(e.cubes.size(), cubes) << c.name;
        for (const tprf::CubeShape& cube : e.cubes) {
            ASSERT_TRUE(r.arrays.count(cube.name)) << c.name << ": " << cube.name;
            EXPECT_EQ(r.arrays.at(cube.name).shape, cube.shape) << c.name << ": " << cube.name;
        }
        tprf::SolverOptions options;
        options.delay = c.scene.solver.delay;
        options.max_bounces = c.scene.solver.max_bounces;
        options.bounce_terms = solver.at("bounce_terms").get<int>();
        options.threads = 2;
        const tprf::MarchSizing plan = planned_march(c.scene, options, 1, e.channels);
        expect_same_shape(e.march, plan.shape, c.name);
        EXPECT_EQ(tprf::march_working_bytes(e.march, plan.lists), plan.working_bytes) << c.name;
        EXPECT_NEAR(solver.at("working_mb").get<double>() * 1e6, double(plan.working_bytes), 1.0) << c.name;
    }
}

// The NLOS example's capture, small: 4 x 4 points, 64 bins, every bounce to the sixth.
tprf::Scene small_letter_capture() {
    tprf::Scene scene = tprf::load_scene(std::string(TPRF_SOURCE_DIR) + "/examples/nlos/letter.json");
    scene.max_edge = 0.1;
    scene.links.tolerance = 0.01;
    scene.time.bins = 64;
    scene.time.bin_width = 0.05;
    scene.capture->laser_grid.nu = scene.capture->laser_grid.nv = 4;
    scene.capture->sensor_grid = scene.capture->laser_grid;
    scene.capture->max_bounces = 6;
    return scene;
}

// A capture without a camera marches its laser points in batches: the estimate's march of its batch is
// the plan's, on the capture's orders and lanes (a coloured laser makes three).
TEST(EstimateRules, AgreeWithTheCaptureMarch) {
    tprf::Scene scene = small_letter_capture();
    for (const bool coloured : {false, true}) {
        if (coloured) scene.capture->laser_power = tprf::Rgb(1.0, 0.5, 0.25);
        tprf::PipelineOptions roomy;
        roomy.threads = 2;
        roomy.max_memory_gb = 1000.0;
        const tprf::ResourceEstimate e = tprf::estimate_resources(scene, roomy);
        ASSERT_EQ(e.capture_batch, tprf::kMaxBatch);
        EXPECT_EQ(e.channels, coloured ? 3 : 1);
        tprf::SolverOptions options;
        options.delay = scene.solver.delay;
        options.max_bounces = tprf::capture_march_bounces(*scene.capture);
        options.threads = 2;
        const tprf::MarchSizing plan = planned_march(scene, options, e.capture_batch, e.channels);
        expect_same_shape(e.march, plan.shape, coloured ? "coloured laser" : "grey laser");
        EXPECT_EQ(tprf::march_working_bytes(e.march, plan.lists), plan.working_bytes);
    }
}

// Under a memory budget the capture and the estimate choose the batch by one rule (capture_batch), each
// on its own sizes of the march: a budget of one illumination's march and 5.5 more lanes is 6 for both.
TEST(EstimateRules, CaptureBatchUnderABudget) {
    tprf::Scene scene = small_letter_capture();
    tprf::PipelineOptions roomy;
    roomy.threads = 2;
    roomy.max_memory_gb = 1000.0;
    const tprf::ResourceEstimate e = tprf::estimate_resources(scene, roomy);
    tprf::SolverOptions solver;
    solver.delay = scene.solver.delay;
    solver.max_bounces = tprf::capture_march_bounces(*scene.capture);
    solver.threads = 2;
    const double one = double(planned_march(scene, solver, 1, e.channels).working_bytes);
    const double full = double(planned_march(scene, solver, tprf::kMaxBatch, e.channels).working_bytes);
    ASSERT_GT(full, one);
    const double budget = one + 5.5 * (full - one) / (tprf::kMaxBatch - 1);
    EXPECT_EQ(tprf::batch_that_fits(one, full, budget), 6);
    EXPECT_EQ(tprf::batch_that_fits(one, full, 0.5 * one), 1);
    EXPECT_EQ(tprf::batch_that_fits(one, full, 2.0 * full), tprf::kMaxBatch);
    // Where the straight line promises more lanes than the march of that many needs, the rule takes one fewer.
    const auto bulging = [&](int b) { return b == 6 ? budget + 1.0 : one + (b - 1) * (full - one) / (tprf::kMaxBatch - 1); };
    EXPECT_EQ(tprf::capture_batch(bulging, budget), 5);

    const tprf::PatchSet patches = tprf::build_patches(scene);
    const tprf::Visibility visibility(patches);
    const tprf::LinkSet links =
        tprf::make_link_set(patches, visibility, scene.links, tprf::march_time(scene).bin_width_m(), {});
    tprf::CaptureOptions options;
    options.memory_bytes = std::size_t(budget);
    EXPECT_EQ(tprf::compute_capture(scene, patches, visibility, &links, options).batch, 6);
    // The estimate applies the rule to its own model of the march (one lane: its sizes under a limit too
    // small for two; all lanes: roomy).
    const double beside = double(e.base_bytes + e.patch_bytes + e.visibility_bytes + e.link_bytes + e.cube_bytes);
    tprf::PipelineOptions limited = roomy;
    limited.max_memory_gb = beside / 1e9;
    const tprf::ResourceEstimate tight = tprf::estimate_resources(scene, limited);
    ASSERT_EQ(tight.capture_batch, 1);
    ASSERT_EQ(e.capture_batch, tprf::kMaxBatch);
    const double modelled = double(tight.solver_bytes) +
                            5.5 * double(e.solver_bytes - tight.solver_bytes) / (tprf::kMaxBatch - 1);
    limited.max_memory_gb = (beside + modelled) / 1e9;
    EXPECT_EQ(tprf::estimate_resources(scene, limited).capture_batch, 6);
}

// The estimate against what a render measures (render.json's peak_rss_mb), in a process of its own, on
// the sample scenes (the statue's render takes minutes: bench/estimate_constants.py checks it, and the
// seconds, which no test asserts).
TEST_F(Estimate, IsWithinAFactorTwoOfTheMeasuredPeak) {
#if defined(__SANITIZE_ADDRESS__)
    // AddressSanitizer's shadow memory and quarantine double a process's resident memory (measured:
    // 93.6 MB against 34.7 estimated for the small corner): the estimate models a normal build.
    GTEST_SKIP() << "resident memory under AddressSanitizer is not what the estimate models";
#endif
    const struct {
        std::string name;
        fs::path file;
    } scenes[] = {{"corner at 0.04", m_dir / "corner.json"},
                  {"meshes/corner.json", sample_scene("corner.json")},
                  {"meshes/cornell-box.json", sample_scene("cornell-box.json")},
                  {"meshes/plates.json", sample_scene("plates.json")},
                  {"meshes/mesh-on-floor.json", sample_scene("mesh-on-floor.json")}};
    std::ofstream(m_dir / "corner.json") << corner_scene(0.04);
    for (const auto& s : scenes) {
        const fs::path out = m_dir / "out";
        const Outcome r = tprf::test::run_tprf("render " + s.file.string() + " -o " + out.string() + " --threads 2");
        ASSERT_EQ(r.status, 0) << r.err;
        const auto record = nlohmann::json::parse(std::ifstream(out / "render.json"));
        const double measured = record.at("peak_rss_mb").get<double>();
        tprf::PipelineOptions options;
        options.threads = 2;
        const double estimated = double(tprf::estimate_resources(tprf::load_scene(s.file), options).peak_bytes) / 1e6;
        EXPECT_GT(estimated, measured / 2) << s.name << ": estimated " << estimated << " MB, measured " << measured;
        EXPECT_LT(estimated, measured * 2) << s.name << ": estimated " << estimated << " MB, measured " << measured;
        fs::remove_all(out);
    }
}

TEST_F(Estimate, TooLargeARenderExitsTwoBeforeAllocatingAndNamesTheKeys) {
    // 0.2 mm patches: 5000 x 5000 per square, 50 million patches: about 5e9 hierarchical links (the
    // default), 1.25e15 flat ones. A flat scene is also told to switch its links.method.
    std::string flat = corner_scene(0.0002);
    flat.insert(flat.rfind('}'), R"(, "links": {"method": "flat"})");
    std::ofstream(m_dir / "huge.json") << corner_scene(0.0002);
    std::ofstream(m_dir / "huge_flat.json") << flat;
    for (const char* file : {"huge.json", "huge_flat.json"}) {
        const bool is_flat = std::string(file) == "huge_flat.json";
        const auto start = std::chrono::steady_clock::now();
        const Outcome r = tprf::test::run_tprf("render " + (m_dir / file).string() + " -o " + (m_dir / "out").string() +
                                               " --max-memory 1");
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        EXPECT_EQ(r.status, 2) << r.err;
        EXPECT_LT(seconds, 10.0) << file << ": the refusal must come before the work";
        EXPECT_FALSE(fs::exists(m_dir / "out")) << file << ": nothing is written for a refused render";
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        for (const char* key : {file, "estimated peak memory", "limit of 1 GB", "--max-memory", "patches.max_edge",
                                "time.bins", "camera.width", "camera.height", "links.tolerance"})
            EXPECT_NE(r.err.find(key), std::string::npos) << key << " not in: " << r.err;
        for (const char* key : {"links.method", "\"hierarchical\""})
            EXPECT_EQ(r.err.find(key) != std::string::npos, is_flat) << key << " in: " << r.err;
    }
}

TEST_F(Estimate, InfoDoesNotBuildLinksOverTheLimit) {
    std::ofstream(m_dir / "huge.json") << corner_scene(0.0002);
    const fs::path out = m_dir / "info.txt";
    const Outcome r = tprf::test::shell(std::string(TPRF_BINARY) + " info " + (m_dir / "huge.json").string() +
                                        " --max-memory 1 -q >" + out.string());
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string text = tprf::test::read_bytes(out);
    EXPECT_NE(text.find("OVER the render limit of 1000 MB"), std::string::npos) << text;
    EXPECT_NE(text.find("patches  50000000 (counted"), std::string::npos) << text;
    EXPECT_NE(text.find("links    not built"), std::string::npos) << text;
}

TEST_F(Estimate, ALimitAboveTheEstimateRenders) {
    std::ofstream(m_dir / "small.json") << corner_scene(0.1, 50);
    const Outcome r = tprf::test::run_tprf("render " + (m_dir / "small.json").string() + " -o " +
                                           (m_dir / "out").string() + " --max-memory 4");
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(fs::is_regular_file(m_dir / "out" / "transient.npy"));
    for (const char* bad : {"0", "-1", "lots"})
        EXPECT_EQ(tprf::test::run_tprf("render " + (m_dir / "small.json").string() + " -o " + (m_dir / "bad").string() +
                                       " --max-memory " + bad)
                      .status,
                  2)
            << bad;
}

TEST(CheckMemory, ThrowsInputErrorOverTheLimitOnly) {
    const tprf::Scene scene = tprf::load_scene(sample_scene("corner.json"));
    tprf::PipelineOptions options;
    options.max_memory_gb = 0.01;  // 10 MB: less than the cube alone
    EXPECT_THROW(tprf::check_memory(scene, options), tprf::Error);
    options.max_memory_gb = 1000;
    EXPECT_NO_THROW(tprf::check_memory(scene, options));
    options.max_memory_gb = 0;  // the default: 80% of MemAvailable
    EXPECT_GT(tprf::memory_limit_bytes(options), 0u);
}

TEST_F(Estimate, InfoPrintsTheEstimateBeforeTheMeasuredLinks) {
    std::ofstream(m_dir / "small.json") << corner_scene(0.1, 50);
    const fs::path out = m_dir / "info.txt";
    const Outcome r = tprf::test::shell(std::string(TPRF_BINARY) + " info " + (m_dir / "small.json").string() +
                                        " -q >" + out.string());
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string text = tprf::test::read_bytes(out);
    const std::size_t estimate = text.find("estimate"), links = text.find("\nlinks ");
    ASSERT_NE(estimate, std::string::npos) << text;
    ASSERT_NE(links, std::string::npos) << text;
    EXPECT_LT(estimate, links) << text;
    for (const char* what : {"peak memory", "estimate seconds: patches", "links", "gather", "solve", "write", "total"})
        EXPECT_NE(text.find(what), std::string::npos) << what << " not in: " << text;
}

}  // namespace
