#pragma once
/// Mesh files as a polygon soup in metres: OBJ, OFF, PLY and STL by the project's own readers (with the
/// line or byte of every error), any other format OpenMesh reads through OpenMesh (docs/meshes.md).

#include "tprf/core/types.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tprf {

/// What load_mesh dropped from a file, counted so that a user is told.
struct MeshRepairs {
    std::size_t zero_area_faces = 0;        ///< fewer than three distinct corners, or (almost) no area
    std::size_t duplicate_faces = 0;        ///< the same corners in the same cyclic order as an earlier face
    std::size_t unreferenced_vertices = 0;  ///< vertices no kept face uses
    std::size_t dropped_faces() const { return zero_area_faces + duplicate_faces; }
    bool any() const { return dropped_faces() + unreferenced_vertices > 0; }
};

/// "3 zero-area faces, 1 duplicate face and 12 unreferenced vertices" (the kinds that occurred); empty
/// when nothing was dropped.
std::string describe(const MeshRepairs& repairs);

/// "1 vertex", "5,210 vertices": a count with thousands separators and its noun.
std::string counted(std::size_t n, std::string_view singular, std::string_view plural);

/// Polygons (triangles, quads, n-gons) with the file's winding (counter-clockwise seen from the front).
struct PolygonMesh {
    std::vector<Vec3> vertices;              ///< V, metres (transform applied), each used by a face
    std::vector<int> indices;                ///< the corners of every face, face after face
    std::vector<std::uint32_t> first{0};     ///< F + 1 offsets into `indices`
    std::size_t file_vertices = 0;           ///< vertices the file holds
    std::size_t file_faces = 0;              ///< faces the file holds
    MeshRepairs repairs;                     ///< what was dropped of them
    Eigen::AlignedBox3d bounds;              ///< of `vertices`, metres

    /// Number of faces F.
    std::size_t faces() const { return first.size() - 1; }
    /// The vertex indices of face f, in winding order.
    std::span<const int> face(std::size_t f) const {
        return {indices.data() + first[f], indices.data() + first[f + 1]};
    }
};

/// Loads `file` and applies the affine `transform`. Drops and counts degenerate faces (zero area after
/// the transform, repeated vertices), duplicate faces and unreferenced vertices. Throws tprf::Error
/// naming `scene_file`, `json_path` (e.g. "objects[1].file"), the mesh file, the line or byte offset
/// where that applies, and what is wrong: missing or unreadable file, unknown format, malformed
/// content, an index out of range, a coordinate that is not finite, a point cloud, nothing left.
PolygonMesh load_mesh(const std::filesystem::path& file, const Eigen::Matrix4d& transform,
                      const std::filesystem::path& scene_file, std::string_view json_path);

}  // namespace tprf
