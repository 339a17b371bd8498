#pragma once
// Private to the pipeline: the cubes a camera render fills while it solves, their names and shapes. One
// rule for the render that opens them (render.cpp) and the estimate that counts their bytes (info.cpp).

#include "tprf/scene/scene.h"

#include <cstddef>
#include <string>
#include <vector>

namespace tprf {

/// Per-bounce cubes of an unlimited solve (solver.bounces without max_bounces): orders 0 to 3, and a
/// tail of every later order.
inline constexpr int kUnlimitedBounceCubes = 5;

/// The per-bounce cubes that `solver.bounces` asks for (transient_bounce_K.npy, K below it), which are
/// also the solver's per-order terms (SolverOptions::bounce_terms): every order up to max_bounces, or
/// kUnlimitedBounceCubes.
inline int bounce_cubes(const SolverSettings& s) {
    return s.bounces ? (s.max_bounces >= 0 ? s.max_bounces + 1 : kUnlimitedBounceCubes) : 0;
}

/// One cube the solve fills.
struct RenderCube {
    enum class Kind { Transient, Bounce, Patches };
    Kind kind = Kind::Transient;     ///< the camera's cube, one bounce order's, or the patch profiles
    std::string name;                ///< the array's name: its .npy file's stem
    std::vector<std::size_t> shape;  ///< float32, C order
    int order = -1;                  ///< Bounce: the order it holds
    bool tail = false;               ///< Bounce: it also holds every later order (the last of an unlimited solve)

    std::size_t floats() const {
        std::size_t n = 1;
        for (std::size_t d : shape) n *= d;
        return n;
    }
};

/// The cubes a render of `scene` (with a camera) over `patches` patches fills, in the order it opens
/// them: transient (H, W, T, 3); with `patch_profiles`, patch_transient (N, T, 3); then
/// transient_bounce_K (H, W, T, 3) for K below bounce_cubes.
inline std::vector<RenderCube> render_cubes(const Scene& scene, std::size_t patches, bool patch_profiles) {
    const std::size_t T = std::size_t(scene.time.bins), H = std::size_t(scene.camera->height),
                      W = std::size_t(scene.camera->width);
    std::vector<RenderCube> cubes{{RenderCube::Kind::Transient, "transient", {H, W, T, 3}}};
    if (patch_profiles) cubes.push_back({RenderCube::Kind::Patches, "patch_transient", {patches, T, 3}});
    const int terms = bounce_cubes(scene.solver);
    for (int k = 0; k < terms; ++k)
        cubes.push_back({RenderCube::Kind::Bounce, "transient_bounce_" + std::to_string(k), {H, W, T, 3}, k,
                         scene.solver.max_bounces < 0 && k == terms - 1});
    return cubes;
}

}  // namespace tprf
