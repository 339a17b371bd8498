#include "tprf/transport/patch_views.h"

#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/light_sources.h"

#include <cmath>

namespace tprf {
namespace {

// Patches smaller than this share of their distance from the surface point take one shadow ray, from
// their centroid, for all their samples; larger ones (near the point, where a shadow edge may cross
// them) take one per sample. The views' cost is their rays: 4096 wall points x 12k patches are 50M rays
// instead of 200M.
constexpr double kOneRayAngle = 0.1;

// The samples and cells of every patch.
ViewCells view_cells(const PatchSet& patches) {
    ViewCells c;
    const std::size_t n = patches.size() * std::size_t(kViewSamples);
    c.point.resize(n);
    c.hu.resize(n);
    c.hv.resize(n);
    // The cell's half-axes: central differences of the patch's map over the cell's width.
    const double half = 0.5 / kViewSide;
    for (std::size_t j = 0; j < patches.size(); ++j)
        for (int s = 0; s < kViewSamples; ++s) {
            const double u = (s % kViewSide + 0.5) / kViewSide, t = (s / kViewSide + 0.5) / kViewSide;
            const std::size_t at = j * std::size_t(kViewSamples) + std::size_t(s);
            c.point[at] = patch_point(patches, j, u, t);
            c.hu[at] = 0.5 * (patch_point(patches, j, u + half, t) - patch_point(patches, j, u - half, t));
            c.hv[at] = 0.5 * (patch_point(patches, j, u, t + half) - patch_point(patches, j, u, t - half));
        }
    return c;
}

}  // namespace

// The view of patch j from `probe` (the surface point, or its image through a chain) on a surface of
// normal `wall_normal`, by its samples: arrive() gives the kernel and the exact path with its shadow ray
// (or the unfolded path's weight); small far patches take one ray from the centroid for all samples
// (straight views only).
bool PatchViewer::view_patch(const PointSource& probe, const Vec3& wall_normal, std::size_t j, PatchView& v) const {
    const PatchSet& patches = m_patches;
    const Visibility& visibility = m_visibility;
    const ViewCells& cells = m_cells;
    const Vec3& n = patches.normal[j];
    const double distance = (patches.centroid[j] - probe.origin).norm();
    const bool one_ray = probe.chain < 0 && circumradius(patches, j) < kOneRayAngle * distance;
    v.patch = std::uint32_t(j);
    v.chain = probe.chain;
    v.from = probe.origin;
    if (probe.chain >= 0) v.tint = visibility.chains()[std::size_t(probe.chain)].tint;
    bool seen = false;
    for (int s = 0; s < kViewSamples; ++s) {
        const std::size_t at = j * std::size_t(kViewSamples) + std::size_t(s);
        const Vec3& y = cells.point[at];
        double g = 0.0, path = 0.0;
        if (one_ray) {
            const Vec3 d = probe.position - y;
            const double r = d.norm();
            path = probe.path + (probe.origin - y).norm();  // as arrive() times it: from the point itself
            g = std::max(0.0, n.dot(d)) * std::max(0.0, -wall_normal.dot(d)) / (r * r * r * r);
        } else if (PointArrival a; arrive(probe, y, n, visibility, a)) {
            path = a.path;
            g = a.intensity[0] * a.cos_over_r2;
        }
        if (!(g > 0.0)) continue;
        v.path[std::size_t(s)] = float(path);
        v.g[std::size_t(s)] = float(g);
        const Vec3 dir = (y - probe.origin).normalized();
        v.du[std::size_t(s)] = float(dir.dot(cells.hu[at]));
        v.dv[std::size_t(s)] = float(dir.dot(cells.hv[at]));
        seen = true;
    }
    if (seen && one_ray) {
        // The one ray from the centroid decides for every sample, glass between passing its share.
        const double passed = visibility.transmittance(patches.centroid[j] + visibility.epsilon() * n, probe.position);
        if (!(passed > 0.0)) return false;
        if (passed < 1.0)
            for (float& g : v.g) g = float(double(g) * passed);
    }
    return seen;
}

PatchViewer::PatchViewer(const PatchSet& patches, const Visibility& visibility)
    : m_patches(patches), m_visibility(visibility), m_cells(view_cells(patches)) {}

std::vector<PatchView> PatchViewer::view(const Vec3& x, const Vec3& n, std::uint32_t own) const {
    // A probe whose intensity toward a direction is the cosine at the surface: arrive() then gives
    // cos cos / r^2 and the exact path, with its shadow ray, as for any point source.
    PointSource probe;
    probe.position = x + m_visibility.epsilon() * n;
    probe.origin = x;
    probe.intensity = Rgb::Constant(M_PI);
    probe.lobe = n;
    probe.patch = own;
    // And its images through mirrors and glass (the point's own patch may see those).
    std::vector<PointSource> probes{probe};
    point_images(probe, m_visibility, probes);
    for (PointSource& image : probes) image.intensity = probe.intensity;  // the chain's tint: PatchView::tint
    std::vector<PatchView> out;
    for (std::size_t j = 0; j < m_patches.size(); ++j)
        for (const PointSource& p : probes) {
            if (j == p.patch) continue;
            PatchView v;
            if (view_patch(p, n, j, v)) out.push_back(v);
        }
    return out;
}

}  // namespace tprf
