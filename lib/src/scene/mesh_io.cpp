#include "tprf/scene/mesh_io.h"

#include "tprf/core/error.h"

#include <Eigen/Geometry>

#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <array>
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

std::size_t count_lines_starting_with(std::istream& in, std::string_view keyword) {
    std::size_t count = 0;
    std::string line;
    std::string token;
    while (std::getline(in, line)) {
        std::istringstream words(line);
        if (words >> token && token == keyword) ++count;
    }
    return count;
}

// OpenMesh's OBJ and STL readers silently skip faces with fewer than three distinct vertices before they
// reach the importer, and OpenMesh has no counter for them. The faces the file holds are counted here
// (without parsing them) so that the difference to what arrived is reported as dropped. OFF and PLY
// declare their face count in a header, which the importer receives through reserve().
std::size_t faces_in_file(const std::filesystem::path& file, const std::string& ext) {
    std::ifstream in(file, std::ios::binary);
    if (ext == ".obj") return count_lines_starting_with(in, "f");
    if (ext.starts_with(".stl")) {  // .stla and .stlb too
        // Binary STL: 80-byte header, uint32 triangle count, 50 bytes per triangle (the test OpenMesh uses).
        std::array<char, 84> header{};
        in.read(header.data(), header.size());
        if (in.gcount() == static_cast<std::streamsize>(header.size())) {
            std::uint32_t n = 0;
            for (int b = 3; b >= 0; --b)
                n = (n << 8) | static_cast<unsigned char>(header[80 + static_cast<std::size_t>(b)]);
            std::error_code ec;
            const auto size = std::filesystem::file_size(file, ec);
            if (!ec && size == 84 + 50 * static_cast<std::uintmax_t>(n)) return n;
        }
        in.clear();
        in.seekg(0);
        return count_lines_starting_with(in, "facet");
    }
    return 0;
}

// An ASCII OFF file as OpenMesh's reader takes it: '#' comments (whole lines and the rest of a line)
// and blank lines removed, which tools write and the reader refuses (or misreads), and counts written
// on the header line ("OFF 8 6 12") moved to a line of their own. Empty for binary OFF ("OFF BINARY"),
// which is left to OpenMesh as it is.
std::string off_text(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    std::string out, line;
    bool header = true;
    while (std::getline(in, line)) {
        if (const auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
        std::istringstream words(line);
        std::string first;
        if (!(words >> first)) continue;  // blank
        if (header) {
            header = false;
            std::string rest;
            std::getline(words, rest);
            if (first.ends_with("OFF") && rest.find("BINARY") != std::string::npos) return {};
            if (first.ends_with("OFF") && rest.find_first_not_of(" \t\r") != std::string::npos) {
                out += first + "\n" + rest + "\n";
                continue;
            }
        }
        out += line;
        out += '\n';
    }
    return out;
}

// Reads `file` (extension `ext`) into `importer` with OpenMesh's readers, silenced; returns what is
// wrong (to follow the file's name), or nothing.
std::string read_file(const std::filesystem::path& file, const std::string& ext, RecordingImporter& importer) {
    OpenMeshSilencer silencer;
    if (const std::string known = readable_extensions(); known.find("*" + ext + " ") == std::string::npos)
        return ": unknown mesh format '" + ext + "' (OpenMesh reads " + known + ")";
    OpenMesh::IO::Options options;
    bool read = false;
    if (const std::string text = ext == ".off" ? off_text(file) : std::string(); !text.empty()) {
        std::istringstream stream(text);
        read = OpenMesh::IO::IOManager().read(stream, ext, importer, options);
    } else {
        read = OpenMesh::IO::IOManager().read(file.string(), importer, options);
    }
    return read ? std::string() : " is not a valid " + ext.substr(1) + " file";
}

Vec3 newell(const std::vector<Vec3>& vertices, const std::vector<int>& face) {
    Vec3 n = Vec3::Zero();
    for (std::size_t i = 0; i < face.size(); ++i) {
        const Vec3& a = vertices[face[i]];
        const Vec3& b = vertices[face[(i + 1) % face.size()]];
        n += a.cross(b);
    }
    return n;
}

bool is_degenerate(const std::vector<Vec3>& vertices, const std::vector<int>& face, double min_area) {
    if (face.size() < 3) return true;
    for (std::size_t i = 0; i < face.size(); ++i)
        for (std::size_t j = i + 1; j < face.size(); ++j)
            if (face[i] == face[j] || vertices[face[i]] == vertices[face[j]]) return true;
    return 0.5 * newell(vertices, face).norm() < min_area;
}

}  // namespace

PolygonMesh load_mesh(const std::filesystem::path& file, const Eigen::Matrix4d& transform,
                      const std::filesystem::path& scene_file, std::string_view json_path) {
    const std::string name = "mesh file '" + file.string() + "'";
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) fail_input(scene_file, json_path, name + " does not exist");
    if (!std::filesystem::is_regular_file(file, ec))
        fail_input(scene_file, json_path, name + " is not a regular file");
    if (!std::ifstream(file).good()) fail_input(scene_file, json_path, name + " cannot be opened");

    const std::string ext = lower_extension(file);
    OmMesh om;
    RecordingImporter importer(om);
    if (const std::string problem = read_file(file, ext, importer); !problem.empty())
        fail_input(scene_file, json_path, name + problem);
    for (const auto& face : importer.faces)
        for (int v : face)
            if (v < 0 || static_cast<std::size_t>(v) >= importer.file_vertices)
                fail_input(scene_file, json_path,
                           name + ": a face refers to vertex " + std::to_string(v + 1) +
                               " but the file has " + std::to_string(importer.file_vertices) + " vertices");

    std::vector<Vec3> positions(importer.file_vertices);
    const Eigen::Matrix3d linear = transform.topLeftCorner<3, 3>();
    const Vec3 offset = transform.topRightCorner<3, 1>();
    Eigen::AlignedBox3d box;
    for (std::size_t i = 0; i < positions.size(); ++i) {
        const auto& p = om.point(OpenMesh::VertexHandle(static_cast<int>(i)));
        positions[i] = linear * Vec3(p[0], p[1], p[2]) + offset;
    }
    for (const auto& face : importer.faces)
        for (int v : face) box.extend(positions[v]);
    const double diag = box.isEmpty() ? 0.0 : box.diagonal().norm();
    // Relative to the mesh's size so that the test means the same in millimetres and in kilometres.
    const double min_area = 1e-12 * diag * diag;
    // A mirroring transform turns counter-clockwise into clockwise; reversing keeps the file's front side.
    const bool mirror = linear.determinant() < 0.0;

    const std::size_t in_file =
        std::max({faces_in_file(file, ext), importer.declared_faces, importer.faces.size()});
    if (in_file == 0 && importer.file_vertices > 0)
        fail_input(scene_file, json_path,
                   name + " has " + std::to_string(importer.file_vertices) +
                       " vertices and no faces: a point cloud, not a surface (tprf renders surfaces; "
                       "mesh it first, e.g. by Poisson reconstruction)");
    PolygonMesh mesh;
    mesh.dropped_degenerate = static_cast<int>(in_file - importer.faces.size());
    std::vector<int> remap(positions.size(), -1);
    mesh.faces.reserve(importer.faces.size());
    for (auto& face : importer.faces) {
        if (is_degenerate(positions, face, min_area)) {
            ++mesh.dropped_degenerate;
            continue;
        }
        if (mirror) std::reverse(face.begin(), face.end());
        for (int& v : face) {
            if (remap[v] < 0) {
                remap[v] = static_cast<int>(mesh.vertices.size());
                mesh.vertices.push_back(positions[v]);
            }
            v = remap[v];
        }
        mesh.faces.push_back(std::move(face));
    }
    if (mesh.faces.empty())
        fail_input(scene_file, json_path,
                   name + " is empty: no faces left after dropping " +
                       std::to_string(mesh.dropped_degenerate) + " degenerate ones");
    return mesh;
}

}  // namespace tprf
