#include "tprf/scene/brdf.h"

#include "tprf/scene/scene.h"
#include "tprf/core/parallel.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace tprf {
namespace {

constexpr double kPi = std::numbers::pi;

// tan^2 of the angle whose cosine is c (0 < c <= 1).
double tan2(double c) { return std::max(0.0, 1.0 - c * c) / (c * c); }

// Gauss-Legendre nodes and weights on [0, 1], n points (Newton on the Legendre polynomial's roots).
struct Quadrature {
    std::vector<double> x, w;
};

Quadrature gauss_legendre01(int n) {
    Quadrature q{std::vector<double>(std::size_t(n)), std::vector<double>(std::size_t(n))};
    for (int i = 0; i < n; ++i) {
        double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), dp = 1.0;
        for (int iteration = 0; iteration < 100; ++iteration) {
            double p0 = 1.0, p1 = 0.0;
            for (int k = 1; k <= n; ++k) {
                const double p2 = p1;
                p1 = p0;
                p0 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p2) / k;
            }
            dp = n * (z * p0 - p1) / (z * z - 1.0);
            const double step = p0 / dp;
            z -= step;
            if (std::abs(step) < 1e-15) break;
        }
        q.x[std::size_t(i)] = 0.5 * (1.0 - z);
        q.w[std::size_t(i)] = 1.0 / ((1.0 - z * z) * dp * dp);
    }
    return q;
}

const Quadrature& rule(int n) {
    static const std::array<Quadrature, 2> rules{gauss_legendre01(128), gauss_legendre01(256)};
    return n == 128 ? rules[0] : rules[1];
}

// The lobe's directional albedo per unit of reflectance (Glossy) or with its Fresnel factor (Plastic),
// in wo's frame: the half vector h drawn by its GGX measure D cos_h dw_h = dxi dphi / (2 pi) with
// tan^2 theta_h = alpha^2 xi / (1 - xi); wi = reflect(wo, h); f cos_i dw_i = F D G1 G1 (wo.h) / cos_o dw_h.
double lobe_albedo(const GlossyBrdf& brdf, double cos_o) {
    const double alpha = brdf.roughness, sin_o = std::sqrt(std::max(0.0, 1.0 - cos_o * cos_o));
    const Vec3 wo(sin_o, 0.0, cos_o);
    const Quadrature& radial = rule(256);
    const Quadrature& azimuth = rule(128);
    const double g1_o = smith_g1(alpha, cos_o);
    double sum = 0.0;
    for (std::size_t a = 0; a < radial.x.size(); ++a) {
        const double xi = radial.x[a];
        const double cos_h = 1.0 / std::sqrt(1.0 + alpha * alpha * xi / (1.0 - xi));
        const double sin_h = std::sqrt(std::max(0.0, 1.0 - cos_h * cos_h));
        double ring = 0.0;
        for (std::size_t b = 0; b < azimuth.x.size(); ++b) {
            // Azimuth over [0, pi] twice: the integrand is even in phi.
            const double phi = kPi * azimuth.x[b];
            const Vec3 h(sin_h * std::cos(phi), sin_h * std::sin(phi), cos_h);
            const double o_h = wo.dot(h);
            if (o_h <= 0.0) continue;
            const double cos_i = 2.0 * o_h * cos_h - cos_o;
            if (cos_i <= 0.0) continue;
            const double fresnel = brdf.model == GlossyModel::Plastic ? fresnel_dielectric(o_h, brdf.ior) : 1.0;
            ring += azimuth.w[b] * fresnel * smith_g1(alpha, cos_i) * o_h / cos_h;
        }
        sum += radial.w[a] * ring;
    }
    return sum * g1_o / cos_o;
}

// 2 * integral over mu in (0, 1] of (1 - F(mu)) mu: the share of a uniform radiance that enters the coat.
double entering_share(double ior) {
    const Quadrature& q = rule(256);
    double sum = 0.0;
    for (std::size_t k = 0; k < q.x.size(); ++k) sum += q.w[k] * (1.0 - fresnel_dielectric(q.x[k], ior)) * q.x[k];
    return 2.0 * sum;
}

// The reflection of light arriving from wi (local frame, z > 0) through the lobe, integrated over the
// lobe's half vectors as lobe_albedo does (GGX measure; here over the whole circle of azimuths, since
// the reflected directions are binned), each reflected direction's share added to the cell it leaves
// through, times `weight`: column[c] += weight * integral over cell c of the lobe's f cos_o.
void bin_reflection(const GlossyBrdf& brdf, const HemisphereCells& cells, const Vec3& wi, double weight,
                    std::vector<double>& column) {
    const double alpha = brdf.roughness, cos_i = wi.z();
    const Quadrature& radial = rule(128);
    const Quadrature& azimuth = rule(256);
    // The azimuths' cosines and sines, the same for every direction: once.
    static const std::vector<std::array<double, 2>> turn = [&] {
        std::vector<std::array<double, 2>> t;
        for (const double x : azimuth.x) t.push_back({std::cos(2.0 * kPi * x), std::sin(2.0 * kPi * x)});
        return t;
    }();
    const Vec3 t1 = Vec3::UnitZ().cross(wi).norm() > 1e-12 ? Vec3(wi.x(), wi.y(), 0.0).normalized() : Vec3::UnitX();
    const Vec3 t2 = Vec3::UnitZ().cross(t1);
    const double scale = weight * smith_g1(alpha, cos_i) / cos_i;
    for (std::size_t a = 0; a < radial.x.size(); ++a) {
        const double xi = radial.x[a];
        const double cos_h = 1.0 / std::sqrt(1.0 + alpha * alpha * xi / (1.0 - xi));
        const double sin_h = std::sqrt(std::max(0.0, 1.0 - cos_h * cos_h));
        for (std::size_t b = 0; b < azimuth.x.size(); ++b) {
            const Vec3 h = sin_h * (turn[b][0] * t1 + turn[b][1] * t2) + cos_h * Vec3::UnitZ();
            const double i_h = wi.dot(h);
            if (i_h <= 0.0) continue;
            const Vec3 wo = 2.0 * i_h * h - wi;
            if (wo.z() <= 0.0) continue;
            const double fresnel = brdf.model == GlossyModel::Plastic ? fresnel_dielectric(i_h, brdf.ior) : 1.0;
            column[std::size_t(cells.cell_of(wo))] +=
                scale * radial.w[a] * azimuth.w[b] * fresnel * smith_g1(alpha, wo.z()) * i_h / cos_h;
        }
    }
}

}  // namespace

double ggx_distribution(double alpha, double cos_h) {
    if (cos_h <= 0.0) return 0.0;
    const double a2 = alpha * alpha, c2 = cos_h * cos_h;
    const double d = c2 * (a2 - 1.0) + 1.0;  // cos_h^2 (alpha^2 + tan_h^2)
    return a2 / (kPi * d * d);
}

double smith_g1(double alpha, double cos_w) {
    if (cos_w <= 0.0) return 0.0;
    return 2.0 / (1.0 + std::sqrt(1.0 + alpha * alpha * tan2(cos_w)));
}

double fresnel_dielectric(double cos_i, double ior) {
    cos_i = std::clamp(cos_i, 0.0, 1.0);
    const double sin_t2 = (1.0 - cos_i * cos_i) / (ior * ior);
    const double cos_t = std::sqrt(std::max(0.0, 1.0 - sin_t2));
    const double rs = (cos_i - ior * cos_t) / (cos_i + ior * cos_t);
    const double rp = (ior * cos_i - cos_t) / (ior * cos_i + cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

double GlossyBrdf::lobe(const Vec3& n, const Vec3& wi, const Vec3& wo) const {
    const double cos_i = n.dot(wi), cos_o = n.dot(wo);
    if (cos_i <= 0.0 || cos_o <= 0.0) return 0.0;
    const Vec3 h = (wi + wo).normalized();
    const double value = ggx_distribution(roughness, n.dot(h)) * smith_g1(roughness, cos_i) *
                         smith_g1(roughness, cos_o) / (4.0 * cos_i * cos_o);
    return model == GlossyModel::Plastic ? value * fresnel_dielectric(wi.dot(h), ior) : value;
}

double GlossyBrdf::base(const Vec3& n, const Vec3& wi, const Vec3& wo) const {
    const double cos_i = n.dot(wi), cos_o = n.dot(wo);
    if (cos_i <= 0.0 || cos_o <= 0.0) return 0.0;
    if (model == GlossyModel::Glossy) return 1.0 / kPi;
    return (1.0 - fresnel_dielectric(cos_i, ior)) * (1.0 - fresnel_dielectric(cos_o, ior)) / kPi;
}

Rgb GlossyBrdf::eval(const Vec3& n, const Vec3& wi, const Vec3& wo) const {
    const double cos_i = n.dot(wi), cos_o = n.dot(wo);
    if (cos_i <= 0.0 || cos_o <= 0.0) return Rgb::Zero();
    const double lobe_value = lobe(n, wi, wo);
    if (model == GlossyModel::Glossy) return albedo / kPi + reflectance * lobe_value;
    const double base = (1.0 - fresnel_dielectric(cos_i, ior)) * (1.0 - fresnel_dielectric(cos_o, ior));
    return Rgb::Constant(lobe_value) + albedo * (base / kPi);
}

Rgb GlossyBrdf::directional_albedo(double cos_o) const {
    const double lobe_part = lobe_albedo(*this, cos_o);
    if (model == GlossyModel::Glossy) return albedo + reflectance * lobe_part;
    const double base = (1.0 - fresnel_dielectric(cos_o, ior)) * entering_share(ior);
    return Rgb::Constant(lobe_part) + albedo * base;
}

Rgb GlossyBrdf::hemispherical_albedo() const {
    static const Quadrature q = gauss_legendre01(32);
    Rgb sum = Rgb::Zero();
    for (std::size_t k = 0; k < q.x.size(); ++k) sum += directional_albedo(q.x[k]) * (2.0 * q.x[k] * q.w[k]);
    return sum;
}

GlossyBrdf glossy_brdf(const Object& o) {
    GlossyBrdf b;
    b.model = o.material.type == MaterialType::Plastic ? GlossyModel::Plastic : GlossyModel::Glossy;
    b.albedo = o.albedo;
    b.reflectance = b.model == GlossyModel::Glossy ? o.material.reflectance : Rgb::Zero();
    b.roughness = o.material.roughness;
    b.ior = o.material.ior;
    return b;
}

HemisphereCells::HemisphereCells(int rings) : m_rings(rings) {
    if (rings < 1) throw std::invalid_argument("HemisphereCells: rings must be at least 1");
}

int HemisphereCells::cell_of(const Vec3& local) const {
    const double r = std::min(1.0, std::hypot(local.x(), local.y()));
    const int k = std::min(m_rings - 1, int(r * m_rings));
    const int sectors = 4 * (2 * k + 1);
    double phi = std::atan2(local.y(), local.x());
    if (phi < 0.0) phi += 2.0 * kPi;
    const int sector = std::min(sectors - 1, int(phi / (2.0 * kPi) * sectors));
    return 4 * k * k + sector;
}

void HemisphereCells::interpolate(const Vec3& local, int cell[4], double weight[4]) const {
    const double r = std::min(1.0, std::hypot(local.x(), local.y()));
    const double rho = std::clamp(r * m_rings - 0.5, 0.0, double(m_rings - 1));
    const int k0 = std::min(m_rings - 1, int(rho)), k1 = std::min(m_rings - 1, k0 + 1);
    const double t = rho - k0;
    double phi = std::atan2(local.y(), local.x());
    if (phi < 0.0) phi += 2.0 * kPi;
    const int rings[2] = {k0, k1};
    const double ring_weight[2] = {1.0 - t, t};
    for (int e = 0; e < 2; ++e) {
        const int k = rings[e], sectors = 4 * (2 * k + 1);
        const double sigma = phi / (2.0 * kPi) * sectors - 0.5;
        const double below = std::floor(sigma), f = sigma - below;
        const int s0 = (int(below) % sectors + sectors) % sectors, s1 = (s0 + 1) % sectors;
        cell[2 * e] = 4 * k * k + s0;
        cell[2 * e + 1] = 4 * k * k + s1;
        weight[2 * e] = ring_weight[e] * (1.0 - f);
        weight[2 * e + 1] = ring_weight[e] * f;
    }
}

Vec3 HemisphereCells::direction(int cell, double u, double v) const {
    int k = int(std::sqrt(cell / 4.0));
    while (4 * (k + 1) * (k + 1) <= cell) ++k;
    while (4 * k * k > cell) --k;
    const int sectors = 4 * (2 * k + 1), sector = cell - 4 * k * k;
    const double r = std::sqrt(k * k + u * (2 * k + 1)) / m_rings;
    const double phi = 2.0 * kPi * (sector + v) / sectors;
    return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1.0 - r * r))};
}

double CellReflectance::at(const GlossyBrdf& brdf, int c, int out, int in) const {
    const double lobe_scale = brdf.model == GlossyModel::Glossy ? brdf.reflectance[c] : 1.0;
    return lobe_scale * lobe_at(out, in) + brdf.albedo[c] * base[std::size_t(out)] * base[std::size_t(in)];
}

CellReflectance cell_reflectance(const GlossyBrdf& brdf, const HemisphereCells& cells, int samples) {
    if (samples < 1) throw std::invalid_argument("cell_reflectance: samples must be at least 1");
    const int m = cells.count();
    const std::size_t size = std::size_t(m);
    CellReflectance out{m, std::vector<double>(size * size, 0.0), std::vector<double>(size, 1.0)};
    // Each of a cell's samples^2 directions carries 1/samples^2 of its projected solid angle pi/M; the
    // light it brings, per unit of the cell's irradiance, is then M / samples^2 of what it reflects.
    const double weight = double(m) / (samples * samples);
    // The in-cells' columns on every core (each its own sums: the same bits for any thread count).
    parallel_for(size, {0, 1, true}, [&](std::size_t c) {
        std::vector<double> column(size, 0.0);
        for (int a = 0; a < samples; ++a)
            for (int b = 0; b < samples; ++b)
                bin_reflection(brdf, cells, cells.direction(int(c), (a + 0.5) / samples, (b + 0.5) / samples), weight,
                               column);
        for (std::size_t o = 0; o < size; ++o) out.lobe[o * size + c] = column[o];
    });
    if (brdf.model == GlossyModel::Plastic) {
        // 1 - F depends on the ring alone; its mean over a ring, uniform in projected solid angle (u).
        const Quadrature& q = rule(256);
        for (int c = 0; c < m; ++c) {
            double sum = 0.0;
            for (std::size_t k = 0; k < q.x.size(); ++k)
                sum += q.w[k] * (1.0 - fresnel_dielectric(cells.direction(c, q.x[k], 0.5).z(), brdf.ior));
            out.base[std::size_t(c)] = sum;
        }
    }
    return out;
}

Rgb lambertian_part_albedo(const GlossyBrdf& brdf, int rings) {
    if (brdf.model == GlossyModel::Glossy) return brdf.albedo;
    const CellReflectance r = cell_reflectance(brdf, HemisphereCells(rings), 1);
    double mean = 0.0;
    for (double v : r.base) mean += v / double(r.cells);
    return brdf.albedo * (mean * mean);
}

}  // namespace tprf
