#include "tprf/geometry/mirror_images.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <variant>

namespace tprf {

Unfolding Unfolding::reflection(const Vec3& point, const Vec3& normal) {
    Unfolding u;
    u.linear = Eigen::Matrix3d::Identity() - 2.0 * normal * normal.transpose();
    u.offset = 2.0 * normal.dot(point) * normal;
    return u;
}

bool SpecularPlane::contains(const Vec3& p) const {
    const double tolerance = 1e-9 * std::max(box.diagonal().norm(), 1e-9);
    if (box.exteriorDistance(p) > 1e3 * tolerance) return false;
    for (std::size_t k = 0; k + 1 < first.size(); ++k) {
        const Vec3* poly = corners.data() + first[k];
        const std::size_t count = first[k + 1] - first[k];
        bool inside = true;
        for (std::size_t c = 0; c < count && inside; ++c) {
            const Vec3 edge = poly[(c + 1) % count] - poly[c];
            inside = edge.cross(p - poly[c]).dot(normal) >= -tolerance * edge.norm();
        }
        if (inside) return true;
    }
    return false;
}

namespace {

// The plane of object `id` from its patches (a rectangle: the rectangle itself, as one polygon).
SpecularPlane make_plane(const Scene& scene, const PatchSet& patches, std::uint32_t id) {
    const Object& o = scene.objects[id];
    SpecularPlane s;
    s.object = id;
    s.reflectance = o.material.reflectance.mean();
    if (s.reflectance > 0.0) s.tint = o.material.reflectance / s.reflectance;
    s.transmittance = o.material.transmittance.mean();
    s.both_sides = o.material.type == MaterialType::Glass;
    if (const auto* r = std::get_if<RectangleShape>(&o.shape)) {
        s.point = r->origin;
        s.normal = r->u.cross(r->v).normalized();
        s.corners = {r->origin, r->origin + r->u, r->origin + r->u + r->v, r->origin + r->v};
        s.first = {0, 4};
    } else {
        bool have = false;
        for (std::size_t i = 0; i < patches.size(); ++i) {
            if (patches.object[i] != id) continue;
            if (!have) {
                s.point = patches.centroid[i];
                s.normal = patches.normal[i];
                have = true;
            }
            const Vec3* poly = patches.polygon(i);
            const std::size_t count = patches.corners(i);
            const bool flip = patches.normal[i].dot(s.normal) < 0.0;
            for (std::size_t c = 0; c < count; ++c) s.corners.push_back(poly[flip ? count - 1 - c : c]);
            s.first.push_back(std::uint32_t(s.corners.size()));
        }
        if (!have) fail_input(scene.file, scene.object_path(id), "a mirror or glass object must have some area");
    }
    for (const Vec3& c : s.corners) s.box.extend(c);
    const double size = s.box.diagonal().norm();
    double off = 0.0;
    for (const Vec3& c : s.corners) off = std::max(off, std::abs(s.normal.dot(c - s.point)));
    if (off > 1e-6 * size)
        fail_input(scene.file, scene.object_path(id),
                   "a mirror or glass object must be planar: a corner lies " + std::to_string(off) +
                       " m off its plane (at most 1e-6 of its size, " + std::to_string(1e-6 * size) + " m)");
    return s;
}

// Whether some corner of `b` lies strictly on side `side` of a's plane.
bool reaches(const SpecularPlane& a, int side, const SpecularPlane& b) {
    const double tolerance = 1e-9 * std::max(a.box.diagonal().norm(), b.box.diagonal().norm());
    for (const Vec3& c : b.corners)
        if (side * a.normal.dot(c - a.point) > tolerance) return true;
    return false;
}

void extend(const std::vector<SpecularPlane>& planes, int max_length, std::size_t limit, MirrorChain& chain,
            std::vector<MirrorChain>& out) {
    if (chain.length == max_length) return;
    for (std::size_t p = 0; p < planes.size(); ++p)
        for (int side : {1, -1}) {
            const SpecularPlane& s = planes[p];
            if (!s.reflects_from(side)) continue;
            if (chain.length > 0) {
                const std::size_t q = chain.plane[std::size_t(chain.length - 1)];
                const int q_side = chain.side[std::size_t(chain.length - 1)];
                if (q == p || !reaches(planes[q], q_side, s) || !reaches(s, side, planes[q])) continue;
            }
            MirrorChain next = chain;
            next.plane[std::size_t(next.length)] = std::uint16_t(p);
            next.side[std::size_t(next.length)] = std::int8_t(side);
            ++next.length;
            next.reflectance *= s.reflectance;
            next.tint *= s.tint;
            next.unfold = chain.unfold.after(Unfolding::reflection(s.point, s.normal));
            if (out.size() >= limit)
                throw Error("solver.max_specular: " + std::to_string(max_length) + " reflections make more than " +
                            std::to_string(limit) + " chains of mirrors and glass; lower it");
            out.push_back(next);
            extend(planes, max_length, limit, next, out);
        }
}

}  // namespace

std::vector<SpecularPlane> specular_planes(const Scene& scene, const PatchSet& patches) {
    std::vector<SpecularPlane> planes;
    for (std::size_t i = 0; i < scene.objects.size(); ++i)
        if (scene.objects[i].material.specular()) planes.push_back(make_plane(scene, patches, std::uint32_t(i)));
    return planes;
}

std::vector<MirrorChain> mirror_chains(const std::vector<SpecularPlane>& planes, int max_length, std::size_t limit) {
    std::vector<MirrorChain> out;
    MirrorChain empty;
    extend(planes, std::min(max_length, kMaxChain), limit, empty, out);
    return out;
}

MirrorChain reversed(const MirrorChain& chain, const std::vector<SpecularPlane>& planes) {
    MirrorChain r;
    for (int k = chain.length - 1; k >= 0; --k) {
        const SpecularPlane& s = planes[chain.plane[std::size_t(k)]];
        r.plane[std::size_t(r.length)] = chain.plane[std::size_t(k)];
        r.side[std::size_t(r.length)] = chain.side[std::size_t(k)];
        ++r.length;
        r.reflectance *= s.reflectance;
        r.tint *= s.tint;
        r.unfold = r.unfold.after(Unfolding::reflection(s.point, s.normal));
    }
    return r;
}

std::vector<Vec3> clip_to_window(const std::vector<Vec3>& poly, const Vec3& apex, const Vec3* window,
                                 std::size_t count, bool front_apex) {
    std::vector<Vec3> current = poly, next;
    // Each window edge (a, b) and the apex span a plane; the cone lies on the side of the window's
    // inside. With the apex on the front, (b - apex) x (a - apex) points inwards for a CCW window.
    for (std::size_t k = 0; k < count && !current.empty(); ++k) {
        const Vec3& a = window[k];
        const Vec3& b = window[(k + 1) % count];
        Vec3 inward = (b - apex).cross(a - apex);
        if (!front_apex) inward = -inward;
        const double scale = inward.norm();
        if (!(scale > 0.0)) return {};
        inward /= scale;
        next.clear();
        for (std::size_t c = 0; c < current.size(); ++c) {
            const Vec3& p = current[c];
            const Vec3& q = current[(c + 1) % current.size()];
            const double hp = inward.dot(p - apex), hq = inward.dot(q - apex);
            if (hp >= 0.0) next.push_back(p);
            if ((hp >= 0.0) != (hq >= 0.0)) next.push_back(p + (hp / (hp - hq)) * (q - p));
        }
        current.swap(next);
    }
    if (current.size() < 3) current.clear();
    return current;
}

}  // namespace tprf
