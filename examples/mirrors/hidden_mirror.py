#!/usr/bin/env python3
"""A hidden mirror's plane from first onsets (Raskar & Davis, "5D time-light transport matrix", §5.2).

A laser lights a point X of a diffuse wall. A planar mirror that the camera cannot see (an occluder hides
it) sends X's light back onto the wall, onto points W_k that the camera sees. Mirrors make shortest paths:
the first light at W_k has travelled X -> V_k -> W_k = s_k, and V_k is where the ellipsoid of foci X and
W_k with that sum touches the mirror, whose plane is the common tangent plane of all these ellipsoids.
Equivalently the mirror image X' of X is at |X' - W_k| = s_k from every W_k: Gauss-Newton finds X', and
the mirror plane is the perpendicular bisector of X X'.

    hidden_mirror.py OUTDIR [--scene hidden_mirror.json]

OUTDIR holds `tprf render hidden_mirror.json -o OUTDIR`. Prints the recovered and the true plane (the
scene's mirror) and writes OUTDIR/hidden_mirror.png. Exit 1 unless the normal is within 1 degree and
the plane within 1 cm.
"""
import sys

import numpy as np

from tprf_cube import (camera_rays, finish, open_experiment, in_rect, laser_ray, onset_paths, ray_plane, rect_plane,
                       unit)

args, scene, cube, start, bin_m, C = open_experiment(__doc__, __file__)
cam = scene["camera"]
L, d = laser_ray(scene)
wall = scene["objects"][0]  # the diffuse wall: a plane the user knows
w0, wn = rect_plane(wall)
X = L + d * ray_plane(L, d, w0, wn)  # the laser spot, on the known laser ray and wall

rays = camera_rays(cam)
t = ray_plane(C, rays, w0, wn)
hits = C + np.where(np.isfinite(t), t, 0.0)[..., None] * rays
on_wall = np.isfinite(t) & in_rect(hits, wall)
legs = np.zeros_like(t) if cam.get("unwarp", False) else t  # unwarp: tprf leaves the camera leg out

# The W_k: what the mirror makes of X is a point source's image, one sharp pulse per pixel, far stronger
# per bin than any later light. Keep the wall pixels where it is strong, less a one-pixel border
# (there the pixel may see past the mirror's edge, whose paths are not the specular ones).
peak = np.where(on_wall, cube.max(axis=2), 0.0)
if not peak.max() > 0:
    sys.exit(f"hidden_mirror.py: no light on the wall in {args.outdir}/transient.npy")
sel = peak >= 0.25 * peak.max()
sel[1:-1, 1:-1] &= sel[:-2, 1:-1] & sel[2:, 1:-1] & sel[1:-1, :-2] & sel[1:-1, 2:]
sel[[0, -1], :] = sel[:, [0, -1]] = False
if sel.sum() < 10:
    sys.exit(f"hidden_mirror.py: only {sel.sum()} wall pixels lit by the mirror; need 10 or more")
W = hits[sel]
s = onset_paths(cube[sel], start, bin_m) - np.linalg.norm(X - L) - legs[sel]


def image_point(W, s, x):
    """Gauss-Newton for the point x at |x - W_k| = s_k (least squares); returns x and the residuals."""
    for _ in range(50):
        r = np.linalg.norm(x - W, axis=1)
        step = np.linalg.lstsq((x - W) / r[:, None], s - r, rcond=None)[0]
        x = x + step
        if np.linalg.norm(step) < 1e-12:
            break
    return x, np.linalg.norm(x - W, axis=1) - s


# Start in front of the wall: the W_k are coplanar, so X' reflected across the wall fits them as well;
# then refit without any point more than 3 bins off (a pixel whose first light was not specular).
Xp, res = image_point(W, s, W.mean(axis=0) + s.mean() * wn)
keep = np.abs(res) <= 3 * bin_m
Xp, res = image_point(W[keep], s[keep], Xp)
n = unit(Xp - X)
mid = (X + Xp) / 2  # on the mirror plane n.p = n.mid

mirror = next(o for o in scene["objects"] if o.get("material", {}).get("type") == "mirror")
m0, mn = rect_plane(mirror)
nt = mn * np.sign(mn @ n)  # the scene's front normal faces the wall; compare planes, not sides
centre = m0 + (np.asarray(mirror["u"]) + np.asarray(mirror["v"])) / 2
angle = np.degrees(np.arccos(np.clip(n @ nt, -1, 1)))
d_rec, d_true = n @ mid, nt @ m0
off = abs(n @ (centre - mid))  # how far the mirror's centre is from the recovered plane
print(f"{sel.sum()} points W_k, {keep.sum()} kept; residual rms {np.sqrt(np.mean(res ** 2)) * 1000:.2f} mm "
      f"(bin {bin_m * 1000:.2f} mm)")
print(f"X = {np.round(X, 4)}, X' = {np.round(Xp, 4)}")
print(f"recovered plane: n = {np.round(n, 4)}, n.p = {d_rec:.4f} m")
print(f"true plane:      n = {np.round(nt, 4)}, n.p = {d_true:.4f} m")
print(f"normal off by {angle:.3f} deg, offset by {abs(d_rec - d_true) * 1000:.2f} mm, "
      f"mirror centre {off * 1000:.2f} mm from the recovered plane")
ok = angle <= 1.0 and abs(d_rec - d_true) <= 0.01 and off <= 0.01

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

fig, (a1, a2) = plt.subplots(1, 2, figsize=(10.5, 4.4))
s_map = np.full(t.shape, np.nan)
s_map[sel] = s
a1.imshow(np.where(on_wall, np.log10(peak + 1e-12), np.nan), cmap="gray")  # the wall, for context
im = a1.imshow(s_map, cmap="viridis")
fig.colorbar(im, ax=a1, label="first onset path X -> mirror -> W_k (m)")
a1.set_title(f"camera view: {sel.sum()} points W_k")

# Top view (x-y): the wall, the spot, its image, the true mirror and the recovered plane's trace at the
# mirror's height.
unit_square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]])
corners = lambda o: np.asarray(o["origin"]) + unit_square @ np.array([o["u"], o["v"]])
a2.plot(*corners(mirror)[:, :2].T, "-", color="0.6", lw=5, label="mirror (true)")
for k, o in enumerate(scene["objects"]):
    if o is not mirror:
        q = corners(o)
        a2.plot(q[:, 0], q[:, 1], "k-", lw=2)
        a2.annotate("wall" if k == 0 else "occluder", q[2, :2], fontsize=8, xytext=(4, -10),
                    textcoords="offset points")
tr = np.array([-n[1], n[0]]) / np.hypot(n[0], n[1])
p0 = centre[:2] + n[:2] * (d_rec - n[2] * centre[2] - n[:2] @ centre[:2]) / (n[:2] @ n[:2])
a2.plot(*np.array([p0 - 0.3 * tr, p0 + 0.3 * tr]).T, "m-", lw=1.5, label="recovered plane")
a2.plot(W[:, 0], W[:, 1], ".", color="tab:green", ms=2, label="W_k")
a2.plot(*zip(L[:2], X[:2]), "r--", lw=1)
Xt = X - 2 * ((X - m0) @ nt) * nt  # the true image of X
marks = [(X, "ro", "X (laser spot)"), (Xt, "kx", "X' true"), (Xp, "m+", "X' recovered"), (C, "b^", "camera")]
for p, style, name in marks:
    a2.plot(p[0], p[1], style, ms=9, label=name)
a2.set_aspect("equal")
a2.set_xlabel("x (m)")
a2.set_ylabel("y (m)")
a2.legend(fontsize=7, loc="best")
a2.set_title(f"top view: normal off {angle:.2f} deg, plane off {off * 1000:.1f} mm")
finish(fig, args.outdir, "hidden_mirror", ok)
