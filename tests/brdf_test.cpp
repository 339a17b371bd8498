// The glossy BRDF (transport/brdf.h) against what fixes it in advance: the GGX distribution's
// normalisation, the identity that defines Smith's masking, Fresnel's closed forms, reciprocity, the
// formula written in its tangent form, and the directional albedo integrated independently over the
// incoming hemisphere.

#include "tprf/scene/brdf.h"

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

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

TEST(HemisphereCells, CutTheDiskIntoCellsOfEqualProjectedSolidAngle) {
    for (int rings : {1, 2, 4, 8}) {
        const tprf::HemisphereCells cells(rings);
        const int m = cells.count();
        ASSERT_EQ(m, 4 * rings * rings);
        // Every cell's own points fall in it.
        for (int c = 0; c < m; ++c)
            for (double u : {0.01, 0.5, 0.99})
                for (double v : {0.01, 0.5, 0.99}) ASSERT_EQ(cells.cell_of(cells.direction(c, u, v)), c);
        // Projected solid angle is area on the unit disk: a fine grid over the disk gives each cell pi / M.
        const int n = 1200;
        std::vector<double> area(std::size_t(m), 0.0);
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                const double x = -1.0 + (2.0 * i + 1.0) / n, y = -1.0 + (2.0 * j + 1.0) / n;
                if (x * x + y * y >= 1.0) continue;
                area[std::size_t(cells.cell_of(Vec3(x, y, std::sqrt(1.0 - x * x - y * y))))] += 4.0 / (double(n) * n);
            }
        // The grid's error is its cells along each cell's edges: about 4 / n of the disk's width per edge.
        for (int c = 0; c < m; ++c) EXPECT_NEAR(area[std::size_t(c)], kPi / m, 12.0 * rings / n * kPi / m) << "cell " << c;
    }
}

// The lobe's part as a matrix (out, in), made here so that it is allocated and freed in this program.
Eigen::MatrixXd lobe_matrix(const tprf::CellReflectance& r) {
    Eigen::MatrixXd m(r.cells, r.cells);
    for (int o = 0; o < r.cells; ++o)
        for (int i = 0; i < r.cells; ++i) m(o, i) = r.lobe_at(o, i);
    return m;
}

// M times the lobe's directional albedo averaged over cell c's sample directions, by directional_albedo.
double mean_lobe_albedo(const GlossyBrdf& brdf, const tprf::HemisphereCells& cells, int c, int samples) {
    GlossyBrdf lobe = brdf;
    lobe.albedo = Rgb::Zero();
    lobe.reflectance = Rgb::Ones();
    double sum = 0.0;
    for (int a = 0; a < samples; ++a)
        for (int b = 0; b < samples; ++b)
            sum += lobe.directional_albedo(cells.direction(c, (a + 0.5) / samples, (b + 0.5) / samples).z())[0];
    return cells.count() * sum / (samples * samples);
}

TEST(CellReflectance, EachCellReflectsWhatItsDirectionalAlbedoSays) {
    const tprf::HemisphereCells cells(3);
    for (GlossyModel model : {GlossyModel::Glossy, GlossyModel::Plastic}) {
        for (double alpha : {0.05, 0.3}) {
            const GlossyBrdf brdf{model, Rgb::Zero(), Rgb::Ones(), alpha, 1.5};
            const Eigen::MatrixXd r = lobe_matrix(tprf::cell_reflectance(brdf, cells, 2));
            for (int c = 0; c < cells.count(); ++c) {
                const double expected = mean_lobe_albedo(brdf, cells, c, 2);
                EXPECT_NEAR(r.col(c).sum(), expected, 2e-4 * expected) << "alpha " << alpha << " cell " << c;
                EXPECT_GE(r.col(c).minCoeff(), 0.0);
            }
        }
    }
}

// The share of each cell's reflected light that leaves through a cell other than its mirror cell.
std::vector<double> leaks(double alpha, const tprf::HemisphereCells& cells) {
    const GlossyBrdf brdf{GlossyModel::Glossy, Rgb::Zero(), Rgb::Ones(), alpha, 1.5};
    const Eigen::MatrixXd r = lobe_matrix(tprf::cell_reflectance(brdf, cells, 2));
    std::vector<double> out;
    for (int c = 0; c < cells.count(); ++c) {
        // The mirror direction of (r, phi) is (r, phi + pi): the same ring, half its sectors on.
        const int k = int(std::sqrt(c / 4.0)), sectors = 4 * (2 * k + 1);
        const int mirror = 4 * k * k + (c - 4 * k * k + sectors / 2) % sectors;
        out.push_back(1.0 - r(mirror, c) / r.col(c).sum());
    }
    return out;
}

TEST(CellReflectance, ASmoothLobeSendsEachCellToItsMirrorCell) {
    // GGX's long tail sends a little of a smooth lobe's light past the mirror cell's edges; less the
    // smoother the lobe.
    const tprf::HemisphereCells cells(4);
    const std::vector<double> smooth = leaks(0.01, cells), rougher = leaks(0.03, cells);
    for (int c = 0; c < cells.count(); ++c) {
        EXPECT_LT(smooth[std::size_t(c)], 0.1) << "cell " << c;
        EXPECT_LT(smooth[std::size_t(c)], rougher[std::size_t(c)]) << "cell " << c;
    }
}

TEST(CellReflectance, PlacesTheLightAsAnIntegralOverTheDiskOfOutgoingDirections) {
    // Projected solid angle is area on the unit disk, so the integral over cell c of f(wi, wo) cos_o dwo
    // is the integral of f over c's part of the disk: a fine grid of the disk, per incoming direction.
    const tprf::HemisphereCells cells(2);
    const GlossyBrdf brdf{GlossyModel::Plastic, Rgb::Zero(), Rgb::Zero(), 0.2, 1.5};
    const Eigen::MatrixXd r = lobe_matrix(tprf::cell_reflectance(brdf, cells, 1));
    const int m = cells.count(), n = 1000;
    for (int c = 0; c < m; ++c) {
        const Vec3 wi = cells.direction(c, 0.5, 0.5);
        Eigen::VectorXd column = Eigen::VectorXd::Zero(m);
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                const double x = -1.0 + (2.0 * i + 1.0) / n, y = -1.0 + (2.0 * j + 1.0) / n;
                if (x * x + y * y >= 1.0) continue;
                const Vec3 wo(x, y, std::sqrt(1.0 - x * x - y * y));
                column[cells.cell_of(wo)] += brdf.lobe(kNormal, wi, wo) * 4.0 / (double(n) * n);
            }
        column *= m;  // one sample carries the whole cell: weight M
        // The grid's error is at the cells' edges and the horizon: 0.3% of the column's light.
        for (int o = 0; o < m; ++o) EXPECT_NEAR(r(o, c), column[o], 3e-3 * column.sum()) << "cells " << o << ", " << c;
    }
}

TEST(CellReflectance, IsReciprocalAsTheBrdf) {
    // f(wi, wo) = f(wo, wi) makes R symmetric for equal cells; what is left is the placing of each
    // incoming cell's few sample directions, which shrinks as the samples grow.
    const tprf::HemisphereCells cells(2);
    const GlossyBrdf rough{GlossyModel::Plastic, Rgb::Zero(), Rgb::Zero(), 0.5, 1.5};
    double previous = 1e9;
    for (int samples : {1, 2, 4}) {
        const Eigen::MatrixXd lobe = lobe_matrix(tprf::cell_reflectance(rough, cells, samples));
        const double asymmetry = (lobe - lobe.transpose()).cwiseAbs().maxCoeff() / lobe.maxCoeff();
        EXPECT_LT(asymmetry, previous);
        previous = asymmetry;
    }
    EXPECT_LT(previous, 0.01);
}

TEST(CellReflectance, ThePlasticBaseIsTheCoatsTransmissionBothWays) {
    // The mean of 1 - F over the hemisphere, in projected solid angle, for a dielectric of index 1.5 is
    // 1 - 0.0917780 (its diffuse reflectance, 2 x integral of F(mu) mu over (0, 1)).
    const tprf::HemisphereCells cells(4);
    const GlossyBrdf plastic{GlossyModel::Plastic, Rgb(0.6, 0.4, 0.2), Rgb::Zero(), 0.2, 1.5};
    const tprf::CellReflectance r = tprf::cell_reflectance(plastic, cells, 1);
    double mean = 0.0;
    for (double b : r.base) mean += b / r.cells;
    EXPECT_NEAR(mean, 1.0 - 0.0917780, 1e-6);
    EXPECT_NEAR(r.at(plastic, 0, 5, 9), r.lobe_at(5, 9) + 0.6 * r.base[5] * r.base[9], 1e-15);
    // A Lambertian glossy surface sends each cell's light to every cell alike: R = albedo everywhere.
    const GlossyBrdf matte{GlossyModel::Glossy, Rgb(0.5, 0.5, 0.5), Rgb::Zero(), 0.2, 1.5};
    const tprf::CellReflectance grey = tprf::cell_reflectance(matte, cells, 1);
    for (int o = 0; o < grey.cells; ++o)
        for (int i = 0; i < grey.cells; ++i) ASSERT_NEAR(grey.at(matte, 1, o, i), 0.5, 1e-15);
}

}  // namespace
