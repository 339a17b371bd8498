#!/usr/bin/env python3
"""Renders the sample two-plane corner from Python, plots one pixel's transient (its TPRF under the
scene's point light) and writes the streak image (x-t) of the image's middle row. No Jupyter needed:

    python3 examples/python/corner.py [OUTDIR]     (default: corner-python/)

Writes OUTDIR/pixel_tprf.png and OUTDIR/streak.png, and prints where the light arrives first.
"""

import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tprf  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "corner-python")
out.mkdir(parents=True, exist_ok=True)

scene = tprf.load_scene(HERE.parents[1] / "meshes" / "corner.json")
print(scene)
estimate = tprf.info(scene, links=False)["estimate"]
print(f"estimate: {estimate['patches']} patches, peak {estimate['peak_bytes'] / 1e6:.0f} MB, "
      f"{estimate['seconds']['total']:.1f} s")


def progress(phase, fraction):
    print(f"\r{phase:>8} {100 * fraction:5.1f}%", end="" if fraction < 1 else "\n", flush=True)


result = tprf.render(scene, progress=progress)
cube = result.transient                       # (H, W, T, 3) float32, shared with the result
H, W, T, _ = cube.shape
t = tprf.times(result)                        # bin starts, metres of optical path
unit = result.time["unit"]

# One pixel's TPRF: the radiance arriving per bin, channels averaged.
y, x = H // 2, W // 3
profile = cube[y, x].mean(axis=1)
first = t[np.argmax(profile > 0)]
print(f"pixel ({x}, {y}): first light at {first:.3f} {unit} of path, "
      f"steady radiance {result.steady[y, x].mean():.4g} W/(m^2 sr)")
fig, ax = plt.subplots(figsize=(6, 3.2))
shown = (t >= first - 0.2) & (t <= first + 1.0)
ax.plot(t[shown], profile[shown], lw=1)
ax.set_xlabel(f"optical path ({unit})")
ax.set_ylabel("radiance per bin")
ax.set_title(f"TPRF of pixel ({x}, {y})")
fig.tight_layout()
fig.savefig(out / "pixel_tprf.png", dpi=120)

# The streak image of the middle row: x across, time down, tone-mapped per image.
streak = cube[y].mean(axis=2).T               # (T, W)
lit = np.nonzero(streak.max(axis=1) > 1e-4 * streak.max())[0]
begin, last = max(0, int(lit.min()) - 20), int(lit.max())
fig, ax = plt.subplots(figsize=(5, 4))
ax.imshow(np.sqrt(streak[begin: last + 1] / streak.max()), aspect="auto", cmap="inferno",
          extent=(0, W, t[last], t[begin]))
ax.set_xlabel("pixel x")
ax.set_ylabel(f"optical path ({unit})")
ax.set_title(f"streak image, row {y}")
fig.tight_layout()
fig.savefig(out / "streak.png", dpi=120)
print(f"wrote {out / 'pixel_tprf.png'} and {out / 'streak.png'}")
