#!/usr/bin/env python3
"""Distance to a mirror from indirect light (Raskar & Davis, "5D time-light transport matrix", §5.1).

A laser at P, aimed in a known direction d, strikes an unknown point X of a mirror; the mirror sends the
beam to a point W of a diffuse wall that the camera sees. A camera sees nothing of X itself, but the
pixel that sees W receives the pulse after PX + XW + WC. With W on the pixel's ray and the wall's plane
known, WC is known, so X lies on the ellipse(oid) PX + XW = s with foci P and W; the laser ray meets it
at X = P + lam d with lam = (s^2 - |P - W|^2) / (2 (s + d.(P - W))).

    mirror_depth.py OUTDIR [--scene mirror_depth.json]

OUTDIR holds `tprf render mirror_depth.json -o OUTDIR`. Prints the recovered and the true X (the laser
ray against the scene's mirror plane) and writes OUTDIR/mirror_depth.png. Exit 1 when X is off by more
than one bin width.
"""
import sys

import numpy as np

from tprf_cube import camera_rays, finish, open_experiment, in_rect, laser_ray, onset_paths, ray_plane, rect_plane

args, scene, cube, start, bin_m, C = open_experiment(__doc__, __file__)
cam = scene["camera"]
P, d = laser_ray(scene)
wall = scene["objects"][0]  # the diffuse wall: a plane the user knows (e.g. measured by stereo)
mirror = next(o for o in scene["objects"] if o.get("material", {}).get("type") == "mirror")

# Where each pixel's ray meets the wall: the visible point and the camera leg to subtract.
rays = camera_rays(cam)
t = ray_plane(C, rays, *rect_plane(wall))
hits = C + np.where(np.isfinite(t), t, 0.0)[..., None] * rays
on_wall = np.isfinite(t) & in_rect(hits, wall)

# The laser spot W is by far the brightest thing on the wall (the mirror sends it the whole beam); tprf
# draws it as a blob a few patches wide. Light from W reaches no wall point Y before PX + XW + |WY|, so
# of the blob's pixels the one whose onset less its camera leg is smallest sees W itself.
energy = np.where(on_wall, cube.sum(axis=2), 0.0)
if not energy.max() > 0:
    sys.exit(f"mirror_depth.py: no light on the wall in {args.outdir}/transient.npy")
lit = energy > 1e-6 * energy.max()
s_map = np.full(t.shape, np.nan)
s_map[lit] = onset_paths(cube[lit], start, bin_m) - t[lit]
blob = energy >= 0.01 * energy.max()
key = np.where(blob, np.round(s_map, 4), np.inf)  # earliest first (to 0.1 mm), then the brightest
iy, ix = np.unravel_index(np.lexsort((-energy.ravel(), key.ravel()))[0], t.shape)
s, W = s_map[iy, ix], hits[iy, ix]
# W is within half a pixel of the spot (the narrow view makes a pixel ~4 mm on the wall). The scene sends
# the beam square onto the wall, so W's error along the wall moves the crossing below only to second
# order; the extra |WY| and the onset's half bin move X by their sum / (1 + cos(angle XP, XW)) at most.

v = P - W
lam = (s * s - v @ v) / (2 * (s + d @ v))
X = P + lam * d

m0, mn = rect_plane(mirror)
X_true = P + d * ((m0 - P) @ mn / (d @ mn))
r = d - 2 * (d @ mn) * mn  # the reflected beam, for the true spot and path
W_true = X_true + r * ray_plane(X_true, r, *rect_plane(wall))
err = np.linalg.norm(X - X_true)
print(f"spot: pixel (row {iy}, column {ix}) of a {blob.sum()}-pixel blob, W = {np.round(W, 4)}")
s_true = np.linalg.norm(X_true - P) + np.linalg.norm(W_true - X_true)
print(f"true W = {np.round(W_true, 4)}, PX + XW = {s:.4f} m (true {s_true:.4f} m)")
print(f"recovered X = {np.round(X, 4)}   (|PX| = {lam:.4f} m)")
print(f"true X      = {np.round(X_true, 4)}   (|PX| = {np.linalg.norm(X_true - P):.4f} m)")
print(f"error       = {err * 1000:.2f} mm = {err / bin_m:.2f} bins of {bin_m * 1000:.2f} mm")

# Figure: the onset map (path less the camera leg) with the spot, and the flatland picture of the
# paper's Figure 5 (top) in the plane through P, W and the laser ray.
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.4))
im = a1.imshow(s_map, cmap="viridis")
fig.colorbar(im, ax=a1, label="first onset - camera leg (m)")
a1.contour(blob, levels=[0.5], colors="w", linewidths=0.8)
a1.plot(ix, iy, "r+", ms=10, label="earliest: W")
a1.legend(loc="lower right", fontsize=8)
a1.set_title("onset per pixel")

e1 = (W - P) / np.linalg.norm(W - P)
e2 = d - (d @ e1) * e1
e2 /= np.linalg.norm(e2)
xy = lambda p: ((p - P) @ e1, (p - P) @ e2)
f = np.linalg.norm(W - P) / 2
ang = np.linspace(0, 2 * np.pi, 400)
a2.plot(f + s / 2 * np.cos(ang), np.sqrt((s / 2) ** 2 - f * f) * np.sin(ang), "c-", lw=1, label="PX + XW = s")
tr = np.array([-(mn @ e2), mn @ e1]) / np.hypot(mn @ e1, mn @ e2)  # the mirror plane's trace in this plane
mx, my = xy(X_true)
a2.plot([mx - 0.12 * tr[0], mx + 0.12 * tr[0]], [my - 0.12 * tr[1], my + 0.12 * tr[1]], "k-", lw=3, label="mirror")
a2.plot(*zip(xy(P), xy(P + 1.3 * lam * d)), "r--", lw=1, label="laser ray")
a2.plot(*zip(xy(X), xy(W)), "r:", lw=1, label="reflected beam")
marks = [(P, "r^", "P (laser)"), (W, "gs", "W (spot)"), (X_true, "ko", "X true"), (X, "m+", "X recovered")]
for p, style, name in marks:
    a2.plot(*xy(p), style, ms=9, mfc="none" if name == "X true" else None, label=name)
a2.set_aspect("equal")
a2.legend(fontsize=8, loc="best")
a2.set_title(f"flatland: X off by {err * 1000:.2f} mm ({err / bin_m:.2f} bins)")
finish(fig, args.outdir, "mirror_depth", err <= bin_m)
