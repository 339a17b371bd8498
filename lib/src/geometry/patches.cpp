#include "tprf/geometry/patches.h"

#include "tprf/core/error.h"
#include "tprf/core/random.h"
#include "tprf/scene/mesh_io.h"
#include "tprf/scene/scene.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <span>
#include <string>

namespace tprf {
namespace {

// Number of equal pieces that bring `length` down to at most `max_edge`. The slack keeps 1.0 / 0.1 from
// becoming 11 pieces through rounding; a piece then exceeds max_edge by at most a relative 1e-9.
std::size_t pieces(double length, double max_edge) {
    const double n = std::ceil(length / max_edge - 1e-9);
    return n < 1.0 ? 1 : static_cast<std::size_t>(n);
}

struct Grid {
    std::size_t nu = 1;
    std::size_t nv = 1;
};

Grid rectangle_grid(const RectangleShape& r, double max_edge) {
    return {pieces(r.u.norm(), max_edge), pieces(r.v.norm(), max_edge)};
}

using Triangle = std::array<Vec3, 3>;

// A piece of a mesh face before refinement to max_edge: a triangle, or a planar convex quad kept
// whole (a grid of quads then, as rectangles are cut).
struct Cell {
    std::array<Vec3, 4> p;
    std::size_t corners = 3;
};

// Whether the polygon turns the same way (about its Newell normal n) at every corner.
bool is_convex(const std::vector<Vec3>& v, std::span<const int> face, const Vec3& n) {
    const std::size_t m = face.size();
    for (std::size_t k = 0; k < m; ++k) {
        const Vec3& a = v[face[(k + m - 1) % m]];
        const Vec3& b = v[face[k]];
        const Vec3& c = v[face[(k + 1) % m]];
        if ((b - a).cross(c - b).dot(n) < 0.0) return false;
    }
    return true;
}

// Ear clipping of a simple planar polygon that is not convex, counter-clockwise about its Newell normal
// n: a corner whose triangle with its neighbours turns the polygon's way and holds no other corner is
// cut off, until three are left. A polygon with no ear (it crosses itself) is fanned from what is left.
void ear_clip(const std::vector<Vec3>& v, std::span<const int> face, const Vec3& n, std::vector<Triangle>& out) {
    std::vector<int> left(face.begin(), face.end());
    const auto turn = [&](const Vec3& a, const Vec3& b, const Vec3& c) { return (b - a).cross(c - b).dot(n); };
    const auto inside = [&](const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
        return turn(a, b, p) >= 0.0 && turn(b, c, p) >= 0.0 && turn(c, a, p) >= 0.0;
    };
    while (left.size() > 3) {
        const std::size_t m = left.size();
        bool cut = false;
        for (std::size_t k = 0; k < m && !cut; ++k) {
            const Vec3& a = v[left[(k + m - 1) % m]];
            const Vec3& b = v[left[k]];
            const Vec3& c = v[left[(k + 1) % m]];
            if (!(turn(a, b, c) > 0.0)) continue;
            bool empty = true;
            for (std::size_t j = 0; j < m && empty; ++j)
                if (j != k && j != (k + 1) % m && j != (k + m - 1) % m && inside(v[left[j]], a, b, c)) empty = false;
            if (!empty) continue;
            out.push_back({a, b, c});
            left.erase(left.begin() + std::ptrdiff_t(k));
            cut = true;
        }
        if (!cut) break;
    }
    for (std::size_t i = 1; i + 1 < left.size(); ++i) out.push_back({v[left[0]], v[left[i]], v[left[i + 1]]});
}

// Whether a quad's corners lie in one plane: within 1e-6 of its size (float coordinates are exact to
// about 1e-7 of it), and whether it turns the same way, strictly, at every corner.
bool planar_convex_quad(const std::vector<Vec3>& v, std::span<const int> face, const Vec3& n) {
    if (face.size() != 4) return false;
    const Vec3 normal = n.normalized();
    const double size = std::max((v[face[2]] - v[face[0]]).norm(), (v[face[3]] - v[face[1]]).norm());
    for (int k : face)
        if (std::abs((v[k] - v[face[0]]).dot(normal)) > 1e-6 * size) return false;
    for (std::size_t k = 0; k < 4; ++k) {
        const Vec3& a = v[face[(k + 3) % 4]];
        const Vec3& b = v[face[k]];
        const Vec3& c = v[face[(k + 1) % 4]];
        if (!((b - a).cross(c - b).dot(normal) > 0.0)) return false;
    }
    return true;
}

// Planar convex quads stay whole. Other convex polygons (what mesh files hold in practice) are fanned
// from their first corner; the others are ear-clipped. Pieces without area (a corner lying on an edge
// of the polygon) are left out: they carry no energy and have no normal. "Without area" is relative to
// the polygon, which load_mesh guarantees is not degenerate itself.
void cut_faces(const PolygonMesh& mesh, std::vector<Cell>& out) {
    const std::vector<Vec3>& v = mesh.vertices;
    std::vector<Triangle> pieces;
    for (std::size_t f = 0; f < mesh.faces(); ++f) {
        const std::span<const int> face = mesh.face(f);
        Vec3 n = Vec3::Zero();
        for (std::size_t k = 0; k < face.size(); ++k) n += v[face[k]].cross(v[face[(k + 1) % face.size()]]);
        if (planar_convex_quad(v, face, n)) {
            out.push_back({{v[face[0]], v[face[1]], v[face[2]], v[face[3]]}, 4});
            continue;
        }
        pieces.clear();
        if (is_convex(v, face, n))
            for (std::size_t i = 1; i + 1 < face.size(); ++i) pieces.push_back({v[face[0]], v[face[i]], v[face[i + 1]]});
        else
            ear_clip(v, face, n, pieces);
        double polygon = 0.0;
        for (const Triangle& t : pieces) polygon += (t[1] - t[0]).cross(t[2] - t[0]).norm();
        for (const Triangle& t : pieces)
            if ((t[1] - t[0]).cross(t[2] - t[0]).norm() > 1e-12 * polygon) out.push_back({{t[0], t[1], t[2], t[2]}, 3});
    }
}

// A cell's cut: n x n similar triangles (nu = nv = n) for a triangle, nu x nv quads of a bilinear grid
// for a quad, each edge at most max_edge.
Grid cell_grid(const Cell& c, double max_edge) {
    const auto& p = c.p;
    if (c.corners == 3) {
        const std::size_t n =
            pieces(std::max({(p[1] - p[0]).norm(), (p[2] - p[1]).norm(), (p[0] - p[2]).norm()}), max_edge);
        return {n, n};
    }
    // The grid's u lines run between edges p0p1 and p3p2, so a piece of either is at most the longer / nu.
    return {pieces(std::max((p[1] - p[0]).norm(), (p[2] - p[3]).norm()), max_edge),
            pieces(std::max((p[3] - p[0]).norm(), (p[2] - p[1]).norm()), max_edge)};
}

// One object's geometry before subdivision: a rectangle, or a mesh already cut into cells, with the
// patches each side will have.
struct Source {
    const Object* object = nullptr;
    std::vector<Cell> cells;          // empty for a rectangle
    std::vector<std::size_t> running; // patches per side of cells 0..c
    std::size_t patch_count = 0;      // per side
    std::size_t corner_count = 0;     // corners of those patches, per side

    std::size_t sides() const { return object->two_sided ? 2 : 1; }
};

// Object `object` cut into patches of at most `max_edge`, counted (the mesh is cut into cells, not
// refined).
Source cut(const Object& object, const PolygonMesh& mesh, double max_edge) {
    Source s;
    s.object = &object;
    if (const auto* r = std::get_if<RectangleShape>(&object.shape)) {
        const Grid g = rectangle_grid(*r, max_edge);
        s.patch_count = g.nu * g.nv;
        s.corner_count = 4 * s.patch_count;
        return s;
    }
    cut_faces(mesh, s.cells);
    s.running.reserve(s.cells.size());
    for (const Cell& c : s.cells) {
        const Grid g = cell_grid(c, max_edge);
        s.patch_count += g.nu * g.nv;
        s.corner_count += c.corners * g.nu * g.nv;
        s.running.push_back(s.patch_count);
    }
    return s;
}

// Every object's mesh (loaded through OpenMesh; none for a rectangle) and bounding box.
struct LoadedObjects {
    std::vector<PolygonMesh> meshes;
    std::vector<Eigen::AlignedBox3d> bounds;
    std::vector<MeshReport> reports;  // their triangles counted once cut
};

MeshReport report(std::size_t object, const std::filesystem::path& file, const PolygonMesh& mesh) {
    MeshReport r;
    r.object = object;
    r.file = file.string();
    r.vertices = mesh.vertices.size();
    r.faces = mesh.faces();
    r.bounds = mesh.bounds;
    r.repairs = mesh.repairs;
    return r;
}

// The cells of object k's mesh, now that it is cut, in its report.
void count_cells(LoadedObjects& loaded, std::size_t k, const Source& s) {
    for (MeshReport& r : loaded.reports)
        if (r.object == k)
            for (const Cell& c : s.cells) ++(c.corners == 3 ? r.triangles : r.quads);
}

LoadedObjects load_objects(const Scene& scene) {
    LoadedObjects out;
    out.meshes.resize(scene.objects.size());
    out.bounds.resize(scene.objects.size());
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        const Object& object = scene.objects[k];
        const std::string path = "objects[" + std::to_string(k) + "]";
        Eigen::AlignedBox3d& box = out.bounds[k];
        if (const auto* r = std::get_if<RectangleShape>(&object.shape)) {
            if (!(r->u.cross(r->v).norm() > 0.0)) fail_input(scene.file, path, "rectangle has no area");
            for (const Vec3& p : {r->origin, Vec3(r->origin + r->u), Vec3(r->origin + r->u + r->v),
                                  Vec3(r->origin + r->v)})
                box.extend(p);
        } else {
            const auto& m = std::get<MeshShape>(object.shape);
            out.meshes[k] = load_mesh(m.file, m.transform, scene.file, path + ".file");
            out.reports.push_back(report(k, m.file, out.meshes[k]));
            box = out.meshes[k].bounds;
        }
    }
    return out;
}

// The bounding box of every object.
Eigen::AlignedBox3d scene_box(const LoadedObjects& loaded) {
    Eigen::AlignedBox3d box;
    for (const Eigen::AlignedBox3d& b : loaded.bounds) box.extend(b);
    return box;
}

// The patch size: the scene's, or its bounding-box diagonal / kDefaultPatchDivisions.
double patch_size(const Scene& scene, const Eigen::AlignedBox3d& box) {
    const double max_edge = scene.max_edge > 0.0 ? scene.max_edge : box.diagonal().norm() / kDefaultPatchDivisions;
    TPRF_CHECK_LT(0.0, max_edge);
    return max_edge;
}

void emit(PatchSet& patches, const Vec3* corners, std::size_t count, const Object& object,
          std::uint32_t id) {
    add_patch(patches, corners, count, object.albedo, object.emission, id);
    if (!object.two_sided) return;
    // Emission leaves from the front side (docs/scene.md); a two-sided object has two fronts, so the back copy
    // emits too. This makes a two-sided emitter a light seen from both sides, which is what a user who
    // asks for two sides on an emitter means.
    std::array<Vec3, 4> reversed;
    for (std::size_t i = 0; i < count; ++i) reversed[i] = corners[count - 1 - i];
    add_patch(patches, reversed.data(), count, object.albedo, object.emission, id);
}

// The quads of a grid whose node (i, j) is point(i, j), counter-clockwise as i, then j, grow.
template <class Point>
void emit_grid(PatchSet& patches, const Grid& grid, Point point, const Object& object, std::uint32_t id) {
    for (std::size_t j = 0; j < grid.nv; ++j)
        for (std::size_t i = 0; i < grid.nu; ++i) {
            const std::array<Vec3, 4> quad{point(i, j), point(i + 1, j), point(i + 1, j + 1),
                                           point(i, j + 1)};
            emit(patches, quad.data(), quad.size(), object, id);
        }
}

void emit_rectangle(PatchSet& patches, const RectangleShape& r, const Grid& grid, const Object& object,
                    std::uint32_t id) {
    const double nu = static_cast<double>(grid.nu);
    const double nv = static_cast<double>(grid.nv);
    emit_grid(patches, grid, [&](std::size_t i, std::size_t j) {
        return Vec3(r.origin + (static_cast<double>(i) / nu) * r.u + (static_cast<double>(j) / nv) * r.v);
    }, object, id);
}

// A planar convex quad as a bilinear grid: its sub-quads lie in its plane and are convex.
void emit_quad(PatchSet& patches, const Cell& c, const Grid& grid, const Object& object, std::uint32_t id) {
    const double nu = static_cast<double>(grid.nu);
    const double nv = static_cast<double>(grid.nv);
    emit_grid(patches, grid, [&](std::size_t i, std::size_t j) {
        return polygon_point(c.p.data(), 4, static_cast<double>(i) / nu, static_cast<double>(j) / nv);
    }, object, id);
}

// Uniform subdivision into n^2 similar triangles: every sub-edge is parallel to an edge of `t` and 1/n of
// its length, and every sub-triangle keeps the winding of `t`.
void emit_triangle(PatchSet& patches, const std::array<Vec3, 4>& t, std::size_t n, const Object& object,
                   std::uint32_t id) {
    const double inv = 1.0 / static_cast<double>(n);
    const Vec3 du = (t[1] - t[0]) * inv;
    const Vec3 dv = (t[2] - t[0]) * inv;
    auto point = [&](std::size_t i, std::size_t j) {
        return Vec3(t[0] + static_cast<double>(i) * du + static_cast<double>(j) * dv);
    };
    for (std::size_t j = 0; j < n; ++j)
        for (std::size_t i = 0; i + j < n; ++i) {
            const std::array<Vec3, 3> up{point(i, j), point(i + 1, j), point(i, j + 1)};
            emit(patches, up.data(), up.size(), object, id);
            if (i + j + 1 < n) {
                const std::array<Vec3, 3> down{point(i + 1, j), point(i + 1, j + 1), point(i, j + 1)};
                emit(patches, down.data(), down.size(), object, id);
            }
        }
}

}  // namespace

Vec3 polygon_point(const Vec3* p, std::size_t count, double u, double v) {
    if (count == 4) return (1 - u) * (1 - v) * p[0] + u * (1 - v) * p[1] + u * v * p[2] + (1 - u) * v * p[3];
    const double su = std::sqrt(u);
    return (1 - su) * p[0] + su * (1 - v) * p[1] + su * v * p[2];
}

double circumradius(const PatchSet& patches, std::size_t i) {
    double r = 0.0;
    for (std::size_t k = 0; k < patches.corners(i); ++k) r = std::max(r, (patches.polygon(i)[k] - patches.centroid[i]).norm());
    return r;
}

void add_patch(PatchSet& patches, const Vec3* corners, std::size_t count, const Rgb& albedo,
               const Rgb& emission, std::uint32_t object) {
    TPRF_CHECK_LE(std::size_t{3}, count);
    TPRF_CHECK_LE(patches.vertices.size() + count,
                  static_cast<std::size_t>(std::numeric_limits<std::uint32_t>::max()));
    // Newell's normal is exact for planar polygons and does not depend on which corner comes first.
    Vec3 n = Vec3::Zero();
    for (std::size_t i = 0; i < count; ++i) n += corners[i].cross(corners[(i + 1) % count]);
    const double twice_area = n.norm();
    TPRF_CHECK_LT(0.0, twice_area);
    const Vec3 normal = n / twice_area;

    // Area centroid: the fan's triangle centroids weighted by their (signed) areas.
    Vec3 centroid = Vec3::Zero();
    double weight = 0.0;
    for (std::size_t i = 1; i + 1 < count; ++i) {
        const double w = (corners[i] - corners[0]).cross(corners[i + 1] - corners[0]).dot(normal);
        centroid += w * (corners[0] + corners[i] + corners[i + 1]) / 3.0;
        weight += w;
    }

    if (patches.first.empty()) patches.first.push_back(0);
    patches.vertices.insert(patches.vertices.end(), corners, corners + count);
    patches.first.push_back(static_cast<std::uint32_t>(patches.vertices.size()));
    patches.centroid.push_back(centroid / weight);
    patches.normal.push_back(normal);
    patches.area.push_back(0.5 * twice_area);
    patches.albedo.push_back(albedo);
    patches.emission.push_back(emission);
    patches.object.push_back(object);
}

std::size_t PatchSet::glossy_patches() const {
    if (glossy.empty()) return 0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < size(); ++i) n += brdf(i) != nullptr;
    return n;
}

std::size_t dropped_faces(const std::vector<MeshReport>& meshes) {
    std::size_t n = 0;
    for (const MeshReport& m : meshes) n += m.repairs.dropped_faces();
    return n;
}

namespace {

// The glossy objects' reflectances (PatchSet::glossy), and their patches' albedo: with directional cells
// (links.glossy_resolution) the Lambertian part's, which their patch rows carry; without, each object's
// hemispherical albedo, what the transport between patches then takes a glossy patch for.
void add_glossy(const Scene& scene, PatchSet& patches) {
    const auto& objects = scene.objects;
    if (std::none_of(objects.begin(), objects.end(), [](const Object& o) { return o.material.glossy(); })) return;
    patches.glossy.resize(objects.size());
    for (std::size_t k = 0; k < objects.size(); ++k)
        if (objects[k].material.glossy()) patches.glossy[k] = glossy_brdf(objects[k]);
    const int rings = patches.glossy_rings_for(scene.links.glossy_resolution);
    std::vector<Rgb> albedo(objects.size());
    for (std::size_t k = 0; k < objects.size(); ++k)
        if (patches.glossy[k])
            albedo[k] = rings > 0 ? lambertian_part_albedo(*patches.glossy[k], rings)
                                  : patches.glossy[k]->hemispherical_albedo();
    for (std::size_t i = 0; i < patches.size(); ++i)
        if (patches.brdf(i)) patches.albedo[i] = albedo[patches.object[i]];
}

}  // namespace

std::string default_size_note(const Scene& scene, double diagonal) {
    if (scene.max_edge > 0.0) return {};
    char text[300];
    std::snprintf(text, sizeof text,
                  "patches of %.4g m: the scene sets no patch size, so its bounding box's diagonal (%.4g m) / %g "
                  "(--max-edge%s sets it)",
                  diagonal / kDefaultPatchDivisions, diagonal, kDefaultPatchDivisions,
                  scene.file.extension() == ".json" ? " or patches.max_edge" : "");
    return text;
}

PatchSet build_patches(const Scene& scene, const PatchOptions& options, PatchStats* stats) {
    PatchStats local;
    PatchStats& st = stats ? *stats : local;
    st = PatchStats{};

    // Meshes are loaded first: the default patch size depends on the bounding box of every object.
    LoadedObjects loaded = load_objects(scene);
    PatchSet patches;
    patches.first.push_back(0);
    if (scene.objects.empty()) return patches;
    const Eigen::AlignedBox3d box = scene_box(loaded);
    st.max_edge = patch_size(scene, box);
    st.diagonal = box.diagonal().norm();
    if (const std::string note = default_size_note(scene, st.diagonal); !note.empty() && options.notice) options.notice(note);

    // Counting before emitting lets every array be allocated once.
    std::vector<Source> sources;
    std::size_t total = 0;
    std::size_t corner_total = 0;
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        sources.push_back(cut(scene.objects[k], loaded.meshes[k], st.max_edge));
        count_cells(loaded, k, sources.back());
        loaded.meshes[k] = PolygonMesh{};
        const Source& s = sources.back();
        total += s.patch_count * s.sides();
        corner_total += s.corner_count * s.sides();
    }
    st.meshes = std::move(loaded.reports);
    patches.vertices.reserve(corner_total);
    patches.first.reserve(total + 1);
    patches.centroid.reserve(total);
    patches.normal.reserve(total);
    patches.area.reserve(total);
    patches.albedo.reserve(total);
    patches.emission.reserve(total);
    patches.object.reserve(total);

    for (std::size_t k = 0; k < sources.size(); ++k) {
        const Source& s = sources[k];
        const auto id = static_cast<std::uint32_t>(k);
        if (const auto* r = std::get_if<RectangleShape>(&s.object->shape)) {
            emit_rectangle(patches, *r, rectangle_grid(*r, st.max_edge), *s.object, id);
        } else {
            for (const Cell& c : s.cells) {
                const Grid g = cell_grid(c, st.max_edge);
                if (c.corners == 3)
                    emit_triangle(patches, c.p, g.nu, *s.object, id);
                else
                    emit_quad(patches, c, g, *s.object, id);
            }
        }
        if (options.progress)
            options.progress("patches", static_cast<double>(k + 1) / static_cast<double>(sources.size()));
    }
    TPRF_CHECK_EQ(patches.size(), total);
    add_glossy(scene, patches);
    return patches;
}

namespace {

// A uniform double in [0, 1) from one 64-bit draw.
double unit(SplitMix64& random) { return double(random.next() >> 11) * 0x1.0p-53; }

// Patch `local` (0 <= local < per_side) of one side of an object, at a uniform point.
PatchSample census_sample(const Source& c, double max_edge, std::size_t local, SplitMix64& random) {
    PatchSample s;
    const double a = unit(random), b = unit(random);
    if (const auto* r = std::get_if<RectangleShape>(&c.object->shape)) {
        const Grid g = rectangle_grid(*r, max_edge);
        const double i = double(local % g.nu), j = double(local / g.nu);
        s.point = r->origin + (i + a) / double(g.nu) * r->u + (j + b) / double(g.nv) * r->v;
        s.normal = r->u.cross(r->v).normalized();
        s.area = r->u.cross(r->v).norm() / double(g.nu * g.nv);
        return s;
    }
    const auto at = std::upper_bound(c.running.begin(), c.running.end(), local);
    const Cell& cell = c.cells[std::size_t(at - c.running.begin())];
    s.point = polygon_point(cell.p.data(), cell.corners, a, b);
    const Grid g = cell_grid(cell, max_edge);
    // A quad's or a triangle's area (its diagonals' cross product; for a triangle two edges from p2),
    // shared by the grid's pieces (a quad's bilinear pieces only on average).
    s.area = 0.5 * (cell.p[2] - cell.p[0]).cross(cell.p[cell.corners - 1] - cell.p[1]).norm() / double(g.nu * g.nv);
    s.normal = (cell.p[1] - cell.p[0]).cross(cell.p[2] - cell.p[0]).normalized();
    return s;
}

// Each object's share of `samples` by its patch count (running rounding: the shares add up).
void draw_samples(const std::vector<Source>& sources, std::size_t samples, std::uint64_t seed, PatchCensus& census) {
    SplitMix64 random(seed);
    std::size_t before = 0;
    for (std::size_t k = 0; k < sources.size(); ++k) {
        const Source& c = sources[k];
        const std::size_t count = c.patch_count * c.sides();
        const auto share = [&](std::size_t upto) {
            return std::size_t(std::llround(double(samples) * double(upto) / double(census.patches)));
        };
        const std::size_t draws = share(before + count) - share(before);
        before += count;
        for (std::size_t d = 0; d < draws; ++d) {
            const std::size_t index = std::min(count - 1, std::size_t(unit(random) * double(count)));
            PatchSample s = census_sample(c, census.max_edge, index % c.patch_count, random);
            if (index >= c.patch_count) s.normal = -s.normal;  // the back copy of a two-sided object
            s.object = std::uint32_t(k);
            census.samples.push_back(s);
        }
    }
}

}  // namespace

PatchCensus count_patches(const Scene& scene, std::size_t samples, std::uint64_t seed) {
    PatchCensus census;
    LoadedObjects loaded = load_objects(scene);
    census.bounds = loaded.bounds;
    for (const PolygonMesh& m : loaded.meshes) census.mesh_faces += m.faces();
    if (scene.objects.empty()) return census;
    const Eigen::AlignedBox3d box = scene_box(loaded);
    census.diagonal = box.diagonal().norm();
    census.max_edge = patch_size(scene, box);
    std::vector<Source> sources;
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        sources.push_back(cut(scene.objects[k], loaded.meshes[k], census.max_edge));
        count_cells(loaded, k, sources.back());
        const Source& c = sources.back();
        census.patches += c.patch_count * c.sides();
        census.object_patches.push_back(c.patch_count * c.sides());
        census.corners += c.corner_count * c.sides();

        if ((scene.objects[k].emission > 0.0).any()) census.emissive += c.patch_count * c.sides();
    }
    census.meshes = std::move(loaded.reports);
    if (samples > 0 && census.patches > 0) draw_samples(sources, samples, seed, census);
    return census;
}

}  // namespace tprf
