#pragma once
/// Small geometric vocabulary shared by all stages.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>

namespace tprf {

/// A point or direction in metres (double precision: form factors of close patches need it).
using Vec3 = Eigen::Vector3d;
/// A point in a plane (normalised image coordinates).
using Vec2 = Eigen::Vector2d;
/// An RGB triple (albedo, emission, intensity or power per channel).
using Rgb = Eigen::Array3d;

/// Whether a colour is grey: its three channels equal.
inline bool is_grey(const Rgb& c) { return c[0] == c[1] && c[1] == c[2]; }

/// Speed of light, m/s (docs/scene.md: the same in every medium).
inline constexpr double kSpeedOfLight = 299792458.0;

}  // namespace tprf
