#include "mesh_files.h"
#include "tprf/scene/mesh_io.h"

#include "tprf/core/error.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using tprf::Vec3;

using Mesh = tprf::test::MeshFiles;
using tprf::test::expect_input_error;

// The faces as lists, for tests that walk them.
std::vector<std::vector<int>> faces_of(const tprf::PolygonMesh& mesh) {
    std::vector<std::vector<int>> out;
    for (std::size_t f = 0; f < mesh.faces(); ++f) out.emplace_back(mesh.face(f).begin(), mesh.face(f).end());
    return out;
}

double total_area(const tprf::PolygonMesh& mesh) {
    double area = 0.0;
    for (const auto& face : faces_of(mesh)) {
        Vec3 n = Vec3::Zero();
        for (std::size_t i = 0; i < face.size(); ++i)
            n += mesh.vertices[face[i]].cross(mesh.vertices[face[(i + 1) % face.size()]]);
        area += 0.5 * n.norm();
    }
    return area;
}

Vec3 face_normal(const tprf::PolygonMesh& mesh, std::size_t f) {
    const auto face = mesh.face(f);
    const Vec3& a = mesh.vertices[face[0]];
    return (mesh.vertices[face[1]] - a).cross(mesh.vertices[face[2]] - a).normalized();
}

// The unit square [0,1]^2 at z = 0 as two triangles, counter-clockwise seen from +z, in each format.
const char* kSquareObj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n";
const char* kSquareOff = "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
const char* kSquarePly =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
const char* kSquareStl =
    "solid square\n"
    "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nendloop\nendfacet\n"
    "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\n"
    "endsolid square\n";

// Scale 2, then 90 degrees about +z, then translate (1, 2, 3), as the scene file composes them.
Eigen::Matrix4d scale_rotate_translate() {
    Eigen::Affine3d t = Eigen::Translation3d(1, 2, 3) * Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()) *
                        Eigen::Scaling(2.0);
    return t.matrix();
}

void expect_transformed_square(const tprf::PolygonMesh& mesh) {
    ASSERT_EQ(mesh.vertices.size(), 4u);
    ASSERT_EQ(mesh.faces(), 2u);
    EXPECT_FALSE(mesh.repairs.any()) << tprf::describe(mesh.repairs);
    // Scaling lengths by 2 scales area by 4; the inputs are small integers, exact in float and double.
    EXPECT_NEAR(total_area(mesh), 4.0, 1e-12);
    // (x, y, 0) -> (2x, 2y, 0) -> (-2y, 2x, 0) -> (1 - 2y, 2 + 2x, 3).
    for (const Vec3& expected : {Vec3(1, 2, 3), Vec3(1, 4, 3), Vec3(-1, 4, 3), Vec3(-1, 2, 3)}) {
        const bool found = std::any_of(mesh.vertices.begin(), mesh.vertices.end(),
                                       [&](const Vec3& v) { return (v - expected).norm() < 1e-12; });
        EXPECT_TRUE(found) << expected.transpose();
    }
    // A rotation about z keeps the file's counter-clockwise front facing +z.
    for (std::size_t f = 0; f < mesh.faces(); ++f)
        EXPECT_NEAR(face_normal(mesh, f).z(), 1.0, 1e-12);
}

TEST_F(Mesh, ReadsObjWithTransform) {
    expect_transformed_square(tprf::load_mesh(write("square.obj", kSquareObj), scale_rotate_translate(),
                                              "scene.json", "objects[0].file"));
}

TEST_F(Mesh, ReadsOffWithTransform) {
    expect_transformed_square(tprf::load_mesh(write("square.off", kSquareOff), scale_rotate_translate(),
                                              "scene.json", "objects[0].file"));
}

TEST_F(Mesh, ReadsAsciiPlyWithTransform) {
    expect_transformed_square(tprf::load_mesh(write("square.ply", kSquarePly), scale_rotate_translate(),
                                              "scene.json", "objects[0].file"));
}

TEST_F(Mesh, ReadsAsciiStlWithTransform) {
    expect_transformed_square(tprf::load_mesh(write("square.stl", kSquareStl), scale_rotate_translate(),
                                              "scene.json", "objects[0].file"));
}

std::string binary_stl(const std::vector<std::array<float, 9>>& triangles) {
    std::string out(80, ' ');
    auto put = [&](const void* p, std::size_t n) { out.append(static_cast<const char*>(p), n); };
    const auto count = static_cast<std::uint32_t>(triangles.size());
    put(&count, 4);  // STL is little-endian, as is every machine tprf targets
    for (const auto& t : triangles) {
        const float normal[3] = {0, 0, 1};
        put(normal, sizeof normal);
        put(t.data(), 9 * sizeof(float));
        const std::uint16_t attributes = 0;
        put(&attributes, 2);
    }
    return out;
}

TEST_F(Mesh, ReadsBinaryStlAndCountsCollapsedTriangles) {
    // The third triangle has two equal corners: dropped and counted.
    const auto file = write("square.stl", binary_stl({{0, 0, 0, 1, 0, 0, 1, 1, 0},
                                                      {0, 0, 0, 1, 1, 0, 0, 1, 0},
                                                      {0, 0, 0, 1, 0, 0, 1, 0, 0}}));
    const auto mesh = tprf::load_mesh(file, scale_rotate_translate(), "scene.json", "objects[0].file");
    EXPECT_EQ(mesh.repairs.zero_area_faces, 1u);
    tprf::PolygonMesh kept = mesh;
    kept.repairs = {};
    expect_transformed_square(kept);
}

// Valid square plus a collinear (zero-area) triangle and a triangle with a repeated vertex.
TEST_F(Mesh, DropsAndCountsDegenerateFacesInEveryFormat) {
    const std::string obj = std::string(kSquareObj) + "v 2 0 0\nf 1 2 5\nf 1 2 2\n";
    const std::string off =
        "OFF\n5 4 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n3 0 1 2\n3 0 2 3\n3 0 1 4\n3 0 1 1\n";
    const std::string ply =
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n3 0 1 2\n3 0 2 3\n3 0 1 4\n3 0 1 1\n";
    const std::string stl =
        std::string(kSquareStl, std::string_view(kSquareStl).rfind("endsolid")) +
        "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 2 0 0\nendloop\nendfacet\n"
        "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 0 0\nendloop\nendfacet\n"
        "endsolid square\n";
    const std::pair<const char*, std::string> files[] = {{"d.obj", obj}, {"d.off", off}, {"d.ply", ply},
                                                         {"d.stl", stl}};
    for (const auto& [name, text] : files) {
        SCOPED_TRACE(name);
        const auto mesh = tprf::load_mesh(write(name, text), Eigen::Matrix4d::Identity(), "scene.json",
                                          "objects[0].file");
        EXPECT_EQ(mesh.faces(), 2u);
        EXPECT_EQ(mesh.repairs.zero_area_faces, 2u);
        EXPECT_NEAR(total_area(mesh), 1.0, 1e-12);
        // Only vertices of kept faces remain (vertex 5 belonged to the collinear triangle alone).
        EXPECT_EQ(mesh.vertices.size(), 4u);
        EXPECT_EQ(mesh.repairs.unreferenced_vertices, 1u);
        EXPECT_EQ(tprf::describe(mesh.repairs), "2 zero-area faces and 1 unreferenced vertex");
    }
}

TEST_F(Mesh, DropsFacesWithCoincidentPositions) {
    // Vertices 2 and 5 are distinct indices at the same position: the quad 1 2 5 3 is degenerate.
    const auto file = write("c.obj", std::string(kSquareObj) + "v 1 0 0\nf 1 2 5 3\n");
    const auto mesh = tprf::load_mesh(file, Eigen::Matrix4d::Identity(), "scene.json", "objects[0].file");
    EXPECT_EQ(mesh.faces(), 2u);
    EXPECT_EQ(mesh.repairs.zero_area_faces, 1u);
}

TEST_F(Mesh, MirroringTransformKeepsTheFrontSide) {
    Eigen::Matrix4d mirror = Eigen::Matrix4d::Identity();
    mirror(0, 0) = -1.0;
    const auto mesh =
        tprf::load_mesh(write("square.obj", kSquareObj), mirror, "scene.json", "objects[0].file");
    // The file's front faces +z; a mirror in x leaves that direction alone, so the front must too.
    for (std::size_t f = 0; f < mesh.faces(); ++f)
        EXPECT_NEAR(face_normal(mesh, f).z(), 1.0, 1e-12);
}

TEST_F(Mesh, KeepsPolygonsWhole) {
    const auto mesh = tprf::load_mesh(write("quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"),
                                      Eigen::Matrix4d::Identity(), "scene.json", "objects[0].file");
    ASSERT_EQ(mesh.faces(), 1u);
    EXPECT_EQ(mesh.face(0).size(), 4u);
    EXPECT_NEAR(total_area(mesh), 1.0, 1e-12);
}

TEST_F(Mesh, SampleTetrahedraAgreeAcrossFormats) {
    // meshes/tetra.*: a regular tetrahedron of circumradius 1, edge sqrt(8/3), outward faces.
    const double edge = std::sqrt(8.0 / 3.0);
    const double area = 4.0 * std::sqrt(3.0) / 4.0 * edge * edge;
    for (const char* name : {"tetra.obj", "tetra.ply", "tetra.off", "tetra.stl"}) {
        SCOPED_TRACE(name);
        const auto mesh = tprf::load_mesh(fs::path(TPRF_SOURCE_DIR) / "meshes" / name,
                                          Eigen::Matrix4d::Identity(), "scene.json", "objects[0].file");
        EXPECT_EQ(mesh.vertices.size(), 4u);
        ASSERT_EQ(mesh.faces(), 4u);
        // The files store 6 decimals (float precision for STL): 1e-5 relative covers both.
        EXPECT_NEAR(total_area(mesh), area, 1e-5 * area);
        Vec3 centre = Vec3::Zero();
        for (const Vec3& v : mesh.vertices) centre += v / 4.0;
        for (std::size_t f = 0; f < mesh.faces(); ++f)
            EXPECT_GT(face_normal(mesh, f).dot(mesh.vertices[mesh.face(f)[0]] - centre), 0.0);
    }
}

TEST_F(Mesh, SampleIcosphereIsClosedAndOutward) {
    const auto mesh = tprf::load_mesh(fs::path(TPRF_SOURCE_DIR) / "meshes" / "icosphere.obj",
                                      Eigen::Matrix4d::Identity(), "scene.json", "objects[0].file");
    // Two subdivisions of the icosahedron: 20 * 4^2 faces, 10 * 4^2 + 2 vertices.
    EXPECT_EQ(mesh.faces(), 320u);
    ASSERT_EQ(mesh.vertices.size(), 162u);
    for (const Vec3& v : mesh.vertices) EXPECT_NEAR(v.norm(), 1.0, 1e-6);  // 6 decimals in the file
    // Closed and consistently wound: every directed edge occurs once, and its reverse once.
    std::map<std::pair<int, int>, int> edges;
    for (std::size_t f = 0; f < mesh.faces(); ++f) {
        const auto face = mesh.face(f);
        for (std::size_t i = 0; i < face.size(); ++i) ++edges[{face[i], face[(i + 1) % face.size()]}];
        EXPECT_GT(face_normal(mesh, f).dot(mesh.vertices[face[0]]), 0.0) << "face " << f;
    }
    for (const auto& [edge, count] : edges) {
        EXPECT_EQ(count, 1);
        EXPECT_EQ(edges.count({edge.second, edge.first}), 1u);
    }
}

TEST_F(Mesh, MissingFileNamesTheJsonPath) {
    expect_input_error(m_dir / "nowhere.obj", "does not exist");
}

TEST_F(Mesh, DirectoryInPlaceOfTheFileNamesTheJsonPath) {
    const fs::path dir = m_dir / "folder.obj";
    fs::create_directory(dir);
    expect_input_error(dir, "mesh file '" + dir.string() + "' is not a regular file");
}

TEST_F(Mesh, FifoInPlaceOfTheFileIsRefusedWithoutWaitingForAWriter) {
    // Opening a FIFO for reading blocks until someone writes: the file is refused before it is opened.
    const fs::path fifo = m_dir / "pipe.obj";
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    expect_input_error(fifo, "mesh file '" + fifo.string() + "' is not a regular file");
}

TEST_F(Mesh, AFaceOfThreeHundredCornersIsKeptWhole) {
    // A regular 300-gon of circumradius 1: area (n / 2) sin(2 pi / n).
    const int n = 300;
    std::ostringstream obj;  // (GCC 12 warns falsely, -Wrestrict, on "literal" + std::string here)
    obj.precision(17);
    for (int k = 0; k < n; ++k) obj << "v " << std::cos(2 * M_PI * k / n) << ' ' << std::sin(2 * M_PI * k / n) << " 0\n";
    obj << 'f';
    for (int k = 1; k <= n; ++k) obj << ' ' << k;
    obj << '\n';
    const auto mesh = tprf::load_mesh(write("polygon.obj", obj.str()), Eigen::Matrix4d::Identity(), "scene.json",
                                      "objects[0].file");
    ASSERT_EQ(mesh.faces(), 1u);
    EXPECT_EQ(mesh.face(0).size(), std::size_t(n));
    const double area = 0.5 * n * std::sin(2 * M_PI / n);
    EXPECT_NEAR(total_area(mesh), area, 1e-12 * area);
}

TEST_F(Mesh, NonManifoldEdgesAreKept) {
    // Three triangles on one edge (a fin, as scans and CAD exports hold): each is a surface of its own.
    const auto mesh = tprf::load_mesh(write("fins.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\n"
                                                         "f 1 2 3\nf 1 2 4\nf 1 2 5\n"),
                                      Eigen::Matrix4d::Identity(), "scene.json", "objects[0].file");
    EXPECT_EQ(mesh.faces(), 3u);
    EXPECT_NEAR(total_area(mesh), 1.5, 1e-12);
}

TEST_F(Mesh, UnreadableFileNamesTheJsonPath) {
    // File permissions do not stop root (CI runs as root), but Linux sysctl files are checked by their
    // own mode bits for root too: /proc/sys/vm/drop_caches (mode 0200) is a regular file that no one
    // may read. A link to it stands for a mesh file that exists and cannot be opened.
    const fs::path sysctl = "/proc/sys/vm/drop_caches";
    if (!fs::is_regular_file(sysctl) || std::ifstream(sysctl))
        GTEST_SKIP() << sysctl << " is absent or readable here: no unreadable regular file to point at";
    const fs::path link = m_dir / "locked.obj";
    fs::create_symlink(sysctl, link);
    expect_input_error(link, "mesh file '" + link.string() + "' cannot be opened");
}

TEST_F(Mesh, GarbageNamesTheJsonPath) {
    expect_input_error(write("garbage.ply", "this is not a mesh\n"), "line 1: not a PLY file");
    // OBJ skips statements it does not know, as the format asks: nothing is left.
    expect_input_error(write("garbage.obj", "this is not a mesh\n"), "has no vertices and no faces");
    expect_input_error(write("garbage.xyz", "1 2 3\n"), "unknown mesh format");
}

TEST_F(Mesh, FaceIndexOutOfRangeIsAnError) {
    expect_input_error(write("bad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n"), "vertex 9");
}

TEST_F(Mesh, OffWithCommentsBlankLinesAndCountsOnTheHeaderLineLoads) {
    // What tools write (issue 19): comments before the header, between and inside the sections, blank
    // lines, and the counts on the header line. A unit square as two triangles.
    const std::string off = "# written by some tool\n\nOFF 4 2 0   # vertices faces edges\n# the corners\n"
                            "0 0 0\n1 0 0 # trailing comment\n\n1 1 0\n0 1 0\n# the faces\n3 0 1 2\n3 0 2 3\n";
    const auto mesh = tprf::load_mesh(write("commented.off", off), Eigen::Matrix4d::Identity(), "scene.json",
                                      "objects[0].file");
    EXPECT_EQ(mesh.vertices.size(), 4u);
    ASSERT_EQ(mesh.faces(), 2u);
    EXPECT_FALSE(mesh.repairs.any());
    for (const auto& face : faces_of(mesh)) EXPECT_EQ(face.size(), 3u);
}

TEST_F(Mesh, PointCloudsAreNamedAsSuch) {
    // Vertices and no faces: PLY and OFF declare 0 faces, OBJ has no f lines.
    expect_input_error(write("cloud.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                          "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n"),
                       "has 3 vertices and no faces: a point cloud, not a surface");
    expect_input_error(write("cloud.off", "OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"),
                       "has 4 vertices and no faces: a point cloud");
    expect_input_error(write("cloud.obj", "v 0 0 0\nv 1 0 0\n"), "has 2 vertices and no faces: a point cloud");
}

TEST_F(Mesh, AllDegenerateIsEmpty) {
    expect_input_error(write("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 2 2\n"),
                       "empty: no faces left after dropping 2 zero-area faces and 3 unreferenced vertices");
}

}  // namespace
