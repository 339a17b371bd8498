"""What both mirror examples read from a tprf render: the cube, its time axis and the camera's pixel rays.

Only the cube and what a user knows of the set-up (camera pose, laser ray, the diffuse wall's plane) are
used; the mirror's geometry is read from the scene only to score the result.
"""
import argparse
import json
from pathlib import Path

import numpy as np

C_LIGHT = 299792458.0  # m/s: tprf takes light at this speed in every medium


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def load_scene(path):
    return json.loads(Path(path).read_text())


def load_render(outdir):
    """(cube, start, bin): the cube as one channel (H, W, T), the mean of RGB (these scenes are grey), and
    the time axis of render.json in metres of optical path (bin k holds paths in [start + k bin, + bin))."""
    outdir = Path(outdir)
    cube = np.load(outdir / "transient.npy").mean(axis=3)
    t = json.loads((outdir / "render.json").read_text())["time"]
    scale = 1.0 if t.get("unit", "m") == "m" else C_LIGHT * 1e-12  # "ps": picoseconds of light travel
    return cube, float(t.get("start", 0.0)) * scale, float(t["bin_width"]) * scale


def open_experiment(doc, script):
    """The command line both scripts take (the render's folder, --scene), the scene, the cube and its
    time axis, and the camera's position."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("--scene", default=str(Path(script).with_suffix(".json")))
    args = ap.parse_args()
    scene = load_scene(args.scene)
    cube, start, bin_m = load_render(args.outdir)
    return args, scene, cube, start, bin_m, np.asarray(scene["camera"]["position"], float)


def camera_rays(cam):
    """(H, W, 3) unit directions through the pixel centres, as tprf's pinhole camera builds them
    (fov vertical, row 0 at the top). The examples use spp 1, so each pixel is exactly this ray."""
    pos = np.asarray(cam["position"], float)
    forward = unit(np.subtract(cam["look_at"], pos))
    right = unit(np.cross(forward, cam["up"]))
    up = np.cross(right, forward)
    w, h = int(cam["width"]), int(cam["height"])
    tan_half = np.tan(np.radians(cam["fov"]) / 2)
    x = (2 * (np.arange(w) + 0.5) / w - 1) * tan_half * w / h
    y = (1 - 2 * (np.arange(h) + 0.5) / h) * tan_half
    return unit(forward + x[None, :, None] * right + y[:, None, None] * up)


def rect_plane(obj):
    """(point, front normal) of a rectangle object."""
    return np.asarray(obj["origin"], float), unit(np.cross(obj["u"], obj["v"]))


def ray_plane(origin, dirs, point, normal):
    """Distance along each ray to the plane (inf for rays parallel to it or pointing away)."""
    den = np.asarray(dirs) @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (np.asarray(point) - origin) @ normal / den
    return np.where(t > 0, t, np.inf)


def in_rect(points, obj):
    """Whether each point (on the rectangle's plane) lies inside the rectangle."""
    u, v = np.asarray(obj["u"], float), np.asarray(obj["v"], float)
    p = np.asarray(points) - np.asarray(obj["origin"], float)
    a, b = p @ u / (u @ u), p @ v / (v @ v)
    return (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)


def laser_ray(scene):
    """(origin, unit direction) of the scene's laser."""
    las = next(l for l in scene["lights"] if l["type"] == "laser")
    o = np.asarray(las["origin"], float)
    return o, unit(np.subtract(las["target"], o) if "target" in las else las["direction"])


def onset_paths(profiles, start, bin_m, frac=0.02):
    """Optical path (m) of the first pulse of each profile (N, T): the energy centroid of the first bin
    above `frac` of the profile's peak and the bin after it. A delta that tprf places wholly in one bin
    gives that bin's centre (off by at most half a bin); one that the camera's last leg splits over two
    bins (linear delays) gives back the split, so again at most half a bin."""
    p = np.asarray(profiles, float)
    k0 = np.argmax(p >= frac * p.max(axis=1, keepdims=True), axis=1)
    rows = np.arange(len(p))
    a, b = p[rows, k0], p[rows, np.minimum(k0 + 1, p.shape[1] - 1)]
    return start + (k0 + b / (a + b) + 0.5) * bin_m


def finish(fig, outdir, name, ok):
    """Writes the figure as OUTDIR/NAME.png and exits 0 when the answer met its bar, else 1."""
    import sys
    fig.tight_layout()
    png = Path(outdir) / f"{name}.png"
    fig.savefig(png, dpi=110)
    print(f"wrote {png}")
    sys.exit(0 if ok else 1)
