// Links an installed tprf and checks two view factors against Howell's closed forms: one straight
// from the public form-factor API, one through a scene file, the patch builder and the link stage
// (which exercise the library's private dependencies: the JSON reader, Embree, FLANN and OpenMP).
// Usage: tprf_consumer SCENE.json  (meshes/corner.json: two unit squares meeting at a right angle)
#include <tprf/geometry/form_factors.h>
#include <tprf/geometry/patches.h>
#include <tprf/geometry/visibility.h>
#include <tprf/scene/parse_json.h>
#include <tprf/transport/links.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>

#if defined(_OPENMP)
#error "tprf::tprf passed -fopenmp to a consumer"
#endif

namespace {

// Howell's catalogue C-11 for two directly opposed unit squares at unit distance (0.19982), and C-14
// for two unit squares sharing an edge at a right angle (0.20004): the closed forms evaluated in double
// precision (as tests/test_scenes.h does).
constexpr double kParallelUnitSquares = 0.19982489569838746;
constexpr double kPerpendicularUnitSquares = 0.20004377607540316;

bool check(const char* what, double value, double expected, double tolerance) {
    const bool ok = std::abs(value - expected) <= tolerance;
    std::printf("%s: %.8f, expected %.8f +- %.1e: %s\n", what, value, expected, tolerance, ok ? "ok" : "FAILED");
    return ok;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s SCENE.json\n", argv[0]);
        return 2;
    }
    try {
        using tprf::Vec3;
        const Vec3 floor[4] = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
        const Vec3 ceiling[4] = {Vec3(0, 0, 1), Vec3(0, 1, 1), Vec3(1, 1, 1), Vec3(1, 0, 1)};
        const double f11 = tprf::polygon_form_factor({floor, 4, Vec3::UnitZ()}, {ceiling, 4, -Vec3::UnitZ()});
        // The default quadrature measures 1.6e-4 off here; the bound of tests/form_factors_test.cpp.
        bool ok = check("C-11 parallel unit squares", f11, kParallelUnitSquares, 6e-4 * kParallelUnitSquares);

        tprf::Scene scene = tprf::load_scene(argv[1]);
        scene.max_edge = 0.1;  // 200 patches: enough for the check, fast
        const tprf::PatchSet patches = tprf::build_patches(scene);
        const tprf::Visibility visibility(patches);
        const tprf::Links links = tprf::compute_links(patches, visibility);
        // Object 0 to object 1: the area-weighted sum of the patch-level form factors.
        double flux = 0.0, area = 0.0;
        for (std::size_t i = 0; i < patches.size(); ++i) {
            if (patches.object[i] != 0) continue;
            area += patches.area[i];
            for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k)
                if (patches.object[links.source[k]] == 1) flux += patches.area[i] * double(links.ff[k]);
        }
        // Measured 3.1e-5 off; the bound of object-level sums at this patch size (tests/links_test.cpp).
        ok = check("C-14 perpendicular unit squares", flux / area, kPerpendicularUnitSquares,
                   3e-4 * kPerpendicularUnitSquares) && ok;
        return ok ? 0 : 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "tprf_consumer: %s\n", e.what());
        return 1;
    }
}
