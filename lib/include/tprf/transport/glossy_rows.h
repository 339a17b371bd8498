#pragma once
/// The directional light of glossy patches in the march: rows of the solver beside the patches' own.
///
/// A glossy patch p keeps its patch row for the Lambertian part of its BRDF (its `albedo` there, the
/// base's mean for a plastic) and gets 2 M more rows, M = 4 R^2 cells of equal projected solid angle
/// over its hemisphere (HemisphereCells, R = links.glossy_resolution):
///  - in-cell rows I(p, c'): the irradiance arriving through cell c', one patch link from every patch
///    that p sees (the light leaving a glossy source towards p read from its out-cell facing p);
///  - out-cell rows O(p, c): pi times the mean radiance leaving through cell c, the lobe's part of the
///    BRDF over the cells: O(p, c) = lobe_colour sum_c' lobe(c, c') I(p, c') (CellReflectance), applied
///    by the march (and the steady solve) as one M x M product per patch and bin, not as links.
/// Every receiver that sees p takes p's patch row (as before) and the out-cell facing it, at the pair's
/// distance. So a path keeps its length: an in-cell gathers its links one bin early (each link's
/// distance less `step_m`, one bin) and the out-cell reads it one bin later; light between patches less
/// than a bin apart arrives one bin after it left instead of within that bin. Rows are numbered
/// after the patches: the in-cells of every glossy patch, then the out-cells (out-cells gather from
/// in-cells only, so a bounce-order march reads them from the same order, LinkSet::out_rows).

#include "tprf/core/types.h"
#include "tprf/scene/brdf.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tprf {

struct PatchSet;
struct Illumination;
struct Pulse;
struct LightSources;

struct GlossyRows {
    std::size_t patches = 0;              ///< N: the rows start after the patches'
    int rings = 0;                        ///< R (0: no glossy rows)
    std::vector<std::uint32_t> glossy;    ///< the glossy patches, increasing
    std::vector<std::int32_t> slot;       ///< per patch: its index in `glossy`, or -1 (empty: none glossy)
    std::vector<Rgb> albedo;              ///< per row after the patches: what the march multiplies its gathered light by
    /// Per object (PatchSet::glossy's order): the cells' lobe, out-cell by in-cell (cell_reflectance,
    /// 4 x 4 incoming directions per cell); empty for other objects.
    std::vector<CellReflectance> reflectance;
    /// The same lobes in single precision, as the march applies them, per object, in-cell by in-cell:
    /// lobe[object][in * M + out]. (Dense: even at roughness 0.1 and R = 4 the out-cells that carry 99% of an in-cell's
    /// reflection are two thirds of them, GGX's tails and the in-cells' spread of directions.)
    std::vector<std::vector<float>> lobe;
    float step_m = 0.0f;                  ///< the in-cell to out-cell delay, metres: one bin

    bool empty() const { return glossy.empty(); }
    /// M = 4 R^2.
    int cells() const { return 4 * rings * rings; }
    /// Rows after the patches: 2 M per glossy patch.
    std::size_t rows() const { return glossy.size() * 2 * std::size_t(cells()); }
    /// The first out-cell row: every row from here to patches + rows() is an out-cell.
    std::size_t out_begin() const { return patches + glossy.size() * std::size_t(cells()); }
    std::uint32_t in_row(std::size_t g, int c) const {
        return std::uint32_t(patches + g * std::size_t(cells()) + std::size_t(c));
    }
    std::uint32_t out_row(std::size_t g, int c) const { return std::uint32_t(out_begin() + g * std::size_t(cells()) + std::size_t(c)); }
    /// The cell of glossy patch `i` (slot[i] >= 0) that the direction `dir` (world, any length) leaves
    /// or arrives through.
    int cell_towards(const PatchSet& set, std::size_t i, const Vec3& dir) const;
    /// The cells of glossy patch `i` about the direction `dir` (world) with their weights, as
    /// HemisphereCells::interpolate: what the camera reads along its view.
    void cells_about(const PatchSet& set, std::size_t i, const Vec3& dir, int cell[4], double weight[4]) const;
    /// Glossy row i's patch's in-cells (i an out-cell: out_begin() <= i < patches + rows()): the first
    /// in-cell's row.
    std::uint32_t first_in_of(std::size_t i) const {
        return std::uint32_t(patches + (i - out_begin()) / std::size_t(cells()) * std::size_t(cells()));
    }
    /// Glossy patch g's lobe (`lobe`'s layout).
    const float* lobe_of_patch(const PatchSet& set, std::size_t g) const;
    /// Glossy patch i's share of a pulse that brings `irradiance` from the point `from`: one pulse per
    /// out-cell the lobe reaches from the cell facing `from`, appended to cells[out_row - patches]
    /// (`pulse` gives their time, order and source).
    void lobe_pulses(const PatchSet& set, std::size_t i, const Vec3& from, const Pulse& pulse, const Rgb& irradiance,
                     std::vector<std::vector<Pulse>>& cells) const;
    /// Bytes held.
    std::size_t bytes() const;
};

/// The frame of a glossy patch's cells: two unit tangents, with the normal right-handed.
void cell_frame(const Vec3& normal, Vec3& t, Vec3& b);

/// The rows of the glossy patches of `patches` (PatchSet::glossy) at `rings` rings (links.glossy_resolution),
/// the in-to-out step one bin of `bin_width_m`; none when `rings` is 0 or no patch is glossy.
GlossyRows make_glossy_rows(const PatchSet& patches, int rings, double bin_width_m);

/// Where the direct light of the sources (pulses computed with every glossy patch's albedo taken as 1,
/// so that they carry its irradiance) goes with glossy rows: a glossy patch's reflected pulses to its
/// patch row times its Lambertian albedo (patches.albedo), and, for light from a point or area source,
/// to its out-cells through the lobe from the source's direction; a laser spot's glow on its own patch
/// (a pulse that does not propagate) as it is. Returns the illumination of every row.
Illumination glossy_illumination(const GlossyRows& rows, const PatchSet& patches, const LightSources& sources,
                                 const Illumination& unit);

}  // namespace tprf
