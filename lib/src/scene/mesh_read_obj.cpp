// Wavefront OBJ: the geometry is its `v` and `f` lines. Everything else (vt, vn, o, g, s, usemtl,
// mtllib, l, p, curves) is skipped: tprf reads no materials from a mesh file, so a missing .mtl is no
// error. A line ending in '\' continues on the next, as the format allows.

#include "mesh_readers.h"

#include <limits>

namespace tprf::mesh_read {
namespace {

// A vertex referred to before it is defined (legal: OBJ indices are global), checked at the end.
struct ForwardReference {
    std::size_t vertex = 0;  // 0-based
    std::size_t face = 0;    // 0-based
    Where where;
};

class ObjReader {
public:
    void statement(std::string_view line, Where where) {
        const std::string_view keyword = next_token(line);
        if (keyword == "v")
            vertex(line, where);
        else if (keyword == "f" || keyword == "fo")  // "fo" is the old name of "f"
            face(line, where);
        else if (keyword == "l")
            ++m_mesh.lines;
    }

    RawMesh finish() {
        if (m_forward.vertex >= m_mesh.vertices.size() && m_forward.where.value > 0) out_of_range(m_forward);
        return std::move(m_mesh);
    }

private:
    void vertex(std::string_view line, Where where) {
        Vec3 p;
        for (int k = 0; k < 3; ++k) {
            const std::string_view token = next_token(line);
            if (token.empty())
                throw MeshFileError(where.str() + ": a vertex needs 3 coordinates, the line has " + std::to_string(k));
            p[k] = to_double(token, where);
        }
        // A 4th number (a weight) or three more (a colour) may follow; neither changes the position.
        check_finite(p, m_mesh.vertices.size(), where);
        if (m_mesh.vertices.size() == std::size_t(std::numeric_limits<int>::max()))
            throw MeshFileError(where.str() + ": more vertices than tprf reads");
        m_mesh.vertices.push_back(p);
    }

    void face(std::string_view line, Where where) {
        const std::size_t f = m_mesh.faces();
        for (std::string_view token = next_token(line); !token.empty(); token = next_token(line)) {
            // v, v/vt, v//vn, v/vt/vn: the position's index comes first.
            const long long i = to_integer(token.substr(0, token.find('/')), where);
            const long long n = static_cast<long long>(m_mesh.vertices.size());
            if (i == 0)
                throw MeshFileError(where.str() + ": face " + count(f + 1) +
                                    " refers to vertex 0, but OBJ counts vertices from 1");
            // Negative indices count back from the last vertex defined so far.
            const long long v = i > 0 ? i - 1 : n + i;
            if (v < 0)
                throw MeshFileError(where.str() + ": face " + count(f + 1) + " refers to vertex " +
                                    std::to_string(i) + " (relative), but only " +
                                    count(m_mesh.vertices.size(), "vertex is", "vertices are") + " defined before it");
            if (v >= n && (std::size_t(v) > m_forward.vertex || m_forward.where.value == 0)) {
                if (v >= std::numeric_limits<int>::max()) out_of_range({std::size_t(v), f, where});
                m_forward = {std::size_t(v), f, where};
            }
            m_mesh.indices.push_back(int(v));
        }
        m_mesh.end_face();
    }

    [[noreturn]] void out_of_range(const ForwardReference& r) const {
        throw MeshFileError(r.where.str() + ": face " + count(r.face + 1) + " refers to vertex " + count(r.vertex + 1) +
                            ", but the file has " + count(m_mesh.vertices.size(), "vertex", "vertices"));
    }

    RawMesh m_mesh;
    ForwardReference m_forward;  // the largest index beyond the vertices defined at its line
};

}  // namespace

RawMesh read_obj(std::string_view text) {
    ObjReader reader;
    Lines lines(text);
    std::string joined;  // a statement continued over lines with '\'
    Where start;
    for (std::string_view line; lines.next(line, '#');) {
        const bool continues = line.ends_with('\\');
        if (continues) line.remove_suffix(1);
        if (continues || !joined.empty()) {
            if (joined.empty()) start = lines.here();
            joined.append(line).push_back(' ');
            if (continues) continue;
            reader.statement(joined, start);
            joined.clear();
            continue;
        }
        reader.statement(line, lines.here());
    }
    if (!joined.empty()) reader.statement(joined, start);
    return reader.finish();
}

}  // namespace tprf::mesh_read
