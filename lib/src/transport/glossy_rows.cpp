#include "tprf/transport/glossy_rows.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/light_sources.h"
#include "tprf/transport/link_set.h"
#include "patch_pairs.h"

#include <algorithm>
#include <cmath>

namespace tprf {

namespace {

// Incoming directions sampled per side of a cell for the cells' reflectance.
constexpr int kCellSamples = 4;
// The smallest float distance whose delay in the solver's arithmetic (delay_bins_f) is a whole bin.
float one_bin_step(double bin_width_m) {
    const float inv_bin = float(1.0 / bin_width_m);
    float step = float(bin_width_m);
    while (step * inv_bin < 1.0f) step = std::nextafter(step, INFINITY);
    return step;
}

// `set` with rows.rows() leaves more, numbered from the patches' end: clusters and their links move up.
void insert_rows(LinkSet& set, const PatchSet& patches, const GlossyRows& rows) {
    ClusterTree& t = set.tree;
    const std::size_t n = t.leaves, extra = rows.rows();
    const auto moved = [&](std::uint32_t m) { return m >= n && m != kNoNode ? std::uint32_t(m + extra) : m; };
    for (std::uint32_t& p : t.parent) p = moved(p);
    for (auto& c : t.children) c = {moved(c[0]), moved(c[1])};
    // Per-node arrays: the new leaves go after the old ones, before the clusters.
    const auto insert = [&](auto& v, auto value_of) {
        using T = typename std::decay_t<decltype(v)>::value_type;
        std::vector<T> add(extra);
        for (std::size_t k = 0; k < extra; ++k) add[k] = value_of(k);
        v.insert(v.begin() + std::ptrdiff_t(n), add.begin(), add.end());
    };
    const auto patch_of = [&](std::size_t k) {
        return rows.glossy[(k % (rows.rows() / 2)) / std::size_t(rows.cells())];
    };
    insert(t.parent, [](std::size_t) { return kNoNode; });
    insert(t.area, [&](std::size_t k) { return patches.area[patch_of(k)]; });
    insert(t.centre, [&](std::size_t k) { return patches.centroid[patch_of(k)]; });
    insert(t.radius, [&](std::size_t k) { return circumradius(patches, patch_of(k)); });
    insert(t.cone_axis, [&](std::size_t k) { return patches.normal[patch_of(k)]; });
    insert(t.cone_cos, [](std::size_t) { return 1.0; });
    insert(t.first, [&](std::size_t k) { return std::uint32_t(n + k); });
    insert(t.last, [&](std::size_t k) { return std::uint32_t(n + k + 1); });
    for (std::size_t k = 0; k < extra; ++k) {
        t.leaf_order.push_back(std::uint32_t(n + k));
        t.area_prefix.push_back(t.area_prefix.back() + patches.area[patch_of(k)]);
    }
    t.leaves = n + extra;
    Links& l = set.links;
    for (std::uint32_t& s : l.source) s = moved(s);
    l.row.insert(l.row.begin() + std::ptrdiff_t(n + 1), extra, l.row[n]);
}

}  // namespace

void cell_frame(const Vec3& n, Vec3& t, Vec3& b) {
    const Vec3 helper = std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
    t = (helper - n * n.dot(helper)).normalized();
    b = n.cross(t);
}

namespace {

// `dir` (world) in the frame of patch i's cells, unit.
Vec3 in_cell_frame(const PatchSet& set, std::size_t i, const Vec3& dir) {
    const Vec3& n = set.normal[i];
    Vec3 t, b;
    cell_frame(n, t, b);
    return Vec3(dir.dot(t), dir.dot(b), dir.dot(n)).normalized();
}

// Points per side of the grid cell_shares lays on the other polygon: fewest and most; and on a near
// glossy patch itself.
constexpr int kShareGridMin = 2, kShareGridMax = 8, kShareGridNear = 3;

}  // namespace

std::vector<CellShare> cell_shares(const PatchSet& patches, int rings, std::size_t p, const SharedPolygon& other) {
    const HemisphereCells cells(rings);
    const Vec3& n = patches.normal[p];
    Vec3 t, b;  // the cells' frame (in_cell_frame's), once for every point
    cell_frame(n, t, b);
    const auto cell_of = [&](const Vec3& dir) { return cells.cell_of(Vec3(dir.dot(t), dir.dot(b), dir.dot(n)).normalized()); };
    const Vec3* corners = other.corners;
    const std::size_t count = other.count;
    const Vec3& o = patches.centroid[p];
    const int centre = cell_of(other.centroid - o);
    bool one = !other.near;
    for (std::size_t k = 0; k < count && one; ++k)
        one = cell_of(corners[k] - o) == centre && cell_of(0.5 * (corners[k] + corners[(k + 1) % count]) - o) == centre;
    if (one) return {{centre, 1.0}};
    const double d = (other.centroid - o).norm();
    const double span = 2.0 * other.radius / std::max(d, other.radius) * rings;  // cells across, about
    const int k = std::clamp(int(std::ceil(2.0 * span)), kShareGridMin, kShareGridMax);
    std::vector<Vec3> from;
    if (other.near) {
        for (int a = 0; a < kShareGridNear; ++a)
            for (int c = 0; c < kShareGridNear; ++c)
                from.push_back(patch_point(patches, p, (a + 0.5) / kShareGridNear, (c + 0.5) / kShareGridNear));
    } else {
        from.push_back(o);
    }
    std::vector<CellShare> shares;
    double total = 0.0;
    for (int a = 0; a < k; ++a)
        for (int c = 0; c < k; ++c) {
            const Vec3 y = polygon_point(corners, count, (a + 0.5) / k, (c + 0.5) / k);
            for (const Vec3& x : from) {
                const Vec3 r = y - x;
                const double r2 = r.squaredNorm();
                const double w = std::max(0.0, r.dot(n)) * std::max(0.0, -r.dot(other.normal)) / (r2 * r2);
                if (!(w > 0.0)) continue;
                const int cell = cell_of(r);
                auto it = std::find_if(shares.begin(), shares.end(), [&](const CellShare& q) { return q.cell == cell; });
                if (it == shares.end()) shares.push_back({cell, w});
                else it->weight += w;
                total += w;
            }
        }
    if (!(total > 0.0)) return {{centre, 1.0}};
    for (CellShare& q : shares) q.weight /= total;
    std::sort(shares.begin(), shares.end(), [](const CellShare& x, const CellShare& y) { return x.cell < y.cell; });
    return shares;
}

SharedPolygon shared_patch(const PatchSet& patches, std::size_t j, double radius, bool near) {
    return {patches.polygon(j), patches.corners(j), patches.normal[j], patches.centroid[j], radius, near};
}

void glossy_pair_cells(const GlossyRows& rows, const GlossyPair& pair, std::vector<ExtraLink>& out) {
    const std::int32_t gi = rows.slot[pair.i], gj = rows.slot[pair.j];
    TPRF_CHECK(gi >= 0);
    const float late = pair.distance, early = float(std::max(0.0, double(pair.distance) - double(rows.step_m)));
    const auto sent = [&](std::uint32_t receiver, std::uint32_t source, double ff, bool to_cell) {
        out.push_back({receiver, source, float(ff), to_cell ? early : late, pair.tint});
    };
    // i's in-cells gather j (its patch row, and its out-cells facing i); j's patch row takes i's out-cells.
    for (const CellShare& q : pair.at_i) {
        const std::uint32_t in = rows.in_row(std::size_t(gi), q.cell);
        if (pair.j_sends) sent(in, std::uint32_t(pair.j), pair.f_ij * q.weight, true);
        for (const CellShare& s : pair.at_j) sent(in, rows.out_row(std::size_t(gj), s.cell), pair.f_ij * q.weight * s.weight, true);
        if (pair.j_sends && gj < 0) sent(std::uint32_t(pair.j), rows.out_row(std::size_t(gi), q.cell), pair.f_ji * q.weight, false);
    }
    // i's patch row takes j's out-cells facing it.
    if (gj >= 0 && pair.i_sends)
        for (const CellShare& s : pair.at_j) sent(std::uint32_t(pair.i), rows.out_row(std::size_t(gj), s.cell), pair.f_ij * s.weight, false);
}

namespace {

// The glossy rows' links of glossy patch g and every patch j it faces (see glossy_rows.h), each pair's
// form factor shared among the cells at either glossy end (cell_shares). A pair of glossy patches is
// made twice, once from each end's turn: each turn gives the links into its own patch's rows and, for
// a Lambertian j, j's links from its out-cells.
void glossy_pair_links(const PairScene& scene, const GlossyRows& rows, std::size_t g, std::vector<ExtraLink>& out,
                       LinkStats& counts) {
    const PatchSet& patches = scene.patches;
    const std::size_t p = rows.glossy[g];
    for (std::size_t j = 0; j < patches.size(); ++j) {
        if (j == p) continue;
        const bool glossy_j = rows.slot[j] >= 0;
        if (!glossy_j && inert(patches, j)) continue;
        PairFormFactors f;
        const bool near = near_pair(patches, scene.radius, scene.options.near_factor, p, j);
        if (!patch_pair(scene, p, j, near, f, counts)) continue;
        GlossyPair pair;
        pair.i = p;
        pair.j = j;
        pair.f_ij = f.ij;
        pair.f_ji = f.ji;
        pair.distance = float((patches.centroid[j] - patches.centroid[p]).norm());
        pair.i_sends = !inert(patches, p);
        pair.j_sends = !inert(patches, j);
        pair.at_i = cell_shares(patches, rows.rings, p, shared_patch(patches, j, scene.radius[j], near));
        if (glossy_j) pair.at_j = cell_shares(patches, rows.rings, j, shared_patch(patches, p, scene.radius[p], near));
        glossy_pair_cells(rows, pair, out);
    }
}

}  // namespace

int GlossyRows::cell_towards(const PatchSet& set, std::size_t i, const Vec3& dir) const {
    return HemisphereCells(rings).cell_of(in_cell_frame(set, i, dir));
}

void GlossyRows::cells_about(const PatchSet& set, std::size_t i, const Vec3& dir, int cell[4], double weight[4]) const {
    HemisphereCells(rings).interpolate(in_cell_frame(set, i, dir), cell, weight);
}

void GlossyRows::lobe_pulses(const PatchSet& set, std::size_t i, const Vec3& from, const Pulse& pulse,
                             const Rgb& irradiance, std::vector<std::vector<Pulse>>& cells) const {
    const std::size_t g = std::size_t(slot[i]);
    const CellReflectance& r = reflectance[set.object[i]];
    const int c_in = cell_towards(set, i, from - set.centroid[i]);
    const Rgb light = set.brdf(i)->lobe_colour() * irradiance;
    for (int c = 0; c < r.cells; ++c)
        if (const double w = r.lobe_at(c, c_in); w > 0.0) {
            Pulse q = pulse;
            q.energy = light * w;
            cells[out_row(g, c) - patches].push_back(q);
        }
}

const float* GlossyRows::lobe_of_patch(const PatchSet& set, std::size_t g) const {
    return lobe[set.object[glossy[g]]].data();
}

std::size_t GlossyRows::bytes() const {
    std::size_t b = glossy.size() * sizeof(std::uint32_t) + slot.size() * sizeof(std::int32_t) + albedo.size() * sizeof(Rgb);
    for (const CellReflectance& r : reflectance) b += (r.lobe.size() + r.base.size()) * sizeof(double);
    for (const auto& l : lobe) b += l.size() * sizeof(float);
    return b;
}

GlossyRows make_glossy_rows(const PatchSet& patches, int rings, double bin_width_m) {
    GlossyRows rows;
    rows.patches = patches.size();
    if (rings <= 0 || patches.glossy.empty()) return rows;
    rows.rings = rings;
    rows.step_m = one_bin_step(bin_width_m);
    const HemisphereCells cells(rings);
    rows.reflectance.resize(patches.glossy.size());
    rows.lobe.resize(patches.glossy.size());
    for (std::size_t k = 0; k < patches.glossy.size(); ++k)
        if (const auto& brdf = patches.glossy[k]) {
            // The lobe depends on the model, roughness and ior alone (not the colours): objects that
            // share them share its cells' reflectance.
            std::size_t same = 0;
            while (same < k && !(patches.glossy[same] && patches.glossy[same]->model == brdf->model &&
                                 patches.glossy[same]->roughness == brdf->roughness && patches.glossy[same]->ior == brdf->ior))
                ++same;
            rows.reflectance[k] =
                same < k ? rows.reflectance[same] : cell_reflectance(*brdf, cells, kCellSamples);
            const std::size_t m = std::size_t(rows.cells());
            rows.lobe[k].resize(m * m);
            for (std::size_t in = 0; in < m; ++in)
                for (std::size_t out = 0; out < m; ++out)
                    rows.lobe[k][in * m + out] = float(rows.reflectance[k].lobe[out * m + in]);
        }
    rows.slot.assign(patches.size(), -1);
    for (std::size_t i = 0; i < patches.size(); ++i)
        if (patches.brdf(i)) {
            rows.slot[i] = std::int32_t(rows.glossy.size());
            rows.glossy.push_back(std::uint32_t(i));
        }
    if (rows.glossy.empty()) return rows;
    const std::size_t m = std::size_t(rows.cells());
    rows.albedo.assign(rows.rows(), Rgb::Ones());  // in-cells: the irradiance itself
    for (std::size_t g = 0; g < rows.glossy.size(); ++g)
        std::fill_n(rows.albedo.begin() + std::ptrdiff_t(rows.glossy.size() * m + g * m), m,
                    patches.brdf(rows.glossy[g])->lobe_colour());
    return rows;
}

std::uint64_t add_glossy_links(LinkSet& set, const PatchSet& patches, const Visibility& vis,
                               const LinkOptions& options, double bin_width_m, int rings) {
    set.glossy = make_glossy_rows(patches, rings, bin_width_m);
    const GlossyRows& rows = set.glossy;
    if (rows.empty()) return 0;
    TPRF_CHECK_EQ(set.patches(), patches.size());
    insert_rows(set, patches, rows);
    const std::vector<double> radius = circumradii(patches);
    std::vector<std::vector<ExtraLink>> per(rows.glossy.size());
    parallel_for(rows.glossy.size(), {options.threads, 1, true}, [&](std::size_t g) {
        LinkStats counts;
        glossy_pair_links({patches, vis, options, radius}, rows, g, per[g], counts);
    });
    std::vector<ExtraLink> extra;
    for (auto& v : per) {
        extra.insert(extra.end(), v.begin(), v.end());
        std::vector<ExtraLink>().swap(v);
    }
    const std::uint64_t added = extra.size();
    merge_extra_links(set, extra, bin_width_m);
    return added;
}

Illumination glossy_illumination(const GlossyRows& rows, const PatchSet& patches, const LightSources& sources,
                                 const Illumination& unit) {
    const std::size_t n = patches.size(), total = n + rows.rows();
    std::vector<std::vector<Pulse>> extra(rows.rows());
    Illumination out;
    out.row.assign(total + 1, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const std::int32_t g = rows.slot.empty() ? -1 : rows.slot[i];
        for (std::uint64_t k = unit.row[i]; k < unit.row[i + 1]; ++k) {
            Pulse p = unit.pulses[k];
            if (g < 0 || !p.propagates) {  // a laser spot's own glow carries what leaves it already
                out.pulses.push_back(p);
                continue;
            }
            const Rgb irradiance = p.energy;
            if (p.order > 0) p.energy = irradiance * patches.albedo[i];
            if ((p.energy > 0.0).any()) out.pulses.push_back(p);
            if (p.order == 0) continue;
            // The source's direction: a point source's position, an area source's centroid.
            Vec3 from;
            if (p.point_source >= 0) {
                from = sources.points[std::size_t(p.point_source)].position;
            } else if (p.area_source >= 0) {
                from = sources.areas[std::size_t(p.area_source)].centroid;
            } else {
                continue;
            }
            rows.lobe_pulses(patches, i, from, p, irradiance, extra);
        }
        out.row[i + 1] = out.pulses.size();
    }
    for (std::size_t r = 0; r < rows.rows(); ++r) {
        out.pulses.insert(out.pulses.end(), extra[r].begin(), extra[r].end());
        out.row[n + r + 1] = out.pulses.size();
    }
    return out;
}

}  // namespace tprf
