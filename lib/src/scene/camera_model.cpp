#include "tprf/scene/scene.h"

#include <cmath>

namespace tprf {

Vec2 Distortion::apply(const Vec2& xy) const {
    const double x = xy.x(), y = xy.y(), r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    return {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y};
}

Eigen::Matrix2d Distortion::jacobian(const Vec2& xy) const {
    const double x = xy.x(), y = xy.y(), r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double slope = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);  // d radial / d r^2
    Eigen::Matrix2d j;
    j(0, 0) = radial + 2.0 * x * x * slope + 2.0 * p1 * y + 6.0 * p2 * x;
    j(0, 1) = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y;
    j(1, 0) = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y;
    j(1, 1) = radial + 2.0 * y * y * slope + 6.0 * p1 * y + 2.0 * p2 * x;
    return j;
}

std::optional<Vec2> Distortion::undo(const Vec2& distorted) const {
    if (none()) return distorted;
    // Newton's method from the distorted point itself: the map is the identity plus a smooth change,
    // so the root on the unfolded branch is near. A point the map folds over has no such root.
    Vec2 p = distorted;
    for (int iteration = 0; iteration < 100; ++iteration) {
        const Eigen::Matrix2d j = jacobian(p);
        if (!(j.determinant() > 0.0)) return std::nullopt;
        const Vec2 step = j.inverse() * (apply(p) - distorted);
        p -= step;
        if (!p.allFinite()) return std::nullopt;
        if (step.norm() <= 1e-15 * (1.0 + p.norm())) break;
    }
    if (!((apply(p) - distorted).norm() <= 1e-12 * (1.0 + distorted.norm())) || !(jacobian(p).determinant() > 0.0))
        return std::nullopt;
    return p;
}

Intrinsics Camera::pinhole() const {
    if (intrinsics) return *intrinsics;
    // A vertical fov over square pixels, centred: pixel centres at integers from 0, so the image's
    // centre is at ((width - 1) / 2, (height - 1) / 2).
    const double f = 0.5 * double(height) / std::tan(0.5 * fov_deg * M_PI / 180.0);
    return {f, f, 0.5 * double(width - 1), 0.5 * double(height - 1)};
}

}  // namespace tprf
