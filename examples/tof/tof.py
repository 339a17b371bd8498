#!/usr/bin/env python3
"""A continuous-wave time-of-flight camera in a room: ground truth, and the multipath error.

A calibrated 64 x 48 camera (OpenCV intrinsics and lens distortion) with a flash (a spot light 4 cm
beside the lens) looks into a room with a scanned bust (scripts/make_statue_mesh.py, coarse) and a
block. tprf renders the transient cube with every bounce and each bounce order apart, and the ground
truth maps of every pixel (--aov all). A two-frequency AMCW camera (20 and 100 MHz, 4 phases each) is
then applied twice: to the whole cube, as the real camera sees it, and to the direct light alone
(transient_bounce_1). The direct light gives the geometric depth; the rest is multipath error.

    tof.py OUTDIR [--tprf build/bin/tprf]

Writes OUTDIR/room.json (this folder's scene, with the bust beside it), the render in OUTDIR/render
(its sensors in render/sensor-all, render/sensor-direct, render/sensor-noisy) and OUTDIR/tof.png, and
prints the errors. The depth an AMCW camera reports is half the path flash -> point -> lens; the
truth compared with is that, from the ground truth's positions (it differs from aov_depth by the
flash's 4 cm offset, up to 2 cm). Exit 1 when the direct light's depth misses the truth by more
than 5 mm (median), or the multipath error is not at least three times that.
"""
import argparse
import json
import pathlib
import shutil
import subprocess
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]

AMCW = {"exposure": {"type": "amcw", "frequencies": [20e6, 100e6], "phases": 4}}
NOISY = {"exposure": {"type": "amcw", "frequencies": [20e6, 100e6], "phases": 4,
                      "photons": 2e4, "ambient": 200, "adc_bits": 12, "seed": 1}}


def run(*args):
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"tof.py: {' '.join(map(str, args))} failed:\n{r.stderr}")
    return r


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("outdir", type=pathlib.Path)
    parser.add_argument("--tprf", default=str(ROOT / "build" / "bin" / "tprf"))
    args = parser.parse_args()
    out = args.outdir
    out.mkdir(parents=True, exist_ok=True)

    # The scene beside its meshes: a coarse scan of the bust (about 4k triangles) and the sample block.
    run(sys.executable, ROOT / "scripts" / "make_statue_mesh.py", out / "statue.ply", "--cell", "0.03")
    shutil.copy(ROOT / "meshes" / "block.obj", out / "block.obj")
    shutil.copy(HERE / "room.json", out / "room.json")
    scene = json.loads((out / "room.json").read_text())

    render = out / "render"
    run(args.tprf, "render", out / "room.json", "-o", render, "--aov", "all", "--quiet")
    for name, block, cube in (("all", AMCW, "transient"), ("direct", AMCW, "transient_bounce_1"),
                              ("noisy", NOISY, "transient")):
        (out / f"{name}.json").write_text(json.dumps(block))
        run(args.tprf, "sensor", render, out / f"{name}.json", "--cube", cube, "--name", name, "--quiet")

    position = np.load(render / "aov_position.npy")
    objects = np.load(render / "aov_object.npy")
    seen = objects >= 0
    cam = np.array(scene["camera"]["position"])
    flash = np.array(scene["lights"][0]["position"])
    truth = 0.5 * (np.linalg.norm(position - flash, axis=-1) + np.linalg.norm(position - cam, axis=-1))
    depth = {name: np.load(render / f"sensor-{name}" / "depth.npy") for name in ("all", "direct", "noisy")}
    error = {name: np.where(seen, d - truth, np.nan) for name, d in depth.items()}
    median = {name: float(np.nanmedian(np.abs(e))) for name, e in error.items()}
    for name, e in error.items():
        print(f"{name:>6}: depth error median {100 * median[name]:.2f} cm, mean {100 * np.nanmean(e):+.2f} cm, "
              f"95th percentile {100 * np.nanpercentile(np.abs(e), 95):.2f} cm")
    record = json.loads((render / "render.json").read_text())
    print(f"render: {record['patches']} patches, {record['seconds']['total']:.1f} s; "
          f"light outside the window {100 * record['camera']['light_outside_window']:.2f}%")

    figure(out / "tof.png", render, truth, depth, error, seen)
    ok = median["direct"] < 0.005 and median["all"] > 3 * median["direct"]
    print("ok" if ok else "FAILED: the direct depth misses the truth, or multipath adds no error")
    return 0 if ok else 1


def figure(path, render, truth, depth, error, seen):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    steady = np.load(render / "steady.npy")
    normal = np.load(render / "aov_normal.npy")
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.4), dpi=100, layout="constrained")
    image = steady / max(np.percentile(steady, 99), 1e-12)
    panels = [
        (np.clip(image, 0, 1) ** (1 / 2.2), "steady image (flash only)", None),
        (np.where(seen, truth, np.nan), "true depth (half the flash-point-lens path), m", "viridis"),
        (0.5 + 0.5 * normal, "ground truth normals", None),
        (depth["all"], "AMCW depth, 20 + 100 MHz, m", "viridis"),
        (100 * error["all"], "depth error with multipath, cm", "RdBu_r"),
        (100 * error["noisy"], "error with shot noise, ambient and a 12-bit ADC, cm", "RdBu_r"),
    ]
    lim = float(np.nanpercentile(np.abs(100 * error["all"]), 98))
    for ax, (data, title, cmap) in zip(axes.flat, panels):
        if cmap is None:
            ax.imshow(data)
        else:
            kwargs = {"vmin": -lim, "vmax": lim} if cmap == "RdBu_r" else {}
            fig.colorbar(ax.imshow(data, cmap=cmap, **kwargs), ax=ax, shrink=0.8)
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
