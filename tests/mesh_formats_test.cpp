// The variants of OFF, OBJ, PLY and STL that tools write, and every way a file can be wrong (issue 19):
// each test asserts the faces that must come out (counted, and their area where the geometry fixes it)
// or the place and words of the error.
#include "mesh_files.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace {

using tprf::Vec3;
using tprf::test::expect_input_error;
using MeshFormats = tprf::test::MeshFiles;

double area(const tprf::PolygonMesh& mesh) {
    double a = 0.0;
    for (std::size_t f = 0; f < mesh.faces(); ++f) {
        const auto face = mesh.face(f);
        Vec3 n = Vec3::Zero();
        for (std::size_t i = 0; i < face.size(); ++i)
            n += mesh.vertices[face[i]].cross(mesh.vertices[face[(i + 1) % face.size()]]);
        a += 0.5 * n.norm();
    }
    return a;
}

// The unit square's two triangles: 4 vertices, 2 faces, area 1 (exact: small integers).
void expect_square(const tprf::PolygonMesh& mesh) {
    EXPECT_EQ(mesh.vertices.size(), 4u);
    EXPECT_EQ(mesh.faces(), 2u);
    EXPECT_DOUBLE_EQ(area(mesh), 1.0);
    EXPECT_FALSE(mesh.repairs.any()) << tprf::describe(mesh.repairs);
}

// ---- OFF ----

TEST_F(MeshFormats, OffHeaderVariantsWithTheirExtraColumns) {
    const std::string faces = "3 0 1 2\n3 0 2 3\n";
    // Each keyword with the columns it adds after x y z: colour (3 or 4), normal, texture coordinates.
    const std::pair<std::string, std::string> variants[] = {
        {"OFF", "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"},
        {"COFF", "0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n"},
        {"NOFF", "0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n"},
        {"CNOFF", "0 0 0 0 0 1 1 0 0\n1 0 0 0 0 1 0 1 0\n1 1 0 0 0 1 0 0 1\n0 1 0 0 0 1 1 1 1\n"},
        {"STOFF", "0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n"},
        {"STCNOFF", "0 0 0 0 0 1 0 0 1 0 0 0\n1 0 0 0 0 1 0 1 0 1 0 0\n1 1 0 0 0 1 0 0 1 1 1 0\n"
                    "0 1 0 0 0 1 1 1 1 0 1 0\n"},
        // Homogeneous: (x, y, z, w) is the point (x, y, z) / w.
        {"4OFF", "0 0 0 2\n2 0 0 2\n3 3 0 3\n0 0.5 0 0.5\n"},
        // nOFF: the dimension comes first; 3 here.
        {"nOFF\n3", "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"},
    };
    for (const auto& [keyword, vertices] : variants) {
        SCOPED_TRACE(keyword);
        expect_square(load("v.off", keyword + "\n4 2 0\n" + vertices + faces));
    }
}

TEST_F(MeshFormats, OffFaceColoursPolygonsAndNoKeyword) {
    // Per-face colours after the indices (integers or floats), a pentagon, and no "OFF" keyword at all
    // (Geomview allows it): the counts alone start the file.
    const auto mesh = load("p.off", "5 2\n0 0 0\n2 0 0\n2 1 0\n1 2 0\n0 1 0\n"
                                    "5 0 1 2 3 4 255 0 0\n3 0 1 2 0.5 0.5 0.5 1.0\n");
    ASSERT_EQ(mesh.faces(), 2u);
    EXPECT_EQ(mesh.face(0).size(), 5u);
    EXPECT_DOUBLE_EQ(area(mesh), 3.0 + 1.0);  // pentagon 2 + 1/2 + 1/2 by the shoelace, triangle 1
}

TEST_F(MeshFormats, OffCountsOnTheNextLineAfterComments) {
    // No space between the keyword and the counts, as some writers leave it out.
    expect_square(load("glued.off", "OFF4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"));
    expect_square(load("c.off", "OFF # the header\n# counts follow\n\n  4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
                                "3 0 1 2 # first\n3 0 2 3\n# trailing comment\n"));
    // CRLF line ends, as Windows tools write them.
    expect_square(load("crlf.off", "OFF\r\n4 2 0\r\n0 0 0\r\n1 0 0\r\n1 1 0\r\n0 1 0\r\n3 0 1 2\r\n3 0 2 3\r\n"));
}

TEST_F(MeshFormats, OffErrorsNameTheLine) {
    const std::string head = "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n";
    expect_input_error(write("range.off", head + "3 0 1 2\n3 0 2 9\n"),
                       "line 8: face 2 refers to vertex 9, but the file has 4 vertices (OFF counts from 0)");
    expect_input_error(write("short.off", head + "3 0 1 2\n"),
                       "the file ends before face 2 of the 2 that the header declares");
    expect_input_error(write("few.off", "OFF\n4 2 0\n0 0 0\n1 0\n"), "line 4: a vertex needs 3 numbers, the line has 2");
    expect_input_error(write("word.off", "OFF\n4 2 0\n0 0 0\n1 zero 0\n"), "line 4: 'zero' is not a number");
    expect_input_error(write("nan.off", "OFF\n4 2 0\n0 0 0\n1 0 0\nnan 1 0\n"),
                       "line 5: vertex 3 has a coordinate that is not a finite number");
    expect_input_error(write("inf.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 inf 0\n"),
                       "line 5: vertex 3 has a coordinate that is not a finite number");
    expect_input_error(write("corners.off", head + "4 0 1 2\n"), "line 7: face 1 declares 4 corners but lists 3");
    expect_input_error(write("neg.off", head + "3 0 -1 2\n"), "line 7: face 1 refers to vertex -1");
    expect_input_error(write("text.off", "hello world\n"),
                       "line 1: the file starts with 'hello', which is neither an OFF keyword");
    expect_input_error(write("nohead.off", "# only a comment\n"), "the file ends before the header gives");
}

TEST_F(MeshFormats, BinaryOffGoesThroughOpenMesh) {
    // OpenMesh's layout: "OFF BINARY", then little-endian int32 counts, float32 corners, and per face
    // its corner count and indices.
    std::string off = "OFF BINARY\n";
    const auto put = [&](auto v) { off.append(reinterpret_cast<const char*>(&v), sizeof v); };
    for (std::int32_t n : {4, 2, 0}) put(n);
    for (float c : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f, 0.f, 1.f, 0.f}) put(c);
    for (std::int32_t i : {3, 0, 1, 2, 3, 0, 2, 3}) put(i);
    expect_square(load("binary.off", off));
}

// ---- OBJ ----

TEST_F(MeshFormats, ObjVertexExtrasFaceFormsAndIgnoredStatements) {
    // A 4th coordinate (a weight) and vertex colours; every face form; negative indices; the statements
    // tprf does not need, a missing material library among them; two objects in one file.
    const std::string obj = "mtllib does_not_exist.mtl\no first\ng walls\ns 1\nusemtl red\n"
                            "v 0 0 0 1\nv 1 0 0 1.0 0.5 0.2 0.1\nv 1 1 0\nv 0 1 0 0.3 0.3 0.3\n"
                            "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n"
                            "f 1/1 2/2 3/3\nf 1//1 3//1 4//1\nl 1 2\np 3\n"
                            "o second\nv 0 0 1\nv 1 0 1\nv 1 1 1\nf -3/1/1 -2/2/1 -1/3/1\n"
                            "f 5 7 \\\n 8\nv 0 1 1\n";
    const auto mesh = load("m.obj", obj);
    EXPECT_EQ(mesh.faces(), 4u);
    EXPECT_EQ(mesh.vertices.size(), 8u);
    EXPECT_DOUBLE_EQ(area(mesh), 2.0);  // the unit square at z = 0 and again at z = 1
    EXPECT_FALSE(mesh.repairs.any()) << tprf::describe(mesh.repairs);
}

TEST_F(MeshFormats, ObjErrorsNameTheLine) {
    const std::string v = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
    expect_input_error(write("zero.obj", v + "f 0 1 2\n"),
                       "line 5: face 1 refers to vertex 0, but OBJ counts vertices from 1");
    // A vertex defined after the face that uses it is legal; one defined nowhere is not.
    expect_input_error(write("range.obj", v + "f 1 2 3\nf 1 3 9\nv 2 2 0\n"),
                       "line 6: face 2 refers to vertex 9, but the file has 5 vertices");
    expect_input_error(write("back.obj", v + "f -1 -2 -7\n"),
                       "line 5: face 1 refers to vertex -7 (relative), but only 4 vertices are defined before it");
    expect_input_error(write("nan.obj", "v 0 0 0\nv 1 NaN 0\n"),
                       "line 2: vertex 2 has a coordinate that is not a finite number");
    expect_input_error(write("short.obj", "v 0 0\n"), "line 1: a vertex needs 3 coordinates, the line has 2");
    expect_input_error(write("word.obj", v + "f 1 two 3\n"), "line 5: 'two' is not a whole number");
    expect_input_error(write("huge.obj", "v 1e999 0 0\n"), "line 1: '1e999' is out of the range of a double");
}

TEST_F(MeshFormats, ForwardReferencesResolveAtTheEnd) {
    expect_square(load("fwd.obj", "f 1 2 3\nf 1 3 4\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"));
}

// ---- STL ----

// A binary STL with the given 80-byte header text.
std::string binary_stl(const std::string& header, const std::vector<std::array<float, 9>>& triangles) {
    std::string out = header;
    out.resize(80, ' ');
    auto put32 = [&](std::uint32_t v) {
        for (int b = 0; b < 4; ++b) out.push_back(static_cast<char>((v >> (8 * b)) & 0xFF));
    };
    put32(static_cast<std::uint32_t>(triangles.size()));
    for (const auto& t : triangles) {
        for (float n : {0.0f, 0.0f, 1.0f}) put32(std::bit_cast<std::uint32_t>(n));
        for (float c : t) put32(std::bit_cast<std::uint32_t>(c));
        out.append(2, '\0');  // attribute byte count
    }
    return out;
}

const std::vector<std::array<float, 9>> kSquareTriangles = {{0, 0, 0, 1, 0, 0, 1, 1, 0}, {0, 0, 0, 1, 1, 0, 0, 1, 0}};

TEST_F(MeshFormats, BinaryStlWhoseHeaderStartsWithSolid) {
    // The classic trap: "solid" in a binary header. The size (84 + 50 n) decides; corners are merged.
    expect_square(load("solid.stl", binary_stl("solid exported by a CAD tool", kSquareTriangles)));
}

TEST_F(MeshFormats, BinaryStlErrorsNameTheByte) {
    std::string cut = binary_stl("", kSquareTriangles);
    cut.resize(84 + 50 + 20);
    expect_input_error(write("cut.stl", cut),
                       "byte 154: the file ends inside triangle 2 of the 2 that its header (bytes 80-83) declares");
    std::vector<std::array<float, 9>> nan = kSquareTriangles;
    nan[1][4] = std::numeric_limits<float>::quiet_NaN();  // triangle 2, corner 2, y
    // Triangle 2 starts at byte 134; its second corner at 134 + 12 (normal) + 12.
    expect_input_error(write("nan.stl", binary_stl("", nan)),
                       "byte 158: vertex 5 has a coordinate that is not a finite number");
    expect_input_error(write("tiny.stl", "abc"), "byte 0: neither an ASCII STL");
}

TEST_F(MeshFormats, AsciiStlWithSeveralSolids) {
    const std::string facet0 = "facet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 1 1 0\n"
                               " endloop\nendfacet\n";
    const std::string facet1 = "facet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 1 0\n  vertex 0 1 0\n"
                               " endloop\nendfacet\n";
    expect_square(load("two.stl", "solid a b c\n" + facet0 + "endsolid a b c\nsolid\n" + facet1 + "endsolid\n"));
    expect_input_error(write("bad.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertec 1 0 0\n"),
                       "line 5: 'vertec' is not an STL keyword");
    expect_input_error(write("open.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"),
                       "the file ends inside a facet");
}

// ---- PLY ----

// A value's bytes in the given byte order.
template <class T>
void put(std::string& out, T value, bool big_endian) {
    std::array<char, sizeof(T)> bytes;
    std::memcpy(bytes.data(), &value, sizeof(T));
    if (big_endian) std::reverse(bytes.begin(), bytes.end());
    out.append(bytes.data(), bytes.size());
}

// The unit square in binary PLY with colours, normals and a quality among the coordinates (mixed
// types), the list under the name `vertex_index` with a ushort count and uint indices after a texture
// coordinate list, and a material element before the vertices and an edge element after the faces.
std::string binary_square_ply(bool big_endian) {
    std::string s = std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
                    " 1.0\ncomment made by a test\nelement material 1\nproperty uchar red\nproperty float shine\n"
                    "element vertex 4\nproperty uchar red\nproperty double x\nproperty float nx\nproperty float y\n"
                    "property float quality\nproperty double z\nproperty ushort flags\n"
                    "element face 2\nproperty list uchar float texcoord\nproperty list ushort uint vertex_index\n"
                    "property int group\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
    put<std::uint8_t>(s, 7, big_endian);
    put<float>(s, 0.5f, big_endian);
    const double xy[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    for (const auto& v : xy) {
        put<std::uint8_t>(s, 200, big_endian);
        put<double>(s, v[0], big_endian);
        put<float>(s, 0.0f, big_endian);
        put<float>(s, float(v[1]), big_endian);
        put<float>(s, 0.9f, big_endian);
        put<double>(s, 0.0, big_endian);
        put<std::uint16_t>(s, 3, big_endian);
    }
    for (const std::array<std::uint32_t, 3>& f : {std::array<std::uint32_t, 3>{0, 1, 2}, {0, 2, 3}}) {
        put<std::uint8_t>(s, 2, big_endian);
        put<float>(s, 0.25f, big_endian);
        put<float>(s, 0.75f, big_endian);
        put<std::uint16_t>(s, 3, big_endian);
        for (std::uint32_t i : f) put<std::uint32_t>(s, i, big_endian);
        put<std::int32_t>(s, -1, big_endian);
    }
    put<std::int32_t>(s, 0, big_endian);
    put<std::int32_t>(s, 1, big_endian);
    return s;
}

TEST_F(MeshFormats, BinaryPlyEitherEndianWithExtraPropertiesAndElements) {
    expect_square(load("le.ply", binary_square_ply(false)));
    expect_square(load("be.ply", binary_square_ply(true)));
}

TEST_F(MeshFormats, AsciiPlyWithExtraPropertiesAndElements) {
    // Properties in a writer's order (normals and colours first), int coordinates, a record spread over
    // lines, values after a record on its line (ignored: MeshLab writes them), an edge element between
    // vertices and faces, CRLF line ends.
    const std::string ply = "ply\r\nformat ascii 1.0\r\ncomment x\r\nobj_info y\r\nelement vertex 4\r\n"
                            "property float nx\r\nproperty float ny\r\nproperty float nz\r\nproperty int x\r\n"
                            "property uchar red\r\nproperty int y\r\nproperty int z\r\nelement edge 1\r\n"
                            "property int vertex1\r\nproperty int vertex2\r\nelement face 2\r\n"
                            "property list int int vertex_indices\r\nproperty float quality\r\nend_header\r\n"
                            "0 0 1 0 255 0 0\r\n0 0 1 1 255\r\n 0 0\r\n0 0 1 1 255 1 0  9 9 9\r\n0 0 1 0 255 1 0\r\n"
                            "0 1\r\n3 0 1 2 0.5 6 1 1 1 1 1 1\r\n3 0 2 3 0.5\r\n";
    expect_square(load("a.ply", ply));
}

TEST_F(MeshFormats, PlyErrorsNameTheLineOrByte) {
    const std::string head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                             "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    expect_input_error(write("range.ply", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"),
                       "line 13: face 1 refers to vertex 3, but the file has 3 vertices (PLY counts from 0)");
    expect_input_error(write("short.ply", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1\n"),
                       "the file ends inside face 1 of 1");
    expect_input_error(write("nan.ply", head + "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n"),
                       "line 11: vertex 2 has a coordinate that is not a finite number");
    expect_input_error(write("format.ply", "ply\nformat binary_middle_endian 1.0\n"),
                       "line 2: 'binary_middle_endian' is not a PLY format");
    expect_input_error(write("noz.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                        "property float y\nend_header\n0 0\n"),
                       "line 3: the vertex element has no property 'z'");
    expect_input_error(write("nolist.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                           "property float y\nproperty float z\nelement face 1\nproperty int a\n"
                                           "end_header\n0 0 0\n1\n"),
                       "line 7: the face element has no 'vertex_indices' (or 'vertex_index') list");
    expect_input_error(write("noend.ply", "ply\nformat ascii 1.0\nelement vertex 1\n"),
                       "the file ends before the header's 'end_header' line");
    // Binary: the byte of the bad index. After the header: the material (5 bytes), 4 vertices of 31 bytes; the first
    // face starts with 9 bytes of texture list, a 2-byte count, then indices of 4 bytes.
    std::string bad = binary_square_ply(false);
    const std::size_t header = bad.find("end_header\n") + 11, first_index = header + 5 + 4 * 31 + 9 + 2;
    bad[first_index + 4] = 9;  // the second corner of face 1: vertex 9 of 4
    expect_input_error(write("bad.ply", bad), "byte " + std::to_string(first_index + 4) +
                                                  ": face 1 refers to vertex 9, but the file has 4 vertices");
    bad = binary_square_ply(false);
    bad.resize(header + 30);
    expect_input_error(write("cut.ply", bad), "byte " + std::to_string(header + 30) + ": the file ends inside vertex 1 of 4");
}

// ---- Repairs ----

TEST_F(MeshFormats, DuplicateFacesAndUnreferencedVerticesAreCounted) {
    // Faces 3 and 4 repeat face 1: the same corners in a rotated order, and the same positions under
    // other indices (5-7). Face 5 is face 1 reversed: the back of a sheet, kept. Vertex 8 is used by
    // no face.
    const std::string obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 5 5 5\n"
                            "f 1 2 3\nf 1 3 4\nf 2 3 1\nf 5 6 7\nf 3 2 1\n";
    const auto mesh = load("dup.obj", obj);
    EXPECT_EQ(mesh.faces(), 3u);
    EXPECT_EQ(mesh.repairs.duplicate_faces, 2u);
    EXPECT_EQ(mesh.repairs.zero_area_faces, 0u);
    // Vertices 5-7 were used only by the dropped duplicate; vertex 8 by nothing.
    EXPECT_EQ(mesh.repairs.unreferenced_vertices, 4u);
    EXPECT_EQ(tprf::describe(mesh.repairs), "2 duplicate faces and 4 unreferenced vertices");
    EXPECT_DOUBLE_EQ(area(mesh), 1.5);
}

TEST_F(MeshFormats, SizesOutsideWhatTprfComputesWithAreRefused) {
    // 1e-300 m and 1e300 m: a triangle's area would underflow to 0 or overflow to infinity.
    expect_input_error(write("tiny.obj", "v 0 0 0\nv 1e-300 0 0\nv 0 1e-300 0\nf 1 2 3\n"),
                       "spans 1.41e-300 m after the transform, outside the 1e-9 m to 1e9 m");
    expect_input_error(write("huge.obj", "v 0 0 0\nv 1e300 0 0\nv 0 1e300 0\nf 1 2 3\n"),
                       "spans 1.41e+300 m after the transform");
    // A transform can overflow what the file holds within range.
    Eigen::Matrix4d scale = Eigen::Matrix4d::Identity() * 1e300;
    scale(3, 3) = 1.0;
    const auto file = write("ok.obj", "v 0 0 0\nv 1e10 0 0\nv 0 1e10 0\nf 1 2 3\n");
    EXPECT_THROW(tprf::load_mesh(file, scale, "scene.json", "objects[0].file"), tprf::Error);
    // All corners at one point: nothing spans, every face has no area.
    expect_input_error(write("point.obj", "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n"), "is empty: no faces left");
}

TEST_F(MeshFormats, EmptyFilesSayWhatIsMissing) {
    expect_input_error(write("empty.obj", ""), "has no vertices and no faces");
    expect_input_error(write("cloud.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nv 2 2 2\n"),
                       "has 5 vertices and no faces: a point cloud, not a surface");
    expect_input_error(write("wire.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3 1\n"),
                       "has 3 vertices and 2 lines but no faces: a wireframe, not a surface");
}

}  // namespace
