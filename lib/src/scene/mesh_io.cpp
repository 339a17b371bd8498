// GCC 12 under the sanitizers (build-asan) warns that OpenMesh's PropertyT<VectorT>::push_back, which
// appends T(), may copy an uninitialised value: VectorT's default constructor leaves its components
// unset by design. A false positive inside the libraries' headers, silenced for this file alone (the
// pragma must precede the standard headers, where GCC places the warning).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

#include "tprf/scene/mesh_io.h"

#include "mesh_readers.h"
#include "open_reason.h"
#include "tprf/core/error.h"

#include <Eigen/Geometry>

#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

namespace tprf {
namespace {

// Double-precision points so that the transform is applied without a round trip through float.
struct DoubleTraits : OpenMesh::DefaultTraits {
    using Point = OpenMesh::Vec3d;
};
using OmMesh = OpenMesh::PolyMesh_ArrayKernelT<DoubleTraits>;

// OpenMesh writes warnings ("complex edge", "Face has equal vertices") to its global streams; the only
// diagnostics a user should see are ours, so they are switched off while a file is read and restored after.
class OpenMeshSilencer {
public:
    OpenMeshSilencer() {
        for (std::size_t i = 0; i < m_streams.size(); ++i) {
            m_enabled[i] = m_streams[i]->is_enabled();
            m_streams[i]->disable();
        }
    }
    ~OpenMeshSilencer() {
        for (std::size_t i = 0; i < m_streams.size(); ++i) {
            // A line left unfinished while disabled would otherwise come out once the stream is enabled.
            m_streams[i]->flush();
            if (m_enabled[i]) m_streams[i]->enable();
        }
    }
    OpenMeshSilencer(const OpenMeshSilencer&) = delete;
    OpenMeshSilencer& operator=(const OpenMeshSilencer&) = delete;

private:
    std::array<OpenMesh::mostream*, 3> m_streams{&omerr(), &omlog(), &omout()};
    std::array<bool, 3> m_enabled{};
};

// Records every face exactly as the reader hands it over, before OpenMesh's halfedge structure can refuse
// it (repeated vertices, non-manifold edges). The halfedge mesh is still built, because the readers query
// it (n_faces, handles of added faces) and rely on the usual ImporterT behaviour.
class RecordingImporter : public OpenMesh::IO::ImporterT<OmMesh> {
public:
    using Base = OpenMesh::IO::ImporterT<OmMesh>;
    explicit RecordingImporter(OmMesh& mesh) : Base(mesh) {}

    OpenMesh::VertexHandle add_vertex(const OpenMesh::Vec3f& point) override {
        ++file_vertices;
        return Base::add_vertex(point);
    }
    OpenMesh::VertexHandle add_vertex(const OpenMesh::Vec3d& point) override {
        ++file_vertices;
        return Base::add_vertex(point);
    }
    OpenMesh::VertexHandle add_vertex() override {
        ++file_vertices;
        return Base::add_vertex();
    }

    OpenMesh::FaceHandle add_face(const VHandles& indices) override {
        std::vector<int>& face = faces.emplace_back();
        face.reserve(indices.size());
        for (const auto& vh : indices) face.push_back(vh.idx());
        return Base::add_face(indices);
    }

    void reserve(unsigned int n_vertices, unsigned int n_edges, unsigned int n_faces) override {
        declared_faces = n_faces;
        Base::reserve(n_vertices, n_edges, n_faces);
    }

    /// Vertices the reader added. ImporterT appends copies of the corners of faces that the halfedge
    /// structure refuses; those come after these and are never referenced by `faces`.
    std::size_t file_vertices = 0;
    std::vector<std::vector<int>> faces;  ///< every face the reader passed on, file vertex indices
    std::size_t declared_faces = 0;       ///< the face count from the file's header (OFF, PLY), else 0
};

std::string lower_extension(const std::filesystem::path& file) {
    std::string ext = file.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return ext;
}

// The patterns ("*.obj *.off ...") of the registered readers, each followed by a space. IOManager::can_read()
// cannot be used instead: it asks the OFF and PLY readers to open a dummy file by that name, and they fail.
std::string readable_extensions() {
    const std::string& filters = OpenMesh::IO::IOManager().qt_read_filters();
    std::istringstream all(filters.substr(0, filters.find(')')).substr(filters.find('(') + 1));
    std::string known;
    for (std::string pattern; all >> pattern;) known += pattern + " ";
    return known;
}

// The whole file, for the readers to parse in place.
std::string file_bytes(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    std::string bytes;
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    if (size > 0) {
        bytes.resize(static_cast<std::size_t>(size));
        in.seekg(0);
        in.read(bytes.data(), size);
        bytes.resize(static_cast<std::size_t>(in.gcount()));
    }
    return bytes;
}

// Any other format, and binary OFF, through OpenMesh's readers (silenced): no line numbers there, and
// faces OpenMesh skips (fewer than three distinct corners) are counted from the file's declared count.
mesh_read::RawMesh read_with_openmesh(const std::filesystem::path& file, const std::string& ext) {
    OpenMeshSilencer silencer;
    if (const std::string known = readable_extensions(); known.find("*" + ext + " ") == std::string::npos)
        throw mesh_read::MeshFileError("unknown mesh format '" + ext + "' (tprf reads *.obj *.off *.ply *.stl " +
                                       "and what OpenMesh reads: " + known + ")");
    OmMesh om;
    RecordingImporter importer(om);
    OpenMesh::IO::Options options;
    if (!OpenMesh::IO::IOManager().read(file.string(), importer, options))
        throw mesh_read::MeshFileError("OpenMesh cannot read it as a " + ext.substr(1) + " file");
    mesh_read::RawMesh raw;
    raw.vertices.resize(importer.file_vertices);
    for (std::size_t i = 0; i < raw.vertices.size(); ++i) {
        const auto& p = om.point(OpenMesh::VertexHandle(static_cast<int>(i)));
        raw.vertices[i] = Vec3(p[0], p[1], p[2]);
        if (!raw.vertices[i].allFinite())  // OpenMesh gives no place to name
            throw mesh_read::MeshFileError("vertex " + mesh_read::count(i + 1) +
                                           " has a coordinate that is not a finite number (NaN or infinite)");
    }
    for (const auto& face : importer.faces) {
        for (int v : face) {
            if (v < 0 || std::size_t(v) >= raw.vertices.size())
                throw mesh_read::MeshFileError("face " + mesh_read::count(raw.faces() + 1) + " refers to vertex " +
                                               std::to_string(v) + ", but the file has " +
                                               mesh_read::count(raw.vertices.size(), "vertex", "vertices"));
            raw.indices.push_back(v);
        }
        raw.end_face();
    }
    // Faces OpenMesh skipped stay as empty faces, which count as degenerate.
    for (std::size_t f = importer.faces.size(); f < importer.declared_faces; ++f) raw.end_face();
    return raw;
}

mesh_read::RawMesh read_raw(const std::filesystem::path& file) {
    const std::string ext = lower_extension(file);
    if (ext == ".obj") return mesh_read::read_obj(file_bytes(file));
    if (ext == ".ply") return mesh_read::read_ply(file_bytes(file));
    if (ext == ".stl") return mesh_read::read_stl(file_bytes(file));
    if (ext == ".off") {
        const std::string bytes = file_bytes(file);
        if (!mesh_read::is_binary_off(bytes)) return mesh_read::read_off(bytes);
    }
    return read_with_openmesh(file, ext);
}

std::span<const int> face_of(const mesh_read::RawMesh& raw, std::size_t f) {
    return {raw.indices.data() + raw.first[f], raw.indices.data() + raw.first[f + 1]};
}

Vec3 newell(const std::vector<Vec3>& vertices, std::span<const int> face) {
    Vec3 n = Vec3::Zero();
    for (std::size_t i = 0; i < face.size(); ++i) n += vertices[face[i]].cross(vertices[face[(i + 1) % face.size()]]);
    return n;
}

bool is_degenerate(const std::vector<Vec3>& vertices, std::span<const int> face, double min_area) {
    if (face.size() < 3) return true;
    for (std::size_t i = 0; i < face.size(); ++i)
        for (std::size_t j = i + 1; j < face.size(); ++j)
            if (face[i] == face[j] || vertices[face[i]] == vertices[face[j]]) return true;
    return !(0.5 * newell(vertices, face).norm() > min_area);
}

// Lexicographic order of positions: where a face's canonical rotation starts.
bool before(const Vec3& a, const Vec3& b) {
    return a.x() != b.x() ? a.x() < b.x() : a.y() != b.y() ? a.y() < b.y() : a.z() < b.z();
}

// The corner a face's canonical rotation starts at: its lexicographically smallest position (distinct
// in a face that is not degenerate).
std::size_t canonical_start(const std::vector<Vec3>& p, std::span<const int> face) {
    std::size_t s = 0;
    for (std::size_t k = 1; k < face.size(); ++k)
        if (before(p[face[k]], p[face[s]])) s = k;
    return s;
}

std::uint64_t face_hash(const std::vector<Vec3>& p, std::span<const int> face) {
    const std::size_t s = canonical_start(p, face);
    std::uint64_t h = face.size();
    for (std::size_t k = 0; k < face.size(); ++k)
        for (int c = 0; c < 3; ++c)
            h = (h ^ std::bit_cast<std::uint64_t>(p[face[(s + k) % face.size()]][c] + 0.0)) * 0x100000001B3ull;
    return h ^ (h >> 31);
}

// Whether faces a and b have the same positions in the same cyclic order (the same side in front).
bool same_face(const std::vector<Vec3>& p, std::span<const int> a, std::span<const int> b) {
    if (a.size() != b.size()) return false;
    const std::size_t sa = canonical_start(p, a), sb = canonical_start(p, b);
    for (std::size_t k = 0; k < a.size(); ++k)
        if (p[a[(sa + k) % a.size()]] != p[b[(sb + k) % b.size()]]) return false;
    return true;
}

// Marks faces that repeat an earlier one (by position, so that the unshared corners of STL and of
// meshes written with repeated vertices are caught too). Two faces over the same corners in opposite
// order are the two sides of a sheet and both stay.
std::size_t mark_duplicates(const mesh_read::RawMesh& raw, const std::vector<Vec3>& p, std::vector<char>& drop) {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keys;
    keys.reserve(raw.faces());
    for (std::size_t f = 0; f < raw.faces(); ++f)
        if (!drop[f]) keys.emplace_back(face_hash(p, face_of(raw, f)), std::uint32_t(f));
    std::sort(keys.begin(), keys.end());
    std::size_t duplicates = 0;
    for (std::size_t g = 0; g < keys.size();) {
        std::size_t end = g + 1;
        while (end < keys.size() && keys[end].first == keys[g].first) ++end;
        for (std::size_t i = g + 1; i < end; ++i)
            for (std::size_t j = g; j < i; ++j)
                if (!drop[keys[j].second] &&
                    same_face(p, face_of(raw, keys[i].second), face_of(raw, keys[j].second))) {
                    drop[keys[i].second] = 1;
                    ++duplicates;
                    break;
                }
        g = end;
    }
    return duplicates;
}

}  // namespace

std::string counted(std::size_t n, std::string_view singular, std::string_view plural) {
    return mesh_read::count(n, singular, plural);
}

std::string describe(const MeshRepairs& r) {
    std::vector<std::string> parts;
    if (r.zero_area_faces > 0) parts.push_back(mesh_read::count(r.zero_area_faces, "zero-area face", "zero-area faces"));
    if (r.duplicate_faces > 0) parts.push_back(mesh_read::count(r.duplicate_faces, "duplicate face", "duplicate faces"));
    if (r.unreferenced_vertices > 0)
        parts.push_back(mesh_read::count(r.unreferenced_vertices, "unreferenced vertex", "unreferenced vertices"));
    std::string out;
    for (std::size_t k = 0; k < parts.size(); ++k)
        out += (k == 0 ? "" : k + 1 == parts.size() ? " and " : ", ") + parts[k];
    return out;
}

namespace {

// The kept faces of `raw` over the transformed positions `p`: degenerate and duplicate faces dropped,
// vertices renumbered in order of first use, windings reversed when the transform mirrors.
PolygonMesh keep_faces(const mesh_read::RawMesh& raw, const std::vector<Vec3>& p, bool mirror, double min_area) {
    PolygonMesh mesh;
    mesh.file_vertices = p.size();
    mesh.file_faces = raw.faces();
    std::vector<char> drop(raw.faces(), 0);
    for (std::size_t f = 0; f < raw.faces(); ++f)
        if (is_degenerate(p, face_of(raw, f), min_area)) {
            drop[f] = 1;
            ++mesh.repairs.zero_area_faces;
        }
    mesh.repairs.duplicate_faces = mark_duplicates(raw, p, drop);

    std::vector<int> remap(p.size(), -1);
    mesh.indices.reserve(raw.indices.size());
    mesh.first.reserve(raw.faces() + 1);
    for (std::size_t f = 0; f < raw.faces(); ++f) {
        if (drop[f]) continue;
        const std::size_t begin = mesh.indices.size();
        for (int v : face_of(raw, f)) {
            if (remap[std::size_t(v)] < 0) {
                remap[std::size_t(v)] = static_cast<int>(mesh.vertices.size());
                mesh.vertices.push_back(p[std::size_t(v)]);
                mesh.bounds.extend(p[std::size_t(v)]);
            }
            mesh.indices.push_back(remap[std::size_t(v)]);
        }
        // A mirroring transform turns counter-clockwise into clockwise; reversing keeps the front side.
        if (mirror) std::reverse(mesh.indices.begin() + std::ptrdiff_t(begin), mesh.indices.end());
        mesh.first.push_back(static_cast<std::uint32_t>(mesh.indices.size()));
    }
    mesh.repairs.unreferenced_vertices = p.size() - mesh.vertices.size();
    return mesh;
}

}  // namespace

PolygonMesh load_mesh(const std::filesystem::path& file, const Eigen::Matrix4d& transform,
                      const std::filesystem::path& scene_file, std::string_view json_path) {
    const std::string name = "mesh file '" + file.string() + "'";
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) fail_input(scene_file, json_path, name + " does not exist");
    if (!std::filesystem::is_regular_file(file, ec))
        fail_input(scene_file, json_path, name + " is not a regular file");
    errno = 0;
    const std::ifstream probe(file);
    if (!probe) fail_input(scene_file, json_path, name + " cannot be opened" + open_reason(errno));

    mesh_read::RawMesh raw;
    try {
        raw = read_raw(file);
    } catch (const mesh_read::MeshFileError& e) {
        fail_input(scene_file, json_path, name + ", " + e.what());
    } catch (const std::length_error& e) {
        fail_input(scene_file, json_path, name + " is too large for tprf to read (" + e.what() + ")");
    } catch (const std::bad_alloc&) {
        fail_input(scene_file, json_path, name + " needs more memory than there is to read");
    }
    if (raw.faces() == 0)
        fail_input(scene_file, json_path,
                   raw.vertices.empty() ? name + " has no vertices and no faces"
                   : raw.lines > 0
                       ? name + " has " + mesh_read::count(raw.vertices.size(), "vertex", "vertices") + " and " +
                             mesh_read::count(raw.lines, "line", "lines") +
                             " but no faces: a wireframe, not a surface (tprf renders surfaces)"
                       : name + " has " + mesh_read::count(raw.vertices.size(), "vertex", "vertices") +
                             " and no faces: a point cloud, not a surface (tprf renders surfaces; mesh it first, "
                             "e.g. by Poisson reconstruction)");

    const Eigen::Matrix3d linear = transform.topLeftCorner<3, 3>();
    const Vec3 offset = transform.topRightCorner<3, 1>();
    std::vector<Vec3> positions(raw.vertices.size());
    for (std::size_t i = 0; i < positions.size(); ++i) positions[i] = linear * raw.vertices[i] + offset;
    raw.vertices = {};
    Eigen::AlignedBox3d box;
    for (int v : raw.indices) box.extend(positions[std::size_t(v)]);
    const double diag = box.diagonal().stableNorm();  // no overflow or underflow on the way
    // Sizes far outside these are a wrong unit or scale, and their areas would overflow or underflow.
    constexpr double kSmallest = 1e-9, kLargest = 1e9;  // metres: a nanometre, a million kilometres
    if (!(diag <= kLargest) || (diag > 0.0 && diag < kSmallest)) {
        char size[32];
        std::snprintf(size, sizeof size, "%.3g", diag);
        fail_input(scene_file, json_path,
                   name + " spans " + size + " m after the transform, outside the 1e-9 m to 1e9 m that tprf " +
                       "computes with: check the file's unit and the transform's scale");
    }
    // Relative to the mesh's size so that the test means the same in millimetres and in kilometres.
    PolygonMesh mesh = keep_faces(raw, positions, linear.determinant() < 0.0, 1e-12 * diag * diag);
    if (mesh.faces() == 0)
        fail_input(scene_file, json_path,
                   name + " is empty: no faces left after dropping " + describe(mesh.repairs));
    return mesh;
}

}  // namespace tprf
