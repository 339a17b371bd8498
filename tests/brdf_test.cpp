// The glossy BRDF (transport/brdf.h) against what fixes it in advance: the GGX distribution's
// normalisation, the identity that defines Smith's masking, Fresnel's closed forms, reciprocity, the
// formula written in its tangent form, and the directional albedo integrated independently over the
// incoming hemisphere.

#include "tprf/transport/brdf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace {

using tprf::GlossyBrdf;
using tprf::GlossyModel;
using tprf::Rgb;
using tprf::Vec3;

constexpr double kPi = std::numbers::pi;
const Vec3 kNormal(0.0, 0.0, 1.0);

// Integral over the hemisphere of half vectors of g(theta_h, phi_h) dw_h, by the midpoint rule in
// x with tan(theta_h) = alpha tan(pi x / 2) (nodes where the lobe is) and in phi.
template <class G>
double over_half_vectors(double alpha, int radial, int azimuthal, G g) {
    double sum = 0.0;
    for (int a = 0; a < radial; ++a) {
        const double x = (a + 0.5) / radial, t = std::tan(0.5 * kPi * x);
        const double theta = std::atan(alpha * t);
        // d theta / dx = alpha (pi / 2) sec^2(pi x / 2) / (1 + alpha^2 t^2)
        const double jacobian = alpha * 0.5 * kPi * (1.0 + t * t) / (1.0 + alpha * alpha * t * t);
        for (int b = 0; b < azimuthal; ++b) {
            const double phi = 2.0 * kPi * (b + 0.5) / azimuthal;
            sum += g(theta, phi) * std::sin(theta) * jacobian;
        }
    }
    return sum * (1.0 / radial) * (2.0 * kPi / azimuthal);
}

TEST(Brdf, GgxDistributionProjectsToOne) {
    // integral of D(h) cos_h over the hemisphere is 1 for every roughness (the distribution's definition).
    for (double alpha : {0.01, 0.05, 0.2, 0.5, 1.0}) {
        const double total = over_half_vectors(alpha, 20000, 1, [&](double theta, double) {
            return tprf::ggx_distribution(alpha, std::cos(theta)) * std::cos(theta);
        });
        EXPECT_NEAR(total, 1.0, 1e-6) << "alpha " << alpha;
    }
}

TEST(Brdf, SmithMaskingProjectsTheVisibleNormalsOntoTheView) {
    // Smith's G1 is defined by: integral of G1(wo) max(0, wo.h) D(h) dw_h = cos_o.
    for (double alpha : {0.05, 0.2, 0.5, 1.0}) {
        for (double cos_o : {1.0, 0.8, 0.4, 0.1}) {
            const Vec3 wo(std::sqrt(1.0 - cos_o * cos_o), 0.0, cos_o);
            const double projected = over_half_vectors(alpha, 2000, 720, [&](double theta, double phi) {
                const Vec3 h(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
                return std::max(0.0, wo.dot(h)) * tprf::ggx_distribution(alpha, std::cos(theta));
            });
            // The midpoint rule in phi is second order across the kink where wo.h changes sign.
            EXPECT_NEAR(tprf::smith_g1(alpha, cos_o) * projected, cos_o, 2e-5 * (1.0 + 1.0 / cos_o))
                << "alpha " << alpha << " cos_o " << cos_o;
        }
    }
}

TEST(Brdf, FresnelMeetsItsClosedForms) {
    const double n = 1.5;
    EXPECT_NEAR(tprf::fresnel_dielectric(1.0, n), std::pow((n - 1.0) / (n + 1.0), 2), 1e-15);
    // At Brewster's angle the p-polarised part vanishes: F = Rs / 2, Rs = ((n^2 - 1) / (n^2 + 1))^2.
    const double brewster = std::atan(n);
    EXPECT_NEAR(tprf::fresnel_dielectric(std::cos(brewster), n), 0.5 * std::pow((n * n - 1.0) / (n * n + 1.0), 2), 1e-14);
    EXPECT_NEAR(tprf::fresnel_dielectric(1e-9, n), 1.0, 1e-8);
}

// D and G1 as the scene reference writes them, in tangents.
double d_tangent_form(double a, double cos_h) {
    const double t2 = (1.0 - cos_h * cos_h) / (cos_h * cos_h);
    return a * a / (kPi * std::pow(cos_h, 4) * std::pow(a * a + t2, 2));
}
double g1_tangent_form(double a, double cos_w) {
    const double t2 = (1.0 - cos_w * cos_w) / (cos_w * cos_w);
    return 2.0 / (1.0 + std::sqrt(1.0 + a * a * t2));
}

TEST(Brdf, EvaluatesTheFormulaOfBothModels) {
    const Vec3 wi = Vec3(0.3, -0.2, 0.9).normalized(), wo = Vec3(-0.5, 0.1, 0.7).normalized();
    const Vec3 h = (wi + wo).normalized();
    const double a = 0.2, ci = wi.z(), co = wo.z();
    const double lobe = d_tangent_form(a, h.z()) * g1_tangent_form(a, ci) * g1_tangent_form(a, co) / (4 * ci * co);

    GlossyBrdf glossy{GlossyModel::Glossy, Rgb(0.1, 0.2, 0.3), Rgb(0.7, 0.6, 0.5), a, 1.5};
    const Rgb f = glossy.eval(kNormal, wi, wo);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[c], glossy.albedo[c] / kPi + glossy.reflectance[c] * lobe, 1e-12 * f[c]);

    GlossyBrdf plastic{GlossyModel::Plastic, Rgb(0.6, 0.4, 0.2), Rgb::Zero(), a, 1.5};
    const double fi = tprf::fresnel_dielectric(ci, 1.5), fo = tprf::fresnel_dielectric(co, 1.5);
    const double fh = tprf::fresnel_dielectric(wi.dot(h), 1.5);
    const Rgb p = plastic.eval(kNormal, wi, wo);
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(p[c], fh * lobe + (1 - fi) * (1 - fo) * plastic.albedo[c] / kPi, 1e-12 * p[c]);

    // Nothing below the surface, from either side.
    EXPECT_EQ(glossy.eval(kNormal, Vec3(0.3, 0.0, -0.95).normalized(), wo).maxCoeff(), 0.0);
    EXPECT_EQ(plastic.eval(kNormal, wi, Vec3(0.3, 0.0, -0.95).normalized()).maxCoeff(), 0.0);
}

TEST(Brdf, IsReciprocal) {
    std::mt19937_64 random(7);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const GlossyBrdf plastic{GlossyModel::Plastic, Rgb(0.5, 0.5, 0.5), Rgb::Zero(), 0.3, 1.7};
    const GlossyBrdf glossy{GlossyModel::Glossy, Rgb(0.2, 0.2, 0.2), Rgb(0.6, 0.6, 0.6), 0.05, 1.5};
    for (int k = 0; k < 200; ++k) {
        const Vec3 wi = Vec3(u(random), u(random), std::abs(u(random)) + 0.01).normalized();
        const Vec3 wo = Vec3(u(random), u(random), std::abs(u(random)) + 0.01).normalized();
        for (const GlossyBrdf* b : {&plastic, &glossy}) {
            const double forward = b->eval(kNormal, wi, wo)[0], backward = b->eval(kNormal, wo, wi)[0];
            EXPECT_NEAR(forward, backward, 1e-12 * forward);
        }
    }
}

// The directional albedo by brute force over wi, in a frame about wo's mirror direction so that even
// a narrow lobe gets nodes: wi at angle beta from the mirror direction, beta = pi x^3.
Rgb albedo_over_incoming_directions(const GlossyBrdf& brdf, double cos_o) {
    const double sin_o = std::sqrt(1.0 - cos_o * cos_o);
    const Vec3 wo(sin_o, 0.0, cos_o), r(-sin_o, 0.0, cos_o);
    const Vec3 t1 = r.unitOrthogonal(), t2 = r.cross(t1);
    const int radial = 1500, azimuthal = 720;
    Rgb sum = Rgb::Zero();
    for (int a = 0; a < radial; ++a) {
        const double x = (a + 0.5) / radial, beta = kPi * x * x * x, jacobian = 3.0 * kPi * x * x;
        for (int b = 0; b < azimuthal; ++b) {
            const double gamma = 2.0 * kPi * (b + 0.5) / azimuthal;
            const Vec3 wi = std::cos(beta) * r + std::sin(beta) * (std::cos(gamma) * t1 + std::sin(gamma) * t2);
            if (wi.z() <= 0.0) continue;
            sum += brdf.eval(kNormal, wi, wo) * (wi.z() * std::sin(beta) * jacobian);
        }
    }
    return sum * (1.0 / radial) * (2.0 * kPi / azimuthal);
}

TEST(Brdf, DirectionalAlbedoMatchesAnIntegralOverIncomingDirections) {
    for (GlossyModel model : {GlossyModel::Glossy, GlossyModel::Plastic}) {
        for (double alpha : {0.05, 0.2, 0.5}) {
            const GlossyBrdf brdf{model, Rgb(0.3, 0.3, 0.3), Rgb(0.7, 0.7, 0.7), alpha, 1.5};
            for (double cos_o : {1.0, 0.6, 0.2}) {
                const double reference = albedo_over_incoming_directions(brdf, cos_o)[0];
                EXPECT_NEAR(brdf.directional_albedo(cos_o)[0], reference, 2e-4 * reference)
                    << (model == GlossyModel::Glossy ? "glossy" : "plastic") << " alpha " << alpha << " cos_o " << cos_o;
            }
        }
    }
}

TEST(Brdf, NeverReflectsMoreThanArrives) {
    // albedo + reflectance = 1 (glossy) and a white base (plastic): the directional albedo stays under 1,
    // the lobe's single scattering losing what Smith's masking removes; a Lambertian glossy is its albedo.
    const GlossyBrdf lambertian{GlossyModel::Glossy, Rgb(0.8, 0.5, 0.2), Rgb::Zero(), 0.3, 1.5};
    for (double cos_o : {1.0, 0.5, 0.05}) {
        for (double alpha : {0.01, 0.1, 0.5, 1.0}) {
            const GlossyBrdf glossy{GlossyModel::Glossy, Rgb::Constant(0.2), Rgb::Constant(0.8), alpha, 1.5};
            const GlossyBrdf plastic{GlossyModel::Plastic, Rgb::Constant(1.0), Rgb::Zero(), alpha, 1.5};
            EXPECT_LE(glossy.directional_albedo(cos_o)[0], 1.0);
            EXPECT_LE(plastic.directional_albedo(cos_o)[0], 1.0);
        }
        const Rgb a = lambertian.directional_albedo(cos_o);
        for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(a[c], lambertian.albedo[c]);
    }
    // A smooth lobe seen head-on keeps nearly everything: 1 - albedo at alpha 0.01 is its masking loss.
    const GlossyBrdf smooth{GlossyModel::Glossy, Rgb::Zero(), Rgb::Constant(1.0), 0.01, 1.5};
    EXPECT_NEAR(smooth.directional_albedo(1.0)[0], 1.0, 1e-3);
}

}  // namespace
