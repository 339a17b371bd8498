#include "tprf/geometry/visibility.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"
#include "tprf/scene/scene.h"

#include <Eigen/Geometry>
#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <new>
#include <string>
#include <vector>

namespace tprf {
namespace {

// Embree calls this from inside its own code, possibly on its worker threads: an exception thrown
// here would cross C frames and end in std::terminate. It records the first error instead, and the
// builder rethrows it on the calling thread.
struct EmbreeErrors {
    std::mutex mutex;
    std::string first;
    RTCError code = RTC_ERROR_NONE;

    // Out of memory becomes std::bad_alloc, as anywhere else; any other error is a bug of tprf's.
    [[noreturn]] void raise(const char* otherwise) const {
        if (code == RTC_ERROR_OUT_OF_MEMORY) throw std::bad_alloc();
        throw InternalError(first.empty() ? otherwise : first);
    }
};

void embree_error(void* user, RTCError code, const char* message) {
    if (code == RTC_ERROR_NONE) return;
    auto* errors = static_cast<EmbreeErrors*>(user);
    try {
        std::lock_guard<std::mutex> lock(errors->mutex);
        if (errors->first.empty()) {
            errors->first = std::string("Embree: ") + (message ? message : "unknown error");
            errors->code = code;
        }
    } catch (...) {  // no memory left even for the message: the builder still sees that it failed
    }
}

// Two-sided objects give each polygon twice with opposite normals; Embree returns either copy, so a
// hit on the copy facing away from the ray is given to its twin. Twins share the object and the
// centroid, so sorting by (object, centroid) puts them side by side.
std::vector<std::int64_t> find_twins(const PatchSet& patches) {
    const std::size_t n = patches.size();
    std::vector<std::uint32_t> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::uint32_t>(i);
    auto key = [&](std::uint32_t i) {
        const Vec3& c = patches.centroid[i];
        return std::array<double, 4>{double(patches.object[i]), c.x(), c.y(), c.z()};
    };
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
    std::vector<std::int64_t> twin(n, -1);
    for (std::size_t k = 0; k + 1 < n; ++k) {
        const std::uint32_t a = order[k], b = order[k + 1];
        if (key(a) == key(b) && patches.normal[a].dot(patches.normal[b]) < -0.999) {
            twin[a] = b;
            twin[b] = a;
        }
    }
    return twin;
}

}  // namespace

struct Visibility::Impl {
    EmbreeErrors errors;
    RTCDevice device = nullptr;
    RTCScene opaque = nullptr;                 // every patch but glass
    RTCScene glass = nullptr;                  // glass patches, one of each pair of twins
    std::vector<std::uint32_t> opaque_patch;   // primitive -> patch
    std::vector<std::uint32_t> glass_patch;
    std::vector<float> glass_transmittance;    // per glass primitive
    const PatchSet* patches = nullptr;
    std::vector<std::int64_t> twin;
    bool packets = false;  // Embree traces packets of 8 rays natively (else one ray at a time)

    ~Impl() {
        if (opaque) rtcReleaseScene(opaque);
        if (glass) rtcReleaseScene(glass);
        if (device) rtcReleaseDevice(device);
    }

    RTCScene make_scene(const std::vector<std::uint32_t>& ids);
};

// A scene of the patches `ids` (primitive k is patch ids[k]).
RTCScene Visibility::Impl::make_scene(const std::vector<std::uint32_t>& ids) {
    RTCScene scene = rtcNewScene(device);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    // Watertight: a ray through the shared edge of two triangles (a quad's diagonal, a patch border)
    // must hit one of them, or pixels and visibility rays leak through the surface.
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    if (!ids.empty()) {
        const PatchSet& p = *patches;
        // Quads throughout: a triangle is a quad whose last corner repeats the third (Embree's convention).
        RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_QUAD);
        auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                               RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                               p.vertices.size()));
        auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
                                                                  RTC_FORMAT_UINT4, 4 * sizeof(unsigned), ids.size()));
        if (!vb || !ib) {  // out of memory: Embree has said why
            rtcReleaseGeometry(geometry);
            rtcReleaseScene(scene);
            errors.raise("Embree: cannot allocate the geometry");
        }
        for (std::size_t k = 0; k < p.vertices.size(); ++k)
            for (int c = 0; c < 3; ++c) vb[3 * k + c] = static_cast<float>(p.vertices[k][c]);
        for (std::size_t k = 0; k < ids.size(); ++k) {
            const std::size_t i = ids[k];
            const std::size_t corners = p.corners(i);
            TPRF_CHECK(corners == 3 || corners == 4);
            const unsigned f = p.first[i];
            ib[4 * k + 0] = f;
            ib[4 * k + 1] = f + 1;
            ib[4 * k + 2] = f + 2;
            ib[4 * k + 3] = corners == 4 ? f + 3 : f + 2;
        }
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(scene, geometry);
        rtcReleaseGeometry(geometry);
    }
    rtcCommitScene(scene);
    return scene;
}

Visibility::Visibility(const PatchSet& patches, std::vector<SpecularPlane> planes, int max_specular)
    : m_impl(std::make_unique<Impl>()), m_planes(std::move(planes)), m_max_specular(max_specular) {
    Impl& im = *m_impl;
    im.patches = &patches;
    im.device = rtcNewDevice(nullptr);
    if (!im.device) {
        // Out of memory is what a process at its limit meets first here: say so, as for any allocation.
        if (rtcGetDeviceError(nullptr) == RTC_ERROR_OUT_OF_MEMORY) throw std::bad_alloc();
        throw InternalError("Embree: cannot create a device");
    }
    rtcSetDeviceErrorFunction(im.device, embree_error, &im.errors);
    im.packets = rtcGetDeviceProperty(im.device, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) != 0;

    Eigen::AlignedBox<double, 3> box;
    for (const Vec3& v : patches.vertices) box.extend(v);
    const double diagonal = patches.vertices.empty() ? 1.0 : box.diagonal().norm();
    // Embree works in single precision: 1e-5 of the scene size clears its rounding, yet stays far below
    // any patch size that matters.
    m_epsilon = 1e-5 * std::max(diagonal, 1e-3);

    im.twin = find_twins(patches);
    for (const SpecularPlane& s : m_planes) {
        if (s.object >= m_object_plane.size()) m_object_plane.resize(s.object + 1, -1);
        m_object_plane[s.object] = int(&s - m_planes.data());
    }
    for (std::uint32_t i = 0; i < patches.size(); ++i) {
        const int plane = plane_of(i);
        if (plane < 0 || !(m_planes[std::size_t(plane)].transmittance > 0.0)) {
            im.opaque_patch.push_back(i);
        } else if (im.twin[i] < 0 || std::int64_t(i) < im.twin[i]) {
            im.glass_patch.push_back(i);
            im.glass_transmittance.push_back(float(m_planes[std::size_t(plane)].transmittance));
        }
    }
    m_glass = !im.glass_patch.empty();
    im.opaque = im.make_scene(im.opaque_patch);
    if (m_glass) im.glass = im.make_scene(im.glass_patch);
    if (!im.errors.first.empty()) im.errors.raise("");
    m_chains = mirror_chains(m_planes, max_specular);
}

int Visibility::plane_of(std::uint32_t patch) const {
    const std::uint32_t object = m_impl->patches->object[patch];
    return object < m_object_plane.size() ? m_object_plane[object] : -1;
}

Visibility::~Visibility() = default;

namespace {

RTCRay make_ray(const Vec3& origin, const Vec3& dir, double tnear, double tfar) {
    RTCRay ray{};
    ray.org_x = static_cast<float>(origin.x());
    ray.org_y = static_cast<float>(origin.y());
    ray.org_z = static_cast<float>(origin.z());
    ray.dir_x = static_cast<float>(dir.x());
    ray.dir_y = static_cast<float>(dir.y());
    ray.dir_z = static_cast<float>(dir.z());
    ray.tnear = static_cast<float>(tnear);
    ray.tfar = static_cast<float>(std::min(tfar, 1e30));
    ray.mask = 0xFFFFFFFFu;
    return ray;
}

// Lane k of a packet of eight rays set to `ray`.
void set_lane(RTCRay8& rays, int k, const RTCRay& ray) {
    rays.org_x[k] = ray.org_x;
    rays.org_y[k] = ray.org_y;
    rays.org_z[k] = ray.org_z;
    rays.dir_x[k] = ray.dir_x;
    rays.dir_y[k] = ray.dir_y;
    rays.dir_z[k] = ray.dir_z;
    rays.tnear[k] = ray.tnear;
    rays.tfar[k] = ray.tfar;
    rays.mask[k] = ray.mask;
}

// The closest primitive of `scene` along the ray, or -1; its distance in `t`.
std::int64_t closest(RTCScene scene, const Vec3& origin, const Vec3& dir, double tnear, double tfar, double& t) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh{};
    rh.ray = make_ray(origin, dir, tnear, tfar);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene, &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return -1;
    t = rh.ray.tfar;
    return rh.hit.primID;
}

// The ray an occlusion test casts along the segment a -> b, its ends lifted off their surfaces by
// `epsilon`; false when the segment is too short to hold anything.
bool segment_ray(const Vec3& a, const Vec3& b, double epsilon, RTCRay& ray) {
    const Vec3 d = b - a;
    const double length = d.norm();
    if (length <= 2 * epsilon) return false;
    ray = make_ray(a, d / length, epsilon, length - epsilon);
    return true;
}

// The product of the transmittances of the glass sheets `ray` crosses, each in turn (a guard against a
// ray stuck in a stack of coincident sheets).
double glass_passed(RTCScene glass, const std::vector<float>& transmittance, const RTCRay& ray, double epsilon) {
    const Vec3 origin(ray.org_x, ray.org_y, ray.org_z), dir(ray.dir_x, ray.dir_y, ray.dir_z);
    double passed = 1.0, from = ray.tnear, t = 0.0;
    for (int k = 0; k < 256; ++k) {
        const std::int64_t prim = closest(glass, origin, dir, from, ray.tfar, t);
        if (prim < 0) break;
        passed *= transmittance[std::size_t(prim)];
        from = t + epsilon;
    }
    return passed;
}

}  // namespace

bool Visibility::occluded(const Vec3& a, const Vec3& b) const {
    RTCRay ray;
    if (!segment_ray(a, b, m_epsilon, ray)) return false;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    rtcOccluded1(m_impl->opaque, &context, &ray);
    return ray.tfar == -std::numeric_limits<float>::infinity();
}

double Visibility::transmittance(const Vec3& a, const Vec3& b) const {
    RTCRay ray;
    if (!segment_ray(a, b, m_epsilon, ray)) return 1.0;
    const float tfar = ray.tfar;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    rtcOccluded1(m_impl->opaque, &context, &ray);
    if (ray.tfar == -std::numeric_limits<float>::infinity()) return 0.0;
    ray.tfar = tfar;
    return m_glass ? glass_passed(m_impl->glass, m_impl->glass_transmittance, ray, m_epsilon) : 1.0;
}

void Visibility::transmittances(const Vec3* a, const Vec3* b, int count, double* passed) const {
    TPRF_CHECK(count >= 0 && count <= kBatch);
    if (!m_impl->packets) {
        for (int k = 0; k < count; ++k) passed[k] = transmittance(a[k], b[k]);
        return;
    }
    alignas(32) int valid[kBatch] = {};
    alignas(32) RTCRay8 rays{};
    RTCRay single[kBatch];
    for (int k = 0; k < count; ++k) {
        passed[k] = 1.0;
        if (!segment_ray(a[k], b[k], m_epsilon, single[k])) continue;
        valid[k] = -1;
        set_lane(rays, k, single[k]);
    }
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    rtcOccluded8(valid, m_impl->opaque, &context, &rays);
    for (int k = 0; k < count; ++k) {
        if (!valid[k]) continue;
        if (rays.tfar[k] == -std::numeric_limits<float>::infinity())
            passed[k] = 0.0;
        else if (m_glass)
            passed[k] = glass_passed(m_impl->glass, m_impl->glass_transmittance, single[k], m_epsilon);
    }
}

RayHit Visibility::intersect(const Vec3& origin, const Vec3& direction, double max_distance) const {
    double t = 0.0;
    const std::int64_t prim = closest(m_impl->opaque, origin, direction, m_epsilon, max_distance, t);
    return first_hit(origin, direction, max_distance, prim, t);
}

void Visibility::intersect_from(const Vec3& origin, const Vec3* directions, int count, double max_distance,
                                RayHit* out) const {
    TPRF_CHECK(count >= 0 && count <= kBatch);
    if (!m_impl->packets) {
        for (int k = 0; k < count; ++k) out[k] = intersect(origin, directions[k], max_distance);
        return;
    }
    alignas(32) int valid[kBatch] = {};
    alignas(32) RTCRayHit8 rays{};
    for (int k = 0; k < count; ++k) {
        valid[k] = -1;
        set_lane(rays.ray, k, make_ray(origin, directions[k], m_epsilon, max_distance));
        rays.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
    }
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcIntersect8(valid, m_impl->opaque, &context, &rays);
    for (int k = 0; k < count; ++k) {
        const bool hit = rays.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
        out[k] = first_hit(origin, directions[k], max_distance, hit ? std::int64_t(rays.hit.primID[k]) : -1,
                           hit ? double(rays.ray.tfar[k]) : 0.0);
    }
}

// The hit of a ray whose closest opaque primitive is `prim` at `t` (prim < 0: none): the glass in
// front of it, if any, and the side of the patch it meets.
RayHit Visibility::first_hit(const Vec3& origin, const Vec3& direction, double max_distance, std::int64_t prim,
                             double t) const {
    const Impl& im = *m_impl;
    double t_glass = 0.0;
    std::uint32_t patch = prim >= 0 ? im.opaque_patch[std::size_t(prim)] : 0;
    if (m_glass) {
        const std::int64_t g = closest(im.glass, origin, direction, m_epsilon, max_distance, t_glass);
        if (g >= 0 && (prim < 0 || t_glass < t)) {
            prim = g;
            t = t_glass;
            patch = im.glass_patch[std::size_t(g)];
        }
    }
    RayHit out;
    if (prim < 0) return out;
    out.hit = true;
    out.distance = t;
    out.point = origin + out.distance * direction;
    const PatchSet& p = *im.patches;
    if (p.normal[patch].dot(direction) > 0 && im.twin[patch] >= 0) patch = static_cast<std::uint32_t>(im.twin[patch]);
    out.patch = patch;
    out.front = p.normal[patch].dot(direction) < 0;
    return out;
}

double Visibility::unfolded(const MirrorChain& chain, const Vec3& x, const Vec3& image, bool* through) const {
    if (through) *through = false;
    const Vec3 d = image - x;
    Unfolding u;  // R1 ... R(j-1): the unfolded frame of plane j
    double t_prev = 0.0;
    std::array<Vec3, kMaxChain + 2> real;  // x, the real crossing points, y
    real[0] = x;
    for (int j = 0; j < chain.length; ++j) {
        const SpecularPlane& s = m_planes[chain.plane[std::size_t(j)]];
        const Vec3 n = u.linear * s.normal;
        const double denom = n.dot(d);
        if (!(std::abs(denom) > 0.0)) return 0.0;
        const double t = n.dot(u(s.point) - x) / denom;
        if (!(t > t_prev && t < 1.0)) return 0.0;
        // The real direction of travel meets the reflecting side: towards -side * normal.
        if (!(chain.side[std::size_t(j)] * s.normal.dot(u.linear.transpose() * d) < 0.0)) return 0.0;
        const Vec3 p = u.inverse(x + t * d);
        if (!s.contains(p)) return 0.0;
        real[std::size_t(j + 1)] = p;
        t_prev = t;
        u = u.after(Unfolding::reflection(s.point, s.normal));
    }
    if (through) *through = true;
    // The legs, now that the path exists: x -> p1 -> ... -> pk -> y, each straight in the real scene.
    const std::size_t ends = std::size_t(chain.length) + 1;
    real[ends] = chain.unfold.inverse(image);
    double weight = chain.reflectance;
    for (std::size_t k = 0; k < ends && weight > 0.0; ++k) weight *= transmittance(real[k], real[k + 1]);
    return weight;
}

void Visibility::trace(const Vec3& origin, const Vec3& direction, std::vector<TracedHit>& out) const {
    struct Ray {
        Vec3 origin, direction;
        double path, weight;
        Rgb tint;
        int reflections, crossings;
        Eigen::Matrix3d turn;
    };
    std::vector<Ray> stack{{origin, direction, 0.0, 1.0, Rgb::Ones(), 0, 0, Eigen::Matrix3d::Identity()}};
    while (!stack.empty()) {
        const Ray r = stack.back();
        stack.pop_back();
        const RayHit h = intersect(r.origin, r.direction, std::numeric_limits<double>::infinity());
        if (!h.hit) continue;
        out.push_back({h, r.path + h.distance, r.weight, r.tint, r.turn});
        const int plane = plane_of(h.patch);
        if (plane < 0) continue;
        const SpecularPlane& s = m_planes[std::size_t(plane)];
        const int side = s.normal.dot(r.direction) < 0.0 ? 1 : -1;
        const double path = r.path + h.distance;
        if (s.transmittance > 0.0 && r.crossings < 64)
            stack.push_back({h.point, r.direction, path, r.weight * s.transmittance, r.tint, r.reflections,
                             r.crossings + 1, r.turn});
        if (s.reflects_from(side) && r.reflections < m_max_specular) {
            const Vec3 reflected = r.direction - 2.0 * s.normal.dot(r.direction) * s.normal;
            const Eigen::Matrix3d householder = Eigen::Matrix3d::Identity() - 2.0 * s.normal * s.normal.transpose();
            stack.push_back({h.point, reflected, path, r.weight * s.reflectance, r.tint * s.tint, r.reflections + 1,
                             r.crossings, householder * r.turn});
        }
    }
}

std::unique_ptr<Visibility> scene_visibility(const Scene& scene, const PatchSet& patches) {
    return std::make_unique<Visibility>(patches, specular_planes(scene, patches), scene.solver.max_specular);
}

}  // namespace tprf
