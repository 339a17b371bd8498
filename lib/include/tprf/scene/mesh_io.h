#pragma once
/// Mesh files: any format OpenMesh reads (OBJ, PLY, OFF, STL), as a polygon soup in metres.

#include "tprf/core/types.h"

#include <filesystem>
#include <string_view>
#include <vector>

namespace tprf {

/// Polygons (triangles, quads, n-gons) with the file's winding (counter-clockwise seen from the front).
struct PolygonMesh {
    std::vector<Vec3> vertices;               ///< V, metres (transform applied)
    std::vector<std::vector<int>> faces;      ///< F, vertex indices in winding order
    int dropped_degenerate = 0;               ///< faces dropped for zero area or repeated vertices
};

/// Loads `file` through OpenMesh and applies the affine `transform`. Drops degenerate faces (zero area
/// after the transform, repeated vertices) and counts them. `scene_file` and `json_path` (e.g.
/// "objects[1].file") name the input in errors: missing or unreadable file, unknown format, empty mesh.
PolygonMesh load_mesh(const std::filesystem::path& file, const Eigen::Matrix4d& transform,
                      const std::filesystem::path& scene_file, std::string_view json_path);

}  // namespace tprf
