#pragma once
/// Glossy reflectance: a GGX microfacet lobe with Smith masking over a Lambertian part, the reflectance
/// of a `glossy` or `plastic` material (docs/materials.md, "Glossy surfaces"). Directions point away
/// from the surface and are unit vectors; `n` is the side's normal (the caller flips it for the back of
/// a two-sided object). Every function is pure.

#include "tprf/core/types.h"

#include <vector>

namespace tprf {

/// The GGX (Trowbridge-Reitz) distribution of normals of roughness `alpha` (> 0) at a half vector whose
/// cosine with the normal is `cos_h`, per steradian: alpha^2 / (pi cos_h^4 (alpha^2 + tan_h^2)^2).
/// Normalised so that its projected integral over the hemisphere is 1. 0 for cos_h <= 0.
double ggx_distribution(double alpha, double cos_h);

/// Smith's masking for GGX in the direction whose cosine with the normal is `cos_w`:
/// 2 / (1 + sqrt(1 + alpha^2 tan_w^2)); 0 for cos_w <= 0.
double smith_g1(double alpha, double cos_w);

/// The unpolarised Fresnel reflectance of light meeting a dielectric of relative index `ior` (> 1, from
/// the outside) at an angle whose cosine is `cos_i` in (0, 1].
double fresnel_dielectric(double cos_i, double ior);

/// Which glossy model a surface follows.
enum class GlossyModel {
    /// albedo/pi + reflectance D G1(wi) G1(wo) / (4 cos_i cos_o): a constant Fresnel term (a rough metal).
    Glossy,
    /// F(wi.h) D G1(wi) G1(wo) / (4 cos_i cos_o) + (1 - F(cos_i)) (1 - F(cos_o)) albedo/pi: a dielectric
    /// coat of index `ior` over a Lambertian base (a rough plastic).
    Plastic,
};

/// A glossy surface's reflectance, per colour channel.
struct GlossyBrdf {
    GlossyModel model = GlossyModel::Glossy;
    Rgb albedo = Rgb::Zero();       ///< the Lambertian part's albedo, in [0, 1]
    Rgb reflectance = Rgb::Zero();  ///< Glossy: the lobe's constant Fresnel term, in [0, 1]; unused by Plastic
    double roughness = 0.1;         ///< GGX alpha, in [0.01, 1]
    double ior = 1.5;               ///< Plastic: the coat's index, > 1; unused by Glossy

    /// f(wi, wo) per steradian; 0 unless both directions lie in front of `n`.
    Rgb eval(const Vec3& n, const Vec3& wi, const Vec3& wo) const;
    /// The lobe's part of f alone (no Lambertian term), per steradian, per unit of reflectance for
    /// Glossy (the Fresnel factor included for Plastic).
    double lobe(const Vec3& n, const Vec3& wi, const Vec3& wo) const;
    /// The colour the lobe is scaled by: `reflectance` (Glossy), white (Plastic).
    Rgb lobe_colour() const { return model == GlossyModel::Glossy ? reflectance : Rgb::Ones(); }
    /// The Lambertian part of f per unit of albedo, per steradian: 1 / pi (Glossy), or (Plastic)
    /// (1 - F(cos_i)) (1 - F(cos_o)) / pi. So f = albedo base + lobe_colour lobe.
    double base(const Vec3& n, const Vec3& wi, const Vec3& wo) const;
    /// The directional albedo: the integral of f(wi, wo) cos_i over the hemisphere of wi, for a wo whose
    /// cosine with the normal is `cos_o` in (0, 1]. By reciprocity, also the share of light arriving
    /// from wo that the surface reflects. The lobe is integrated over its own half vectors (Gauss-Legendre
    /// in the GGX distribution's cumulative measure and in azimuth), the plastic base over cos_i.
    Rgb directional_albedo(double cos_o) const;
    /// The share of light arriving from the whole hemisphere with a uniform radiance (as a Lambertian
    /// surface sends it) that the surface reflects: directional_albedo averaged with weight 2 cos_o.
    Rgb hemispherical_albedo() const;
};

struct Object;

/// A glossy object's reflectance (Object::material.glossy()): its albedo, reflectance, roughness, ior.
GlossyBrdf glossy_brdf(const Object& o);

/// The hemisphere above a surface cut into M = 4 R^2 cells of equal projected solid angle (pi / M each):
/// the unit disk below it (x = sin(theta) cos(phi), y = sin(theta) sin(phi)) cut into R rings of equal
/// width, ring k into 4 (2k + 1) equal sectors, so that every cell is about 1/R of the disk across. The
/// directional resolution of light leaving or reaching a glossy patch, in the patch's own frame (z
/// along its normal).
class HemisphereCells {
public:
    /// `rings` R >= 1.
    explicit HemisphereCells(int rings);
    int rings() const { return m_rings; }
    /// M = 4 R^2.
    int count() const { return 4 * m_rings * m_rings; }
    /// The cell holding a direction of the frame (z > 0; z <= 0 is taken as the horizon's ring).
    int cell_of(const Vec3& local) const;
    /// The cells about a direction of the frame and their weights (summing to 1), to read a quantity
    /// held per cell (at the cell's middle) smoothly: linear between the two nearest rings' middles
    /// (radius sin(theta)) and, within each ring, between its two nearest sectors' middles (azimuth).
    /// Writes 4 cells and weights (a cell may repeat).
    void interpolate(const Vec3& local, int cell[4], double weight[4]) const;
    /// The direction at fractional coordinates (u, v) in [0, 1)^2 of a cell: u across its ring, v along
    /// its sector, both uniform in projected solid angle.
    Vec3 direction(int cell, double u, double v) const;

private:
    int m_rings;
};

/// What a glossy surface does between its cells, as two parts that the materials' colours scale:
/// for a channel with albedo a and reflectance r, R = r lobe + a base base^T (Glossy) or
/// R = lobe + a base base^T (Plastic). R (M x M) maps the irradiance E(c') arriving through cell c' with a
/// radiance uniform over it to pi times the mean radiance leaving through cell c (weighted by projected
/// solid angle): pi L(c) = sum over c' of R(c, c') E(c'). So column c' of R adds up to M times the share of
/// the light arriving through c' that leaves, the directional albedo averaged over the cell.
/// (Plain vectors, not Eigen's dynamic matrices: those allocate with the alignment of the instruction
/// set they are compiled for, which a program built without the library's -march does not share.)
struct CellReflectance {
    int cells = 0;  ///< M
    /// The lobe's part (Glossy: per unit reflectance; Plastic: with its Fresnel factor), M x M by
    /// outgoing cell then incoming cell: lobe[out * M + in]. Each of the samples^2 incoming directions of
    /// a cell has its reflection integrated over its half vectors as `directional_albedo` integrates it,
    /// and binned by the cell it leaves through.
    std::vector<double> lobe;
    /// The Lambertian part's factor per cell (M): 1 (Glossy), or the mean of 1 - F over the cell in
    /// projected solid angle (Plastic: light crosses the coat on the way in and on the way out).
    std::vector<double> base;

    /// The lobe's part from cell `in` to cell `out`.
    double lobe_at(int out, int in) const { return lobe[std::size_t(out) * std::size_t(cells) + std::size_t(in)]; }
    /// R(out, in) for channel `c` of `brdf`.
    double at(const GlossyBrdf& brdf, int c, int out, int in) const;
};

/// A glossy patch's albedo in a transport with directional cells of `rings` rings (its patch row,
/// transport/glossy_rows.h): the Lambertian part's, `albedo` (Glossy) or `albedo` times the square of
/// the base's mean over the cells (Plastic: the coat's 1 - F on the way in and out, each averaged).
Rgb lambertian_part_albedo(const GlossyBrdf& brdf, int rings);

/// The cells' reflectance of `brdf` (its model, roughness and ior; not its colours), with `samples` >= 1
/// incoming directions per side of a cell.
CellReflectance cell_reflectance(const GlossyBrdf& brdf, const HemisphereCells& cells, int samples);

}  // namespace tprf
