#!/usr/bin/env python3
"""Figures of tprf's outputs, drawn with matplotlib (Debian: python3-matplotlib, python3-numpy).

Usage:
  tprf_plots.py sensor SENSOR_PLOT.json OUT.png
      One pixel of a sensor run (tprf writes sensor_plot.json beside sensor_plot.png): its TPRF and
      the TPRF convolved with the pulse (energy per unit time, channel mean) above, its measurements
      below. 900 x 640 pixels.
  tprf_plots.py scaling HARNESS.csv ACCURACY.csv OUT.png [--bin-width M] [--accuracy-bins N]
      tprf_harness's scaling figure (bench/README.md): seconds against patches, seconds against
      bins, relative error against seconds, log-log, with least-squares slopes in the legends.
      1000 x 1320 pixels.

The PNG appears atomically (written under a temporary name beside it, then renamed).
Exit status: 0 drawn; 2 bad arguments or data; 3 matplotlib or numpy cannot be imported (tprf then
tries another Python, and tells the user how to install them when none has them).
"""

import argparse
import csv
import json
import math
import os
import pathlib
import sys

EXIT_BAD_INPUT = 2
EXIT_NO_MATPLOTLIB = 3
DPI = 100


class BadInput(Exception):
    """Data that cannot be drawn: the message names the file and what is wrong."""


def import_matplotlib():
    """matplotlib.pyplot (Agg, no display needed) and numpy, or exit with status 3."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np
    except ImportError as e:
        print(f"tprf_plots.py: {e} (Debian: apt-get install python3-matplotlib python3-numpy)", file=sys.stderr)
        sys.exit(EXIT_NO_MATPLOTLIB)
    return plt, np


def save_atomically(fig, out):
    """Saves `fig` as PNG under a temporary name in out's directory, then renames it to `out`."""
    out = pathlib.Path(out)
    tmp = out.with_name(f".{out.name}.tmp.{os.getpid()}")
    try:
        fig.savefig(tmp, format="png", dpi=DPI)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()


def as_floats(values, what):
    """A list of numbers (JSON null: NaN), or BadInput naming `what`."""
    if not isinstance(values, list):
        raise BadInput(f"{what}: expected a list of numbers")
    out = []
    for v in values:
        if v is None:
            out.append(math.nan)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(float(v))
        else:
            raise BadInput(f"{what}: expected numbers, got {v!r}")
    return out


def field(data, path, file):
    """data[path[0]][path[1]]..., or BadInput naming the file and the missing key."""
    node = data
    for key in path:
        if not isinstance(node, dict) or key not in node:
            raise BadInput(f"{file}: {'.'.join(path)}: missing")
        node = node[key]
    return node


# "auto" draws an axis logarithmically where its positive values span more than this ratio.
LOG_RANGE = 1e3


def y_scale(values, mode):
    """The y scale of an axis showing `values`: ("linear", None), or ("symlog", linthresh) for "log", and
    for "auto" where the positive values span more than LOG_RANGE. symlog is linear below linthresh (the
    smallest positive value) and logarithmic above, so that zero counts stay drawable."""
    positive = [v for v in values if v > 0 and math.isfinite(v)]
    if mode == "linear" or not positive:
        return "linear", None
    low, high = min(positive), max(positive)
    if mode == "auto" and high <= LOG_RANGE * low:
        return "linear", None
    return "symlog", low


def apply_scale(ax, values, mode):
    scale, linthresh = y_scale(values, mode)
    if scale == "symlog":
        ax.set_yscale("symlog", linthresh=linthresh)


def plot_sensor(plt, data_file, out, scale="auto"):
    """sensor_plot.png from sensor_plot.json (docs/sensor.md, "Outputs"); `scale`: the y axes' scale,
    "linear", "log" or "auto" (log where the values span more than 1e3)."""
    try:
        data = json.loads(pathlib.Path(data_file).read_text())
    except (OSError, ValueError) as e:
        raise BadInput(f"{data_file}: cannot read: {e}") from e
    get = lambda *path: field(data, path, data_file)  # noqa: E731
    x, y = get("pixel")
    exposure = get("exposure")
    units = get("units")
    start, end = as_floats(get("window"), "window")
    edges = as_floats(get("tprf", "bin_edges"), "tprf.bin_edges")
    density = as_floats(get("tprf", "density"), "tprf.density")
    conv_t = as_floats(get("tprf_pulse", "time"), "tprf_pulse.time")
    conv = as_floats(get("tprf_pulse", "density"), "tprf_pulse.density")
    at = as_floats(get("measurements", "at"), "measurements.at")
    values = as_floats(get("measurements", "value"), "measurements.value")
    if len(edges) != len(density) + 1 or len(conv_t) != len(conv) or len(at) != len(values) or not density:
        raise BadInput(f"{data_file}: array lengths do not match (bin_edges must be one longer than density)")

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9.0, 6.4), dpi=DPI, layout="constrained")
    top.stairs(density, edges, color="#282828", label="TPRF")
    top.plot(conv_t, conv, color="#dc3c1e", label="TPRF * pulse")
    top.set_xlim(start, end)
    top.set_title(f"pixel ({x}, {y}): TPRF and TPRF * pulse")
    top.set_xlabel(f"time ({units['time']})")
    top.set_ylabel(units["tprf"])
    top.legend(loc="best")

    if exposure == "spad":
        width = edges[1] - edges[0]
        bottom.stairs(values, at + [at[-1] + width] if at else [start], color="#1e5ac8", label="photon counts")
        bottom.set_xlim(start, end)
    else:
        bottom.plot(at, values, "s", color="#1e5ac8", markersize=4, label="M_k")
    bottom.set_title(f"measurements ({exposure})")
    bottom.set_xlabel("phase (degrees)" if units["measurement_at"] == "degrees" else f"time ({units['time']})")
    bottom.set_ylabel(units["measurements"])
    bottom.legend(loc="best")
    apply_scale(top, density + conv, scale)
    apply_scale(bottom, values, scale)
    for ax in (top, bottom):
        ax.set_axisbelow(True)  # the grid below the stairs, which are patches
        ax.grid(True, color="#e4e4e4")
    save_atomically(fig, out)
    plt.close(fig)


def read_csv(path):
    try:
        with open(path, newline="") as f:
            return list(csv.DictReader(f))
    except OSError as e:
        raise BadInput(f"{path}: cannot read: {e}") from e


def number(row, key, path):
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError) as e:
        raise BadInput(f"{path}: column {key}: expected a number") from e


def log_slope(np, x, y):
    """Least-squares slope of log y against log x over the positive pairs; NaN with fewer than two."""
    pairs = [(math.log(a), math.log(b)) for a, b in zip(x, y) if a > 0 and b > 0]
    if len(pairs) < 2 or len({u for u, _ in pairs}) < 2:
        return math.nan
    u, v = np.array(pairs).T
    return float(np.polyfit(u, v, 1)[0])


def slope_text(s):
    return "n/a" if not math.isfinite(s) else f"{s:.2f}"


# Phases drawn, with their colours; a second group in a panel is drawn lighter, out of the legend.
PHASES = [("total", (20, 20, 20)), ("links", (31, 119, 180)), ("solve", (214, 39, 40)), ("gather", (44, 160, 44))]


def rgb(c, lighter=False):
    if lighter:
        c = tuple(v + (255 - v) // 2 for v in c)
    return tuple(v / 255 for v in c)


def phase_curves(np, ax, groups):
    """Seconds of each phase against x for every group [(x, rows)], slopes of all groups in the label."""
    for phase, colour in PHASES:
        ys = [[float(r[f"{phase}_s"]) for r in rows] for _, rows in groups]
        slopes = " | ".join(slope_text(log_slope(np, x, y)) for (x, _), y in zip(groups, ys))
        label = phase if phase == "gather" else f"{phase} (slope {slopes})"
        for gi, ((x, _), y) in enumerate(zip(groups, ys)):
            ax.plot(x, y, "o-", color=rgb(colour, gi > 0), markersize=4, label=None if gi else label)


def general(v):
    """A number as C++ streams print it by default (6 significant digits, no trailing zeros)."""
    return f"{v:g}"


def plot_scaling(plt, np, harness_csv, accuracy_csv, out, bin_width=None, accuracy_bins=None):
    runs = read_csv(harness_csv)
    accuracy = read_csv(accuracy_csv)
    for r in runs:
        for key in ("max_edge", "patches", "bins", "width", "height") + tuple(f"{p}_s" for p, _ in PHASES):
            number(r, key, harness_csv)
    in_sweep = lambda r, name: name in r.get("label", "").split("+")  # noqa: E731
    by_patch = sorted((r for r in runs if in_sweep(r, "patches")), key=lambda r: float(r["patches"]))
    by_bins = {}
    for r in runs:
        if in_sweep(r, "bins"):
            by_bins.setdefault(float(r["max_edge"]), []).append(r)
    if not by_patch or not by_bins:
        raise BadInput(f"{harness_csv}: needs rows of the patches sweep and of the bins sweep")
    pixels = f"{by_patch[0]['width']}x{by_patch[0]['height']}"

    fig, axes = plt.subplots(3, 1, figsize=(10.0, 13.2), dpi=DPI, layout="constrained")
    ax = axes[0]
    phase_curves(np, ax, [([float(r["patches"]) for r in by_patch], by_patch)])
    ax.set_title(f"Seconds against patches ({by_patch[0]['bins']} bins, {pixels})")
    ax.set_xlabel("patches")
    ax.set_ylabel("seconds")

    # Finer max_edge first (dark), coarser after (light).
    groups = []
    for edge in sorted(by_bins):
        rows = sorted(by_bins[edge], key=lambda r: float(r["bins"]))
        groups.append(([float(r["bins"]) for r in rows], rows))
    counts = [f"{float(rows[0]['patches']):.0f}" for _, rows in groups]
    shades = f"; dark {counts[0]} patches" + "".join(f", light {c}" for c in counts[1:])
    ax = axes[1]
    phase_curves(np, ax, groups)
    each = f"{general(bin_width)} m each, " if bin_width else ""
    ax.set_title(f"Seconds against bins ({each}{pixels}{shades})")
    ax.set_xlabel("bins")
    ax.set_ylabel("seconds")

    ax = axes[2]
    coarse = next((k for k in (accuracy[0].keys() if accuracy else []) if k.startswith("rel_l2_transient_")), None)
    curves = [("rel_l2_transient", "transient cube"), ("rel_l2_steady", "steady image")]
    if coarse:
        curves.insert(1, (coarse, coarse[len("rel_l2_transient_"):].replace("bin", "-bin sums")))
    secs = [number(a, "total_s", accuracy_csv) for a in accuracy]
    for (key, label), (_, colour) in zip(curves, PHASES):
        ax.plot(secs, [number(a, key, accuracy_csv) for a in accuracy], "o-", color=rgb(colour), markersize=4,
                label=label)
    bins = f"{accuracy_bins} bins, " if accuracy_bins else ""
    ax.set_title(f"Relative L2 error against the render at max_edge / 2 ({bins}{pixels})")
    ax.set_xlabel("render seconds")
    ax.set_ylabel("relative L2 error")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="major", color="#e4e4e4")
        ax.legend(loc="best")
    save_atomically(fig, out)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="tprf_plots.py", description="Figures of tprf's outputs (matplotlib).")
    sub = parser.add_subparsers(dest="figure", required=True)
    sensor = sub.add_parser("sensor", help="sensor_plot.png from sensor_plot.json")
    sensor.add_argument("data")
    sensor.add_argument("out")
    sensor.add_argument("--scale", choices=("auto", "log", "linear"), default="auto",
                        help="the y axes: log where the values span more than 1e3 (auto), or always log or linear")
    scaling = sub.add_parser("scaling", help="tprf_harness's scaling.png from harness.csv and accuracy.csv")
    scaling.add_argument("harness")
    scaling.add_argument("accuracy")
    scaling.add_argument("out")
    scaling.add_argument("--bin-width", type=float, help="the bins sweep's bin width, metres (for the title)")
    scaling.add_argument("--accuracy-bins", type=int, help="bins of the accuracy renders (for the title)")
    args = parser.parse_args(argv)
    plt, np = import_matplotlib()
    try:
        if args.figure == "sensor":
            plot_sensor(plt, args.data, args.out, args.scale)
        else:
            plot_scaling(plt, np, args.harness, args.accuracy, args.out, args.bin_width, args.accuracy_bins)
    except (BadInput, OSError) as e:
        print(f"tprf_plots.py: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return 0


if __name__ == "__main__":
    sys.exit(main())
