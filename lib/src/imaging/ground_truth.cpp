#include "tprf/imaging/ground_truth.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/imaging/camera.h"

#include <array>
#include <limits>
#include <utility>

namespace tprf {
namespace {

constexpr std::array<std::pair<const char*, AovMap>, 5> kMaps = {{{"depth", kAovDepth},
                                                                  {"normal", kAovNormal},
                                                                  {"position", kAovPosition},
                                                                  {"object", kAovObject},
                                                                  {"albedo", kAovAlbedo}}};

}  // namespace

unsigned parse_aov_list(std::string_view list, std::string_view what) {
    unsigned maps = 0;
    std::size_t start = 0;
    while (start <= list.size()) {
        const std::size_t comma = std::min(list.find(',', start), list.size());
        const std::string_view name = list.substr(start, comma - start);
        bool known = name == "all";
        if (known) maps = kAovDepth | kAovNormal | kAovPosition | kAovObject | kAovAlbedo;
        for (const auto& [key, bit] : kMaps)
            if (name == key) {
                maps |= bit;
                known = true;
            }
        if (!known)
            throw Error(std::string(what) + ": unknown map \"" + std::string(name) +
                        "\" (expected a comma-separated list of depth, normal, position, object, albedo, or all)");
        start = comma + 1;
    }
    return maps;
}

GroundTruth ground_truth(const Camera& camera, const PatchSet& patches, const Visibility& visibility, unsigned maps,
                         int threads) {
    GroundTruth g;
    g.width = camera.width;
    g.height = camera.height;
    const std::size_t pixels = std::size_t(camera.width) * std::size_t(camera.height);
    const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
    if (maps & kAovDepth) g.depth.assign(pixels, inf);
    if (maps & kAovNormal) g.normal.assign(3 * pixels, 0.0f);
    if (maps & kAovPosition) g.position.assign(3 * pixels, nan);
    if (maps & kAovObject) g.object.assign(pixels, -1);
    if (maps & kAovAlbedo) g.albedo.assign(3 * pixels, 0.0f);
    parallel_for(std::size_t(camera.height), {threads, 1, true}, [&](std::size_t row) {
        for (int column = 0; column < camera.width; ++column) {
            const Vec3 d = camera_ray(camera, column + 0.5, double(row) + 0.5);
            if (d.isZero()) continue;  // no ray (validation refuses such a lens; kept for safety)
            const RayHit h = visibility.intersect(camera.position, d, std::numeric_limits<double>::infinity());
            if (!h.hit) continue;
            const std::size_t p = row * std::size_t(camera.width) + std::size_t(column);
            const Vec3 n = h.front ? patches.normal[h.patch] : Vec3(-patches.normal[h.patch]);
            // The diffuse albedo as the scene gives it: a glossy or plastic material's own `albedo` (its
            // patch's albedo is what its row passes on, docs/materials.md); nothing on a one-sided back.
            const GlossyBrdf* brdf = patches.brdf(h.patch);
            const Rgb albedo = !h.front ? Rgb(Rgb::Zero()) : brdf ? brdf->albedo : patches.albedo[h.patch];
            if (maps & kAovDepth) g.depth[p] = float(h.distance);
            if (maps & kAovObject) g.object[p] = std::int32_t(patches.object[h.patch]);
            for (int c = 0; c < 3; ++c) {
                if (maps & kAovNormal) g.normal[3 * p + c] = float(n[c]);
                if (maps & kAovPosition) g.position[3 * p + c] = float(h.point[c]);
                if (maps & kAovAlbedo) g.albedo[3 * p + c] = float(albedo[c]);
            }
        }
    });
    return g;
}

}  // namespace tprf
