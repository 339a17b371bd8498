// STL, ASCII and binary. Which one a file is comes from its size: a binary STL of n triangles has
// exactly 84 + 50 n bytes, n being the little-endian count in bytes 80-83. Many binary writers start
// the free 80-byte header with "solid", so the word alone decides nothing; a text file holds no NUL
// byte, which binary floats (0.0) nearly always do. STL repeats each corner per
// triangle; corners at bit-identical positions are merged, so that a mesh's vertices are counted as
// the other formats count them.

#include "mesh_readers.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>

namespace tprf::mesh_read {
namespace {

constexpr std::size_t kHeaderBytes = 84;    // 80 free bytes and the triangle count
constexpr std::size_t kTriangleBytes = 50;  // normal, 3 corners (12 float32), attribute (uint16)

std::uint32_t little_u32(const char* p) {
    std::uint32_t v = 0;
    for (int b = 3; b >= 0; --b) v = (v << 8) | static_cast<unsigned char>(p[b]);
    return v;
}

float little_f32(const char* p) { return std::bit_cast<float>(little_u32(p)); }

// Corners at bit-identical positions become one vertex (an open-addressed hash table of indices).
void merge_corners(RawMesh& mesh) {
    const std::size_t n = mesh.vertices.size();
    std::size_t slots = 16;
    while (slots < 2 * n) slots *= 2;
    std::vector<int> table(slots, -1);
    std::vector<Vec3> unique;
    unique.reserve(n / 4);
    auto bits = [](double x) { return std::bit_cast<std::uint64_t>(x + 0.0); };  // -0 as +0
    for (int& index : mesh.indices) {
        const Vec3& p = mesh.vertices[std::size_t(index)];
        std::uint64_t h = bits(p.x()) * 0x9E3779B97F4A7C15ull;
        h = (h ^ bits(p.y())) * 0xC2B2AE3D27D4EB4Full;
        h = (h ^ bits(p.z())) * 0x165667B19E3779F9ull;
        std::size_t slot = (h ^ (h >> 29)) & (slots - 1);
        while (table[slot] >= 0 && unique[std::size_t(table[slot])] != p) slot = (slot + 1) & (slots - 1);
        if (table[slot] < 0) {
            table[slot] = static_cast<int>(unique.size());
            unique.push_back(p);
        }
        index = table[slot];
    }
    mesh.vertices = std::move(unique);
}

RawMesh read_binary(std::string_view bytes, std::size_t triangles) {
    RawMesh mesh;
    mesh.vertices.reserve(3 * triangles);
    mesh.indices.reserve(3 * triangles);
    mesh.first.reserve(triangles + 1);
    for (std::size_t t = 0; t < triangles; ++t) {
        const std::size_t offset = kHeaderBytes + t * kTriangleBytes;
        const char* corner = bytes.data() + offset + 12;  // past the normal, which is recomputed
        for (int k = 0; k < 3; ++k, corner += 12) {
            const Vec3 p(little_f32(corner), little_f32(corner + 4), little_f32(corner + 8));
            check_finite(p, mesh.vertices.size(), {Where::Byte, std::size_t(corner - bytes.data())});
            mesh.indices.push_back(static_cast<int>(mesh.vertices.size()));
            mesh.vertices.push_back(p);
        }
        mesh.end_face();
    }
    return mesh;
}

// The tokens of an ASCII STL with the line each is on.
class Tokens {
public:
    explicit Tokens(std::string_view text) : m_lines(text) {}
    std::string_view next() {
        for (std::string_view token = next_token(m_rest); ; token = next_token(m_rest)) {
            if (!token.empty()) return token;
            if (!m_lines.next(m_rest, '\0')) return {};
        }
    }
    void skip_line() { m_rest = {}; }  // a solid's name: any words
    Where here() const { return m_lines.here(); }

private:
    Lines m_lines;
    std::string_view m_rest;
};

double number(Tokens& tokens) {
    const std::string_view token = tokens.next();
    if (token.empty()) throw MeshFileError(tokens.here().str() + ": the file ends inside a facet");
    return to_double(token, tokens.here());
}

RawMesh read_ascii(std::string_view text) {
    RawMesh mesh;
    Tokens tokens(text);
    bool in_facet = false;
    for (std::string_view word = tokens.next(); !word.empty(); word = tokens.next()) {
        if (word == "solid" || word == "endsolid") {
            tokens.skip_line();
        } else if (word == "facet") {
            if (in_facet) throw MeshFileError(tokens.here().str() + ": a facet begins before the last one ended");
            in_facet = true;
            if (tokens.next() != "normal")
                throw MeshFileError(tokens.here().str() + ": 'facet' must be followed by 'normal' and 3 numbers");
            for (int k = 0; k < 3; ++k) number(tokens);
        } else if (word == "vertex") {
            if (!in_facet) throw MeshFileError(tokens.here().str() + ": a vertex outside a facet");
            Vec3 p;
            for (int k = 0; k < 3; ++k) p[k] = number(tokens);
            check_finite(p, mesh.vertices.size(), tokens.here());
            mesh.indices.push_back(static_cast<int>(mesh.vertices.size()));
            mesh.vertices.push_back(p);
        } else if (word == "endfacet") {
            if (!in_facet) throw MeshFileError(tokens.here().str() + ": 'endfacet' without a facet");
            in_facet = false;
            mesh.end_face();
        } else if (word != "outer" && word != "loop" && word != "endloop") {
            throw MeshFileError(tokens.here().str() + ": " + quoted(word) +
                                " is not an STL keyword (solid, facet normal, outer loop, vertex, endloop, "
                                "endfacet, endsolid)");
        }
    }
    if (in_facet) throw MeshFileError(tokens.here().str() + ": the file ends inside a facet");
    return mesh;
}

bool starts_with_solid(std::string_view bytes) {
    const std::size_t begin = bytes.find_first_not_of(" \t\r\n");
    return begin != std::string_view::npos && bytes.substr(begin).starts_with("solid");
}

}  // namespace

RawMesh read_stl(std::string_view bytes) {
    const std::size_t triangles = bytes.size() >= kHeaderBytes ? little_u32(bytes.data() + 80) : 0;
    const std::size_t binary_size = kHeaderBytes + kTriangleBytes * triangles;
    RawMesh mesh;
    if (bytes.size() >= kHeaderBytes && bytes.size() == binary_size) {
        mesh = read_binary(bytes, triangles);
    } else if (starts_with_solid(bytes) && bytes.find('\0') == std::string_view::npos) {
        mesh = read_ascii(bytes);
    } else if (bytes.size() < kHeaderBytes) {
        throw MeshFileError(at_byte(0) + ": neither an ASCII STL (which starts with 'solid') nor a binary one "
                            "(which has an 84-byte header), the file has " + count(bytes.size(), "byte", "bytes"));
    } else if (bytes.size() < binary_size) {
        throw MeshFileError(at_byte(bytes.size()) + ": the file ends inside triangle " +
                            count((bytes.size() - kHeaderBytes) / kTriangleBytes + 1) + " of the " + count(triangles) +
                            " that its header (bytes 80-83) declares; a binary STL of that many triangles has " +
                            count(binary_size, "byte", "bytes"));
    } else {
        // Longer than the triangles need: some writers pad; what follows them is not geometry.
        mesh = read_binary(bytes, triangles);
    }
    merge_corners(mesh);
    return mesh;
}

}  // namespace tprf::mesh_read
