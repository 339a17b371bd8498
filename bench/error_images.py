#!/usr/bin/python3
"""Before/after images of transient renders against a reference render: where each run's error lies.

usage: /usr/bin/python3 bench/error_images.py REFERENCE_DIR OUT.png LABEL=RUN_DIR [LABEL=RUN_DIR ...]
           [--row R] [--bins A:B] [--frame T] [--width W] [--range RANGE]

Each directory holds a render's transient.npy (height x width x bins x 3, the same shape); the channels
are summed. Top row: the reference's streak image (row R, default the middle one, over bins A:B) and
each run's difference from it; bottom row: the reference's frame at bin T (summed over W bins, default
8) and each run's difference. Differences are over the reference's 99th percentile of the same view,
red where the run has too much light, blue where too little, saturated at +-RANGE (default 15%).
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("reference")
    p.add_argument("output")
    p.add_argument("runs", nargs="+", help="LABEL=RUN_DIR")
    p.add_argument("--row", type=int, default=None)
    p.add_argument("--bins", default=None, help="A:B, the streak's bins (default: where the reference has light)")
    p.add_argument("--frame", type=int, default=None, help="the frame's first bin (default: the streak's middle)")
    p.add_argument("--width", type=int, default=8)
    p.add_argument("--range", type=float, default=0.15, help="the differences' saturation (default 0.15)")
    a = p.parse_args()
    ref = np.load(a.reference + "/transient.npy").astype(np.float64).sum(3)
    h, w, t = ref.shape
    runs = []
    for spec in a.runs:
        label, _, path = spec.partition("=")
        cube = np.load(path + "/transient.npy").astype(np.float64).sum(3)
        if cube.shape != ref.shape:
            raise SystemExit(f"{path}: shape {cube.shape}, reference {ref.shape}")
        runs.append((label, cube))
    row = h // 2 if a.row is None else a.row
    if a.bins:
        lo, hi = (int(x) for x in a.bins.split(":"))
    else:
        profile = ref.sum((0, 1))
        lit = np.nonzero(profile > 1e-3 * profile.max())[0]
        lo, hi = int(lit[0]), int(lit[-1]) + 1
    frame = (lo + hi) // 2 if a.frame is None else a.frame
    cols = len(runs) + 1
    fig, ax = plt.subplots(2, cols, figsize=(3.2 * cols, 7.5), gridspec_kw={"height_ratios": [1.4, 1]})
    streak = ref[row, :, lo:hi].T
    s = np.percentile(streak, 99) + 1e-30
    ax[0, 0].imshow(np.clip(streak / s, 0, 1) ** 0.5, aspect="auto", cmap="gray", extent=(0, w, hi, lo))
    ax[0, 0].set_title(f"reference: row {row}")
    ax[0, 0].set_ylabel("bin")
    f = ref[:, :, frame:frame + a.width].sum(2)
    sf = np.percentile(f, 99) + 1e-30
    ax[1, 0].imshow(np.clip(f / sf, 0, 1) ** 0.5, cmap="gray")
    ax[1, 0].set_title(f"reference: bins {frame}-{frame + a.width - 1}")
    for k, (label, cube) in enumerate(runs, start=1):
        d = (cube[row, :, lo:hi].T - streak) / s
        ax[0, k].imshow(d, aspect="auto", cmap="RdBu_r", vmin=-a.range, vmax=a.range, extent=(0, w, hi, lo))
        ax[0, k].set_title(f"{label} - reference")
        df = (cube[:, :, frame:frame + a.width].sum(2) - f) / sf
        ax[1, k].imshow(df, cmap="RdBu_r", vmin=-a.range, vmax=a.range)
        ax[1, k].set_title(f"{label} - reference")
    for x in ax[1]:
        x.axis("off")
    plt.tight_layout()
    plt.savefig(a.output, dpi=70)
    print(f"wrote {a.output}: streak row {row}, bins {lo}:{hi}, frame {frame}")


if __name__ == "__main__":
    main()
