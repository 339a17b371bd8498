#include "tprf/geometry/patches.h"

#include "tprf/core/error.h"
#include "tprf/scene/scene.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using tprf::Vec3;

// Geometry is built from a handful of exact-ish operations on numbers of order 1: 1e-12 is far above
// their rounding and far below any mistake a test could catch.
constexpr double kTol = 1e-12;

tprf::Object rectangle(Vec3 origin, Vec3 u, Vec3 v, bool two_sided = false) {
    tprf::Object o;
    o.shape = tprf::RectangleShape{origin, u, v};
    o.two_sided = two_sided;
    o.emission = tprf::Rgb(1, 2, 3);
    return o;
}

double total_area(const tprf::PatchSet& p) {
    double a = 0.0;
    for (double x : p.area) a += x;
    return a;
}

// Checks what every patch set must satisfy: edges no longer than max_edge, corners counter-clockwise
// about the normal, area and centroid consistent with the corners.
void expect_well_formed(const tprf::PatchSet& p, double max_edge) {
    ASSERT_EQ(p.first.size(), p.size() + 1);
    EXPECT_EQ(p.first.front(), 0u);
    EXPECT_EQ(p.first.back(), p.vertices.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
        const Vec3* c = p.polygon(i);
        const std::size_t n = p.corners(i);
        Vec3 mean = Vec3::Zero();
        for (std::size_t k = 0; k < n; ++k) {
            const Vec3& a = c[k];
            const Vec3& b = c[(k + 1) % n];
            const Vec3& d = c[(k + 2) % n];
            // pieces() allows a relative 1e-9 of overshoot to absorb rounding in length / max_edge.
            EXPECT_LE((b - a).norm(), max_edge * (1 + 1e-9)) << "patch " << i;
            // Every turn is to the left about the normal: convex and counter-clockwise.
            EXPECT_GT((b - a).cross(d - b).dot(p.normal[i]), 0.0) << "patch " << i;
            EXPECT_NEAR((a - c[0]).dot(p.normal[i]), 0.0, kTol) << "patch " << i << " is not planar";
            mean += a / static_cast<double>(n);
        }
        EXPECT_NEAR(p.normal[i].norm(), 1.0, kTol);
        // The area centroid: the corners' mean for triangles and parallelograms; for another convex quad
        // the area-weighted centroids of the two triangles either side of the diagonal 0-2.
        Vec3 centroid = mean;
        if (n == 4) {
            const double a1 = (c[1] - c[0]).cross(c[2] - c[0]).norm(), a2 = (c[2] - c[0]).cross(c[3] - c[0]).norm();
            centroid = (a1 * (c[0] + c[1] + c[2]) + a2 * (c[0] + c[2] + c[3])) / (3.0 * (a1 + a2));
        }
        EXPECT_LT((p.centroid[i] - centroid).norm(), kTol);
    }
}

TEST(Patches, RectangleBecomesGridOfQuads) {
    tprf::Scene scene;
    scene.objects.push_back(rectangle(Vec3(0.2, -1, 0.5), Vec3(0, 1, 0), Vec3(0, 0, 0.5)));
    scene.max_edge = 0.1;
    tprf::PatchStats stats;
    const auto p = tprf::build_patches(scene, {}, &stats);
    EXPECT_DOUBLE_EQ(stats.max_edge, 0.1);
    EXPECT_EQ(tprf::dropped_faces(stats.meshes), 0u);
    ASSERT_EQ(p.size(), 50u);  // ceil(1 / 0.1) x ceil(0.5 / 0.1)
    EXPECT_NEAR(total_area(p), 0.5, kTol);
    for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_EQ(p.corners(i), 4u);
        EXPECT_LT((p.normal[i] - Vec3::UnitX()).norm(), kTol);  // normalize(u x v) = normalize(y x z)
        EXPECT_NEAR(p.area[i], 0.01, kTol);
        EXPECT_EQ(p.object[i], 0u);
        EXPECT_TRUE((p.emission[i] == tprf::Rgb(1, 2, 3)).all());
    }
    expect_well_formed(p, 0.1);
}

TEST(Patches, SkewRectangleKeepsAreaAndOrientation) {
    tprf::Scene scene;
    const Vec3 u(0.7, 0.1, 0), v(0.3, 0.4, 0.2);
    scene.objects.push_back(rectangle(Vec3(1, 2, 3), u, v));
    scene.max_edge = 0.15;
    const auto p = tprf::build_patches(scene);
    EXPECT_EQ(p.size(), std::size_t{5 * 4});  // ceil(0.707 / 0.15) x ceil(0.539 / 0.15)
    EXPECT_NEAR(total_area(p), u.cross(v).norm(), kTol);
    for (const Vec3& n : p.normal) EXPECT_LT((n - u.cross(v).normalized()).norm(), kTol);
    expect_well_formed(p, 0.15);
}

class PatchesMesh : public ::testing::Test {
protected:
    void SetUp() override {
        const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        m_file = fs::temp_directory_path() /
                 ("tprf_patches_test_" + std::to_string(::getpid()) + "_" + test + ".obj");
    }
    void TearDown() override { fs::remove(m_file); }

    tprf::Object mesh(const std::string& obj_text, bool two_sided = false) const {
        std::ofstream(m_file) << obj_text;
        tprf::Object o;
        o.shape = tprf::MeshShape{m_file, Eigen::Matrix4d::Identity()};
        o.two_sided = two_sided;
        return o;
    }

    fs::path m_file;
};

// An equilateral triangle of edge 1 in the plane z = 0, counter-clockwise seen from +z.
const std::string kTriangle = "v 0 0 0\nv 1 0 0\nv 0.5 0.8660254037844386 0\nf 1 2 3\n";

TEST_F(PatchesMesh, TriangleIsRefinedUniformly) {
    tprf::Scene scene;
    scene.objects.push_back(mesh(kTriangle));
    scene.max_edge = 0.3;
    const auto p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 16u);  // n = ceil(1 / 0.3) = 4 pieces per edge, n^2 triangles
    // OpenMesh's OBJ reader parses coordinates as single-precision floats: 1e-7 relative.
    EXPECT_NEAR(total_area(p), std::sqrt(3.0) / 4.0, 1e-7);
    for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_EQ(p.corners(i), 3u);
        EXPECT_LT((p.normal[i] - Vec3::UnitZ()).norm(), kTol);
        EXPECT_NEAR(p.area[i], std::sqrt(3.0) / 64.0, 1e-7);
    }
    expect_well_formed(p, 0.3);
}

TEST_F(PatchesMesh, PlanarQuadStaysAQuad) {
    tprf::Scene scene;
    scene.objects.push_back(mesh("v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nf 1 2 3 4\n"));
    scene.max_edge = 10.0;
    auto p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 1u);
    EXPECT_EQ(p.corners(0), 4u);
    EXPECT_NEAR(total_area(p), 2.0, kTol);
    expect_well_formed(p, 10.0);
    // Cut to 0.5: a grid of 4 x 2 quads, as a rectangle would be.
    scene.max_edge = 0.5;
    p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 8u);
    for (std::size_t i = 0; i < p.size(); ++i) EXPECT_NEAR(p.area[i], 0.25, kTol);
    expect_well_formed(p, 0.5);
}

TEST_F(PatchesMesh, PlanarTrapezoidIsCutIntoConvexQuads) {
    // Bottom edge 3, top edge 1, height 1: area 2. Its longer u edge (3) and v edges (sqrt 2) give a grid
    // of ceil(3 / 0.5) x ceil(1.414 / 0.5) = 6 x 3 planar convex quads (expect_well_formed checks each).
    tprf::Scene scene;
    scene.objects.push_back(mesh("v 0 0 0\nv 3 0 0\nv 2 1 0\nv 1 1 0\nf 1 2 3 4\n"));
    scene.max_edge = 0.5;
    const auto p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 18u);
    EXPECT_NEAR(total_area(p), 2.0, kTol);
    expect_well_formed(p, 0.5);
}

TEST_F(PatchesMesh, NonPlanarQuadIsSplitIntoTriangles) {
    // One corner lifted by 0.1 (of a size of 2): no plane holds the quad, so it is two triangles.
    tprf::Scene scene;
    scene.objects.push_back(mesh("v 0 0 0\nv 2 0 0\nv 2 1 0.1\nv 0 1 0\nf 1 2 3 4\n"));
    scene.max_edge = 10.0;
    const auto p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 2u);
    EXPECT_EQ(p.corners(0), 3u);
    // The fan from corner 1: triangles (0,0,0) (2,0,0) (2,1,0.1) and (0,0,0) (2,1,0.1) (0,1,0).
    const double a1 = 0.5 * Vec3(2, 0, 0).cross(Vec3(2, 1, 0.1)).norm();
    const double a2 = 0.5 * Vec3(2, 1, 0.1).cross(Vec3(0, 1, 0)).norm();
    EXPECT_NEAR(total_area(p), a1 + a2, kTol);
    expect_well_formed(p, 10.0);
}

TEST_F(PatchesMesh, CornerOnAnEdgeLeavesNoSliver) {
    // A square with an extra corner 1 in the middle of the edge from 0 to 2: the fan piece (0, 1, 2) has
    // no area.
    tprf::Scene scene;
    scene.objects.push_back(mesh("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nf 1 2 3 4 5\n"));
    scene.max_edge = 10.0;
    const auto p = tprf::build_patches(scene);
    EXPECT_EQ(p.size(), 2u);
    EXPECT_NEAR(total_area(p), 4.0, kTol);
    expect_well_formed(p, 10.0);
}

TEST_F(PatchesMesh, ConcavePolygonIsEarClippedNotFanned) {
    // An L of area 3 (the unit square [1,2] x [1,2] cut from [0,2] x [0,2]), written from the corner
    // (2, 1) next to the notch: a fan from there would cover the notch and fold over itself.
    tprf::Scene scene;
    scene.objects.push_back(mesh("v 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nv 0 0 0\nv 2 0 0\nf 1 2 3 4 5 6\n"));
    scene.max_edge = 10.0;
    const auto p = tprf::build_patches(scene);
    EXPECT_EQ(p.size(), 4u);  // n - 2 triangles
    EXPECT_NEAR(total_area(p), 3.0, kTol);
    for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_LT((p.normal[i] - Vec3::UnitZ()).norm(), kTol) << "patch " << i;
        // Nothing of the notch: every centroid lies in the L.
        const Vec3& c = p.centroid[i];
        EXPECT_FALSE(c.x() > 1.0 && c.y() > 1.0) << "patch " << i << " at " << c.transpose();
    }
    expect_well_formed(p, 10.0);
}

TEST_F(PatchesMesh, TwoSidedDoublesWithOppositeNormals) {
    tprf::Scene scene;
    scene.objects.push_back(rectangle(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY(), true));
    scene.objects.push_back(mesh(kTriangle, true));
    scene.max_edge = 0.3;
    const auto p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 2u * (16 + 16));
    for (std::size_t i = 0; i < p.size(); i += 2) {
        EXPECT_LT((p.normal[i] + p.normal[i + 1]).norm(), kTol);
        EXPECT_LT((p.centroid[i] - p.centroid[i + 1]).norm(), kTol);
        EXPECT_NEAR(p.area[i], p.area[i + 1], kTol);
        EXPECT_EQ(p.object[i], p.object[i + 1]);
        // Both sides of a two-sided emitter emit (see patches.cpp).
        EXPECT_TRUE((p.emission[i] == p.emission[i + 1]).all());
    }
    expect_well_formed(p, 0.3);
}

TEST_F(PatchesMesh, ObjectIdsAreSceneIndices) {
    tprf::Scene scene;
    scene.objects.push_back(rectangle(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY()));
    scene.objects.push_back(mesh(kTriangle));
    scene.objects.push_back(rectangle(Vec3::UnitZ(), Vec3::UnitY(), Vec3::UnitX()));
    scene.max_edge = 0.5;
    const auto p = tprf::build_patches(scene);
    ASSERT_EQ(p.size(), 4u + 4u + 4u);
    for (std::size_t i = 0; i < p.size(); ++i) EXPECT_EQ(p.object[i], i / 4) << "patch " << i;
    // The third rectangle has u x v = y x x = -z.
    EXPECT_LT((p.normal[11] + Vec3::UnitZ()).norm(), kTol);
}

TEST_F(PatchesMesh, DefaultSizeIsDiagonalOverThirtyTwoAndDropsAreSummed) {
    tprf::Scene scene;
    scene.objects.push_back(rectangle(Vec3::Zero(), Vec3(3, 0, 0), Vec3(0, 4, 0)));
    // The mesh lies inside the rectangle's box and brings one degenerate face.
    scene.objects.push_back(mesh(kTriangle + "f 1 2 2\n"));
    tprf::PatchStats stats;
    std::vector<std::string> notes;
    tprf::PatchOptions options;
    options.notice = [&](const std::string& text) { notes.push_back(text); };
    const auto p = tprf::build_patches(scene, options, &stats);
    EXPECT_DOUBLE_EQ(stats.max_edge, 5.0 / 32.0);  // box 3 x 4 x 0
    EXPECT_DOUBLE_EQ(stats.diagonal, 5.0);
    EXPECT_EQ(tprf::dropped_faces(stats.meshes), 1u);
    EXPECT_EQ(p.size(), std::size_t{20 * 26 + 49});  // ceil(3 / 0.15625) x ceil(4 / 0.15625), n = 7
    expect_well_formed(p, stats.max_edge);
    // The user is told the size and why, once, before anything is cut.
    EXPECT_EQ(notes, std::vector<std::string>{"patches of 0.1562 m: the scene sets no patch size, so its bounding "
                                              "box's diagonal (5 m) / 32 (--max-edge sets it)"});
    // The same scene in millimetres has the same patches; a size of its own, no notice.
    tprf::Scene millimetres;
    millimetres.objects.push_back(rectangle(Vec3::Zero(), Vec3(3000, 0, 0), Vec3(0, 4000, 0)));
    EXPECT_EQ(tprf::build_patches(millimetres).size(), std::size_t{20 * 26});
    scene.max_edge = 0.5;
    notes.clear();
    tprf::PatchStats given;
    tprf::build_patches(scene, options, &given);
    EXPECT_TRUE(notes.empty());
    EXPECT_DOUBLE_EQ(given.max_edge, 0.5);
}

TEST_F(PatchesMesh, ReportsProgressPerObject) {
    tprf::Scene scene;
    scene.objects.push_back(rectangle(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY()));
    scene.objects.push_back(mesh(kTriangle));
    std::vector<double> fractions;
    tprf::PatchOptions options;
    options.progress = [&](std::string_view phase, double f) {
        EXPECT_EQ(phase, "patches");
        fractions.push_back(f);
    };
    tprf::build_patches(scene, options);
    EXPECT_EQ(fractions, (std::vector<double>{0.5, 1.0}));
}

TEST_F(PatchesMesh, MissingMeshNamesItsObject) {
    tprf::Scene scene;
    scene.file = "scene.json";
    scene.objects.push_back(rectangle(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY()));
    tprf::Object o;
    o.shape = tprf::MeshShape{m_file, Eigen::Matrix4d::Identity()};
    scene.objects.push_back(o);
    try {
        tprf::build_patches(scene);
        ADD_FAILURE() << "no error";
    } catch (const tprf::Error& e) {
        EXPECT_NE(std::string(e.what()).find("scene.json: objects[1].file: "), std::string::npos) << e.what();
    }
}

TEST(Patches, AddPatchComputesCentroidOfTrapezoid) {
    // Trapezoid with parallel sides 2 (y = 0) and 1 (y = 1): area 1.5, centroid height
    // h (b1 + 2 b2) / (3 (b1 + b2)) = 4/9, x = 1 by symmetry.
    const std::array<Vec3, 4> c{Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(1.5, 1, 0), Vec3(0.5, 1, 0)};
    tprf::PatchSet p;
    tprf::add_patch(p, c.data(), c.size(), tprf::Rgb::Constant(0.5), tprf::Rgb::Zero(), 7);
    ASSERT_EQ(p.size(), 1u);
    EXPECT_EQ(p.first, (std::vector<std::uint32_t>{0, 4}));
    EXPECT_NEAR(p.area[0], 1.5, kTol);
    EXPECT_LT((p.centroid[0] - Vec3(1, 4.0 / 9.0, 0)).norm(), kTol);
    EXPECT_LT((p.normal[0] - Vec3::UnitZ()).norm(), kTol);
    EXPECT_EQ(p.object[0], 7u);
}

}  // namespace
