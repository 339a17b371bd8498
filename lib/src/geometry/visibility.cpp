#include "tprf/geometry/visibility.h"

#include "tprf/core/error.h"
#include "tprf/geometry/patches.h"

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
    RTCScene scene = nullptr;
    const PatchSet* patches = nullptr;
    std::vector<std::int64_t> twin;

    ~Impl() {
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
};

Visibility::Visibility(const PatchSet& patches) : m_impl(std::make_unique<Impl>()) {
    Impl& im = *m_impl;
    im.patches = &patches;
    im.device = rtcNewDevice(nullptr);
    if (!im.device) {
        // Out of memory is what a process at its limit meets first here: say so, as for any allocation.
        if (rtcGetDeviceError(nullptr) == RTC_ERROR_OUT_OF_MEMORY) throw std::bad_alloc();
        throw InternalError("Embree: cannot create a device");
    }
    rtcSetDeviceErrorFunction(im.device, embree_error, &im.errors);
    im.scene = rtcNewScene(im.device);
    rtcSetSceneBuildQuality(im.scene, RTC_BUILD_QUALITY_HIGH);
    // Watertight: a ray through the shared edge of two triangles (a quad's diagonal, a patch border)
    // must hit one of them, or pixels and visibility rays leak through the surface.
    rtcSetSceneFlags(im.scene, RTC_SCENE_FLAG_ROBUST);

    Eigen::AlignedBox<double, 3> box;
    for (const Vec3& v : patches.vertices) box.extend(v);
    const double diagonal = patches.vertices.empty() ? 1.0 : box.diagonal().norm();
    // Embree works in single precision: 1e-5 of the scene size clears its rounding, yet stays far below
    // any patch size that matters.
    m_epsilon = 1e-5 * std::max(diagonal, 1e-3);

    const std::size_t n = patches.size();
    if (n > 0) {
        // Quads throughout: a triangle is a quad whose last corner repeats the third (Embree's convention).
        RTCGeometry geometry = rtcNewGeometry(im.device, RTC_GEOMETRY_TYPE_QUAD);
        auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                               RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                               patches.vertices.size()));
        auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
                                                                  RTC_FORMAT_UINT4, 4 * sizeof(unsigned), n));
        if (!vb || !ib) {  // out of memory: Embree has said why
            rtcReleaseGeometry(geometry);
            im.errors.raise("Embree: cannot allocate the geometry");
        }
        for (std::size_t k = 0; k < patches.vertices.size(); ++k)
            for (int c = 0; c < 3; ++c) vb[3 * k + c] = static_cast<float>(patches.vertices[k][c]);
        for (std::size_t i = 0; i < n; ++i) {
            const std::size_t corners = patches.corners(i);
            TPRF_CHECK(corners == 3 || corners == 4);
            const unsigned f = patches.first[i];
            ib[4 * i + 0] = f;
            ib[4 * i + 1] = f + 1;
            ib[4 * i + 2] = f + 2;
            ib[4 * i + 3] = corners == 4 ? f + 3 : f + 2;
        }
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(im.scene, geometry);
        rtcReleaseGeometry(geometry);
    }
    rtcCommitScene(im.scene);
    if (!im.errors.first.empty()) im.errors.raise("");
    im.twin = find_twins(patches);
}

Visibility::~Visibility() = default;

bool Visibility::occluded(const Vec3& a, const Vec3& b) const {
    const Vec3 d = b - a;
    const double length = d.norm();
    if (length <= 2 * m_epsilon) return false;
    const Vec3 dir = d / length;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRay ray{};
    ray.org_x = static_cast<float>(a.x());
    ray.org_y = static_cast<float>(a.y());
    ray.org_z = static_cast<float>(a.z());
    ray.dir_x = static_cast<float>(dir.x());
    ray.dir_y = static_cast<float>(dir.y());
    ray.dir_z = static_cast<float>(dir.z());
    ray.tnear = static_cast<float>(m_epsilon);
    ray.tfar = static_cast<float>(length - m_epsilon);
    ray.mask = 0xFFFFFFFFu;
    rtcOccluded1(m_impl->scene, &context, &ray);
    return ray.tfar == -std::numeric_limits<float>::infinity();
}

RayHit Visibility::intersect(const Vec3& origin, const Vec3& direction, double max_distance) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh{};
    rh.ray.org_x = static_cast<float>(origin.x());
    rh.ray.org_y = static_cast<float>(origin.y());
    rh.ray.org_z = static_cast<float>(origin.z());
    rh.ray.dir_x = static_cast<float>(direction.x());
    rh.ray.dir_y = static_cast<float>(direction.y());
    rh.ray.dir_z = static_cast<float>(direction.z());
    rh.ray.tnear = static_cast<float>(m_epsilon);
    rh.ray.tfar = static_cast<float>(std::min(max_distance, 1e30));
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(m_impl->scene, &context, &rh);
    RayHit out;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
    out.hit = true;
    out.distance = rh.ray.tfar;
    out.point = origin + out.distance * direction;
    std::uint32_t patch = rh.hit.primID;
    const PatchSet& p = *m_impl->patches;
    if (p.normal[patch].dot(direction) > 0 && m_impl->twin[patch] >= 0)
        patch = static_cast<std::uint32_t>(m_impl->twin[patch]);
    out.patch = patch;
    out.front = p.normal[patch].dot(direction) < 0;
    return out;
}

}  // namespace tprf
