#pragma once
/// Patches: the planar convex cells that carry the time-resolved radiosity.

#include "tprf/core/types.h"
#include "tprf/core/progress.h"
#include "tprf/scene/brdf.h"
#include "tprf/scene/mesh_io.h"
#include "tprf/scene/scene.h"

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace tprf {

struct Scene;

/// The patch set as parallel arrays (struct of arrays). Patch i is the convex planar polygon
/// vertices[first[i]] .. vertices[first[i+1]-1], counter-clockwise seen from the front (along `normal`).
struct PatchSet {
    std::vector<Vec3> vertices;        ///< corner positions, metres
    std::vector<std::uint32_t> first;  ///< N + 1 offsets into `vertices`
    std::vector<Vec3> centroid;        ///< N, area centroid, metres
    std::vector<Vec3> normal;          ///< N, unit front normal
    std::vector<double> area;          ///< N, m^2
    std::vector<Rgb> albedo;           ///< N, in [0, 1]
    std::vector<Rgb> emission;         ///< N, radiance L_e, W/(m^2 sr)
    std::vector<std::uint32_t> object; ///< N, index into Scene::objects
    /// Per object (Scene::objects' order): its reflectance when its material is glossy or plastic, else
    /// none; empty when no object is glossy. A glossy patch's `albedo` is what its patch row passes on
    /// as a Lambertian surface: with directional cells (links.glossy_resolution > 0) the Lambertian
    /// part of its BRDF (lambertian_part_albedo; the cells carry the lobe, transport/glossy_rows.h),
    /// else its hemispherical albedo (docs/materials.md). The camera's direct light uses the BRDF.
    std::vector<std::optional<GlossyBrdf>> glossy;

    /// Patch i's glossy reflectance, or null for a Lambertian (or mirror, or glass) patch.
    const GlossyBrdf* brdf(std::size_t i) const {
        return glossy.empty() || !glossy[object[i]] ? nullptr : &*glossy[object[i]];
    }

    /// Number of glossy patches (brdf(i) not null).
    std::size_t glossy_patches() const;
    /// The rings of the glossy patches' directional cells under the setting `setting`
    /// (links.glossy_resolution; glossy_rings of this set's counts).
    int glossy_rings_for(int setting) const { return glossy_rings(setting, glossy_patches(), size()); }
    /// Number of patches N.
    std::size_t size() const { return centroid.size(); }
    /// Number of corners of patch i (3 or 4).
    std::size_t corners(std::size_t i) const { return first[i + 1] - first[i]; }
    /// First corner of patch i.
    const Vec3* polygon(std::size_t i) const { return vertices.data() + first[i]; }
    /// Bytes of a set of `patches` patches with `corners` corners in all (its arrays).
    static std::size_t bytes_for(std::size_t patches, std::size_t corners) {
        return corners * sizeof(Vec3) + (patches + 1) * sizeof(std::uint32_t) +
               patches * (2 * sizeof(Vec3) + sizeof(double) + 2 * sizeof(Rgb) + sizeof(std::uint32_t));
    }
};

/// One mesh file of a scene as it was loaded.
struct MeshReport {
    std::size_t object = 0;            ///< index into Scene::objects
    std::string file;                  ///< the file, as resolved from the scene
    std::size_t vertices = 0;          ///< vertices the kept faces use
    std::size_t faces = 0;             ///< polygons kept
    std::size_t triangles = 0;         ///< the triangles they were cut into (before refinement to max_edge)
    std::size_t quads = 0;             ///< planar convex quads kept whole (cut into grids of quads)
    Eigen::AlignedBox3d bounds;        ///< metres, the transform applied
    MeshRepairs repairs;               ///< what was dropped, and how much
};

/// The faces dropped from all of `meshes` (zero area, duplicates): render.json's
/// dropped_degenerate_faces.
std::size_t dropped_faces(const std::vector<MeshReport>& meshes);

/// What build_patches saw besides the patches.
struct PatchStats {
    double max_edge = 0.0;             ///< the patch size used, metres
    double diagonal = 0.0;             ///< of every object's bounding box, metres
    std::vector<MeshReport> meshes;    ///< one per mesh object, in the scene's order
};

/// A scene without patches.max_edge (a Mitsuba scene without --max-edge) gets patches no longer than its
/// bounding box's diagonal / this: the sample Cornell box (1 m) comes out at 2,325 patches from its XML
/// against 2,520 at its JSON's 0.05 m, and a scene in millimetres at the same count.
inline constexpr double kDefaultPatchDivisions = 32.0;

/// The notice of a scene without a patch size whose objects' bounding box has this diagonal (metres):
/// the size it gets and why (PatchOptions::notice); empty when the scene sets its patch size.
std::string default_size_note(const Scene& scene, double diagonal);

/// Options of the patch stage.
struct PatchOptions {
    ProgressFn progress;               ///< may be empty
    /// Called once, before any patch is cut, with what the user should know first: the patch size a
    /// scene without one gets and why (may be empty).
    std::function<void(const std::string&)> notice;
};

/// Subdivides every object of the scene into patches: rectangles and the planar convex quads of meshes
/// into grids of quads, other mesh faces into triangles refined until no patch edge exceeds the
/// scene's max_edge (bounding-box diagonal / kDefaultPatchDivisions when the scene gives none). A
/// two-sided object yields each patch twice, once per side.
PatchSet build_patches(const Scene& scene, const PatchOptions& options = {}, PatchStats* stats = nullptr);

/// The point of a triangle or quad (`count` 3 or 4 corners) at (u, v) in the unit square: bilinear on a
/// quad (uniform in area for parallelograms), the square-root map on a triangle (uniform in area).
Vec3 polygon_point(const Vec3* corners, std::size_t count, double u, double v);

/// The point of patch i at (u, v) in the unit square (polygon_point of its corners; the quads of
/// rectangle grids are parallelograms).
inline Vec3 patch_point(const PatchSet& patches, std::size_t i, double u, double v) {
    return polygon_point(patches.polygon(i), patches.corners(i), u, v);
}

/// Largest distance from patch i's centroid to its corners, metres.
double circumradius(const PatchSet& patches, std::size_t i);

/// Appends one patch (a convex planar polygon, counter-clockwise about its front) with its attributes;
/// computes centroid, normal and area. Used by build_patches and by tests that build patch sets by hand.
void add_patch(PatchSet& patches, const Vec3* corners, std::size_t count, const Rgb& albedo,
               const Rgb& emission, std::uint32_t object);

/// A patch that build_patches would make, seen from afar: a point on it and its front normal.
struct PatchSample {
    Vec3 point = Vec3::Zero();
    Vec3 normal = Vec3::UnitZ();
    std::uint32_t object = 0;          ///< index into Scene::objects
    double area = 0.0;                 ///< the patch's area, m^2
};

/// What build_patches would make, counted by the same rules without making it (the resource estimate,
/// pipeline/info.h). Mesh files are loaded and triangulated to count their refined triangles; nothing
/// of the size of the patch set is allocated.
struct PatchCensus {
    std::size_t patches = 0;           ///< N, both sides of two-sided objects counted
    std::size_t corners = 0;           ///< corners of all patches (4 a quad, 3 a triangle)
    std::size_t emissive = 0;          ///< patches that emit
    std::size_t mesh_faces = 0;        ///< polygons read from mesh files
    double max_edge = 0.0;             ///< the patch size build_patches would use, metres
    double diagonal = 0.0;             ///< bounding-box diagonal of every object, metres
    std::vector<MeshReport> meshes;    ///< one per mesh object, as build_patches reports them
    std::vector<Eigen::AlignedBox3d> bounds;  ///< per object: its bounding box, metres
    std::vector<std::size_t> object_patches;  ///< per object: its patches, both sides counted
    /// About `samples` patches drawn uniformly from all N (each object gets its share by its patch
    /// count), at a uniform point of the patch (a rectangle's grid cell) or of its mesh triangle.
    std::vector<PatchSample> samples;
};

/// Counts the patches of `scene` as build_patches would cut them, and draws `samples` of them
/// (deterministically, from `seed`).
PatchCensus count_patches(const Scene& scene, std::size_t samples = 0, std::uint64_t seed = 1);

}  // namespace tprf
