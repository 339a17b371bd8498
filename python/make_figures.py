#!/usr/bin/python3
"""Makes light-in-flight figures from a tprf render directory.

Usage: python/make_figures.py OUTDIR FIGDIR PREFIX [--frames N] [--energy F] [--scale S]
                               [--bins-per-frame K] [--row Y] [--streak-energy G]

OUTDIR is a directory written by `tprf render` (transient.npy, preview.png, render.json).
Writes into FIGDIR:

  PREFIX-streak.png   the x-t slice of the middle image row (or row Y): x runs left to right,
                      time runs top to bottom (one pixel row per time bin), from just before the
                      row's first light to the bin by which a fraction G (--streak-energy,
                      default 0.98) of the row's light has arrived. Ticks in the left
                      margin mark the bins of the frame strip.
  PREFIX-frames.png   N frames (default 8) side by side, evenly spaced in time from the first
                      bin that holds any light to the bin by which a fraction F (default 0.9) of
                      all the light in the cube has arrived. Every frame is tone-mapped with one
                      common exposure: the 99th percentile of the cube's non-zero luminance maps
                      to 1. With --bins-per-frame K each frame sums K consecutive bins.
  PREFIX-preview.png  a copy of OUTDIR/preview.png (enlarged by S when S > 1).

The streak image uses the same exposure rule applied to its own slice (so a dim middle row is
still visible). Tone mapping: linear scale, clip to [0, 1], sRGB encoding, 8 bits.
Images narrower than 200 pixels are enlarged x2 with nearest-neighbour sampling unless
--scale is given. Uses numpy and matplotlib (python3-numpy, python3-matplotlib).
"""

import argparse
import json
import pathlib
import shutil
import sys

import matplotlib
import matplotlib.image
import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


# ----------------------------------------------------------------------------------------- PNG I/O

def write_png(path, rgb8):
    """Writes an (H, W, 3) uint8 array as an 8-bit PNG (atomically), through matplotlib (which stores it
    as RGBA with opaque alpha; the colours are the array's)."""
    rgb8 = np.ascontiguousarray(rgb8, dtype=np.uint8)
    assert rgb8.ndim == 3 and rgb8.shape[2] == 3
    path = pathlib.Path(path)
    tmp = path.with_name(path.name + ".tmp")
    matplotlib.image.imsave(tmp, rgb8, format="png")
    tmp.replace(path)


def read_png(path):
    """Reads a PNG into (H, W, 3) uint8 (grey is repeated, alpha dropped), through matplotlib."""
    img = matplotlib.image.imread(path)
    if img.dtype != np.uint8:  # PNGs come as floats in [0, 1]
        img = np.rint(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.shape[2] in (1, 2):
        return np.repeat(img[:, :, :1], 3, axis=2)
    return np.ascontiguousarray(img[:, :, :3])


# ------------------------------------------------------------------------------------ tone mapping

def srgb8(linear):
    """Linear values (already exposed, 1 = white) -> sRGB-encoded uint8."""
    x = np.clip(linear, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


def nonzero_percentile(lum, q=99.0):
    """q-th percentile of the positive entries of lum (1.0 when there are none)."""
    v = lum[lum > 0]
    if v.size == 0:
        return 1.0
    p = float(np.percentile(v, q))
    return p if p > 0 else float(v.max())


def enlarge(img, s):
    return img if s == 1 else np.repeat(np.repeat(img, s, axis=0), s, axis=1)


# ------------------------------------------------------------------------------------------- main

def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir", type=pathlib.Path)
    ap.add_argument("figdir", type=pathlib.Path)
    ap.add_argument("prefix")
    ap.add_argument("--frames", type=int, default=8, help="frames in the strip (default 8)")
    ap.add_argument("--energy", type=float, default=0.9,
                    help="the strip ends where this fraction of the light has arrived (default 0.9)")
    ap.add_argument("--bins-per-frame", type=int, default=1, help="bins summed per frame (default 1)")
    ap.add_argument("--streak-energy", type=float, default=0.98,
                    help="the streak ends where this fraction of the row's light has arrived (0.98)")
    ap.add_argument("--row", type=int, default=-1, help="image row of the streak (default: middle)")
    ap.add_argument("--scale", type=int, default=0,
                    help="nearest-neighbour enlargement (default: 2 for images under 200 px wide)")
    a = ap.parse_args(argv)
    if a.frames < 1 or a.bins_per_frame < 1 or not 0 < a.energy <= 1 or not 0 < a.streak_energy <= 1:
        ap.error("--frames and --bins-per-frame must be >= 1, --energy and --streak-energy in (0, 1]")

    cube = np.load(a.outdir / "transient.npy", mmap_mode="r")
    if cube.ndim != 4 or cube.shape[3] != 3:
        sys.exit(f"{a.outdir}/transient.npy: expected shape (H, W, T, 3), got {cube.shape}")
    h, w, t, _ = cube.shape
    scale = a.scale if a.scale > 0 else (2 if w < 200 else 1)
    a.figdir.mkdir(parents=True, exist_ok=True)

    # Luminance cube (H, W, T), row block by row block to bound memory.
    lum = np.empty((h, w, t), dtype=np.float32)
    for y0 in range(0, h, 16):
        lum[y0:y0 + 16] = np.asarray(cube[y0:y0 + 16], dtype=np.float32) @ LUMA
    exposure = nonzero_percentile(lum)

    # Time range: first lit bin .. the bin by which `energy` of the light has arrived.
    per_bin = lum.sum(axis=(0, 1), dtype=np.float64)
    lit = np.nonzero(per_bin > 0)[0]
    if lit.size == 0:
        sys.exit(f"{a.outdir}/transient.npy holds no light")
    cum = np.cumsum(per_bin)
    first = int(lit[0])
    last = int(min(np.searchsorted(cum, a.energy * cum[-1]), t - 1))
    last = max(last, first + a.frames * a.bins_per_frame - 1)
    last = min(last, t - 1)
    starts = np.linspace(first, max(first, last - a.bins_per_frame + 1), a.frames).round().astype(int)

    # Frame strip.
    gap = 2 * scale
    tiles = []
    for k0 in starts:
        frame = np.asarray(cube[:, :, k0:k0 + a.bins_per_frame, :], dtype=np.float32).sum(axis=2)
        tiles.append(enlarge(srgb8(frame / exposure), scale))
        tiles.append(np.full((h * scale, gap, 3), 40, dtype=np.uint8))
    strip = np.concatenate(tiles[:-1], axis=1)
    write_png(a.figdir / f"{a.prefix}-frames.png", strip)

    # Streak image: one row, x across, time down, over the row's own lit range.
    row = h // 2 if a.row < 0 else a.row
    if not 0 <= row < h:
        sys.exit(f"--row {row}: the image has rows 0..{h - 1}")
    row_bins = lum[row].sum(axis=0, dtype=np.float64)
    row_lit = np.nonzero(row_bins > 0)[0]
    if row_lit.size == 0:
        sys.exit(f"image row {row} holds no light; pick another with --row")
    row_cum = np.cumsum(row_bins)
    r_first = int(row_lit[0])
    r_last = int(min(np.searchsorted(row_cum, a.streak_energy * row_cum[-1]), t - 1))
    k_lo = max(0, r_first - max(2, (r_last - r_first) // 20))
    k_hi = max(r_last, r_first + 16) + 1
    k_hi = min(k_hi, t)
    xt = np.asarray(cube[row, :, k_lo:k_hi, :], dtype=np.float32)         # (W, K, 3)
    streak_exposure = nonzero_percentile(xt @ LUMA)
    streak = srgb8(np.transpose(xt, (1, 0, 2)) / streak_exposure)          # (K, W, 3)
    margin = np.zeros((streak.shape[0], 4, 3), dtype=np.uint8)
    for k0 in starts:                                                      # ticks at frame bins
        if k_lo <= k0 < k_hi:
            margin[k0 - k_lo:k0 - k_lo + a.bins_per_frame, :3] = 160
    streak = np.concatenate([margin, streak], axis=1)
    streak = np.repeat(streak, scale, axis=1)  # widen only: one pixel row per bin
    write_png(a.figdir / f"{a.prefix}-streak.png", streak)

    # Preview copy.
    preview = a.outdir / "preview.png"
    dst = a.figdir / f"{a.prefix}-preview.png"
    if preview.exists():
        if scale == 1:
            shutil.copyfile(preview, dst)
        else:
            write_png(dst, enlarge(read_png(preview), scale))

    # Report the time axis of what was drawn.
    info = {}
    try:
        info = json.loads((a.outdir / "render.json").read_text()).get("time", {})
    except (OSError, ValueError):
        pass
    start, width, unit = info.get("start", 0.0), info.get("bin_width", 1.0), info.get("unit", "bin")

    def when(k):
        return f"bin {k} ({start + k * width:.4g} {unit})"

    print(f"{a.prefix}: cube {h}x{w}x{t}, exposure (99th pct of non-zero luminance) {exposure:.4g}")
    print(f"  frames at " + ", ".join(when(int(k)) for k in starts)
          + (f", {a.bins_per_frame} bins each" if a.bins_per_frame > 1 else ""))
    print(f"  streak: image row {row}, {when(k_lo)} .. {when(k_hi - 1)}, exposure {streak_exposure:.4g}")
    for name in ("streak", "frames", "preview"):
        p = a.figdir / f"{a.prefix}-{name}.png"
        if p.exists():
            print(f"  wrote {p} ({p.stat().st_size // 1024} KB)")


if __name__ == "__main__":
    main(sys.argv[1:])
