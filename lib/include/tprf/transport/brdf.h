#pragma once
/// Glossy reflectance: a GGX microfacet lobe with Smith masking over a Lambertian part (docs/materials.md,
/// "Glossy surfaces"). Directions point away from the surface and are unit vectors; `n` is the side's
/// normal (the caller flips it for the back of a two-sided object). Every function is pure.

#include "tprf/core/types.h"

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
    /// The directional albedo: the integral of f(wi, wo) cos_i over the hemisphere of wi, for a wo whose
    /// cosine with the normal is `cos_o` in (0, 1]. By reciprocity, also the share of light arriving
    /// from wo that the surface reflects. The lobe is integrated over its own half vectors (Gauss-Legendre
    /// in the GGX distribution's cumulative measure and in azimuth), the plastic base over cos_i.
    Rgb directional_albedo(double cos_o) const;
};

}  // namespace tprf
