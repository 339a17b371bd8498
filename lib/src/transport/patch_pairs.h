#pragma once
// Private to the transport stage: the patch-to-patch form factor that flat links use for every pair
// and hierarchical links for the pairs they refine down to single patches.

#include "tprf/geometry/patches.h"
#include "tprf/transport/links.h"

#include <vector>

namespace tprf {

struct PairFormFactors {
    double ij = 0.0;  ///< F_ij, visibility included
    double ji = 0.0;  ///< F_ji = F_ij A_i / A_j
};

/// Form factors of patches i and j when they face each other and some stratified ray between them is
/// free: the rule their distance calls for (adaptive when `is_near`, Gauss for middle distances, the
/// centroid rule beyond options.far_factor), times the visible fraction. False: no link.
bool patch_pair(const PatchSet& patches, const Visibility& vis, const LinkOptions& options,
                const std::vector<double>& radius, std::size_t i, std::size_t j, bool is_near, PairFormFactors& out,
                LinkStats& counts);

/// Deterministic jitter in [0, 1) from three integers (threads must not change the answer). Inline: the
/// hierarchical oracle calls it for every sample of every pair it judges.
inline double hash01(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
    std::uint64_t h = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full ^ c;
    h ^= h >> 33;
    h *= 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    h *= 0xc4ceb9fe1a85ec53ull;
    h ^= h >> 33;
    return double(h >> 11) * 0x1.0p-53;
}

/// True when i and j are closer than near_factor (r_i + r_j), the pairs integrated adaptively.
bool near_pair(const PatchSet& patches, const std::vector<double>& radius, double near_factor, std::size_t i,
               std::size_t j);

/// A patch with no diffuse part and no emission (a pure mirror or glass) neither gathers nor sends
/// diffuse light: links to or from it would carry nothing.
inline bool inert(const PatchSet& patches, std::size_t i) {
    return !(patches.albedo[i] > 0.0).any() && !(patches.emission[i] > 0.0).any();
}

/// Circumradius of every patch.
std::vector<double> circumradii(const PatchSet& patches);

}  // namespace tprf
