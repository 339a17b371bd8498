// ASCII OFF as tools write it (Geomview's format, with the habits of the writers that followed):
// '#' comments anywhere, blank lines, the counts on the keyword's line or the next, the keyword
// optional, its prefixes ST (texture coordinates), C (colours), N (normals), 4 (homogeneous) and n (a
// dimension of its own), and per-face colours after the indices. One vertex or face per line.

#include "mesh_readers.h"

#include <algorithm>
#include <array>
#include <limits>

namespace tprf::mesh_read {
namespace {

// What the keyword says about a vertex line: `dims` coordinates (then the extra columns of the
// prefixes, which are not needed), the last one a homogeneous weight when `homogeneous`.
struct OffLayout {
    long long dims = 3;
    bool homogeneous = false;
    bool dims_follow = false;  // nOFF: the dimension is the next number after the keyword
};

// The keyword's layout, or nothing when `word` is not an OFF keyword (then it starts the counts).
bool parse_keyword(std::string_view word, OffLayout& layout) {
    if (!word.ends_with("OFF")) return false;
    word.remove_suffix(3);
    for (std::string_view prefix : {"ST", "C", "N", "4", "n"})
        if (word.starts_with(prefix)) {
            word.remove_prefix(prefix.size());
            if (prefix == "4") layout.homogeneous = true;
            if (prefix == "n") layout.dims_follow = true;
        }
    return word.empty();
}

// The numbers of the header after the keyword: [dimension] vertices faces [edges], on as many lines
// as the writer chose.
struct OffHeader {
    OffLayout layout;
    std::size_t vertices = 0, faces = 0;
};

OffHeader read_header(Lines& lines) {
    OffHeader h;
    std::string_view line;
    std::vector<long long> numbers;
    bool keyword_seen = false;
    const auto wanted = [&] { return h.layout.dims_follow ? 3u : 2u; };
    while (numbers.size() < wanted() && lines.next(line, '#')) {
        std::string_view rest = line;
        for (std::string_view token = next_token(rest); !token.empty(); token = next_token(rest)) {
            if (const std::size_t off = token.find("OFF"); !keyword_seen && numbers.empty() &&
                                                         off != token.npos &&
                                                         parse_keyword(token.substr(0, off + 3), h.layout)) {
                keyword_seen = true;
                token.remove_prefix(off + 3);  // "OFF8 6 12": some writers leave out the space
                if (token.empty()) continue;
            }
            if (numbers.size() == wanted() + 1) break;  // the edge count, which nothing needs
            if (!keyword_seen && numbers.empty() && token.find_first_not_of("+0123456789") != token.npos)
                throw MeshFileError(lines.here().str() + ": the file starts with " + quoted(token) +
                                    ", which is neither an OFF keyword (OFF, COFF, NOFF, ...) nor a vertex count");
            numbers.push_back(to_integer(token, lines.here()));
        }
    }
    if (numbers.size() < wanted())
        throw MeshFileError(lines.here().str() + ": the file ends before the header gives the vertex and face counts");
    if (h.layout.dims_follow) {
        h.layout.dims = numbers[0];
        numbers.erase(numbers.begin());
    }
    if (h.layout.homogeneous) ++h.layout.dims;
    if (h.layout.dims < 1 || h.layout.dims > 64)
        throw MeshFileError(lines.here().str() + ": a dimension of " + std::to_string(h.layout.dims) + " is not one OFF has");
    for (long long n : numbers)
        if (n < 0) throw MeshFileError(lines.here().str() + ": a negative count in the header");
    if (numbers[0] > std::numeric_limits<int>::max())
        throw MeshFileError(lines.here().str() + ": " + count(std::size_t(numbers[0])) +
                            " vertices are more than tprf reads");
    h.vertices = std::size_t(numbers[0]);
    h.faces = std::size_t(numbers[1]);
    return h;
}

// The next line with something on it; false at the end of the file.
bool next_content(Lines& lines, std::string_view& line) {
    while (lines.next(line, '#'))
        if (line.find_first_not_of(" \t\f\v") != std::string_view::npos) return true;
    return false;
}

[[noreturn]] void fail_early_end(const Lines& lines, std::string_view what, std::size_t i, std::size_t n) {
    throw MeshFileError(lines.here().str() + ": the file ends before " + std::string(what) + " " + count(i + 1) +
                        " of the " + count(n) + " that the header declares");
}

Vec3 read_vertex(std::string_view line, const OffLayout& layout, Where where) {
    std::array<double, 4> c{0.0, 0.0, 0.0, 1.0};
    for (long long k = 0; k < layout.dims; ++k) {
        const std::string_view token = next_token(line);
        if (token.empty())
            throw MeshFileError(where.str() + ": a vertex needs " + std::to_string(layout.dims) + " numbers, the line has " +
                                std::to_string(k));
        const double value = to_double(token, where);
        if (k < 3) c[std::size_t(k)] = value;
        if (layout.homogeneous && k == layout.dims - 1) c[3] = value;
    }
    // A homogeneous point with a weight of zero lies at infinity; check_finite then reports it.
    return Vec3(c[0], c[1], c[2]) / c[3];
}

void read_face(std::string_view line, std::size_t face, RawMesh& mesh, Where where) {
    const long long n = to_integer(next_token(line), where);
    if (n < 0) throw MeshFileError(where.str() + ": face " + count(face + 1) + " has a negative corner count");
    for (long long k = 0; k < n; ++k) {
        const std::string_view token = next_token(line);
        if (token.empty())
            throw MeshFileError(where.str() + ": face " + count(face + 1) + " declares " + std::to_string(n) +
                                " corners but lists " + std::to_string(k));
        const long long v = to_integer(token, where);
        if (v < 0 || std::size_t(v) >= mesh.vertices.size())
            throw MeshFileError(where.str() + ": face " + count(face + 1) + " refers to vertex " + std::to_string(v) +
                                ", but the file has " + count(mesh.vertices.size(), "vertex", "vertices") +
                                " (OFF counts from 0)");
        mesh.indices.push_back(int(v));
    }
    mesh.end_face();  // what follows the indices (a colour) is not needed
}

}  // namespace

bool is_binary_off(std::string_view text) {
    Lines lines(text);
    std::string_view line;
    while (lines.next(line, '#')) {
        std::string_view rest = line;
        const std::string_view first = next_token(rest);
        if (first.empty()) continue;
        OffLayout layout;
        return parse_keyword(first, layout) && next_token(rest) == "BINARY";
    }
    return false;
}

RawMesh read_off(std::string_view text) {
    Lines lines(text);
    const OffHeader h = read_header(lines);
    RawMesh mesh;
    // Each vertex and face takes at least two bytes, so a header cannot make us reserve more than the
    // file could hold.
    mesh.vertices.reserve(std::min(h.vertices, text.size() / 2));
    mesh.first.reserve(std::min(h.faces, text.size() / 2) + 1);
    mesh.indices.reserve(3 * std::min(h.faces, text.size() / 2));
    std::string_view line;
    for (std::size_t i = 0; i < h.vertices; ++i) {
        if (!next_content(lines, line)) fail_early_end(lines, "vertex", i, h.vertices);
        mesh.vertices.push_back(read_vertex(line, h.layout, lines.here()));
        check_finite(mesh.vertices.back(), i, lines.here());
    }
    for (std::size_t f = 0; f < h.faces; ++f) {
        if (!next_content(lines, line)) fail_early_end(lines, "face", f, h.faces);
        read_face(line, f, mesh, lines.here());
    }
    return mesh;
}

}  // namespace tprf::mesh_read
