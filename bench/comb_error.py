#!/usr/bin/python3
"""Bin-to-bin ("comb") error of transient renders against a reference render.

usage: /usr/bin/python3 bench/comb_error.py REFERENCE_DIR RUN_DIR [RUN_DIR ...]

Each directory holds a render's transient.npy (height x width x bins x 3); errors are summed over
the channels. Per lit pixel (reference
total at least 1e-3 of the brightest's), over the reference's total: the L1 of the error minus its
9-bin running mean (what changes from one bin to the next: the comb of patch delays in bounced light,
docs/links.md), the L1 after summing every 4 bins (bench/gather_accuracy.py's metric) and the L1 per
bin. Prints the median and the 90th percentile of each.
"""

import sys

import numpy as np


def running_mean(a, width, axis):
    """Mean over `width` bins centred on each bin along `axis`, the ends mirrored."""
    a = np.moveaxis(a, axis, -1)
    half = width // 2
    padded = np.pad(a, [(0, 0)] * (a.ndim - 1) + [(half, half)], mode="symmetric")
    c = np.cumsum(padded, axis=-1)
    c = np.concatenate([np.zeros(c.shape[:-1] + (1,)), c], axis=-1)
    return np.moveaxis((c[..., width:] - c[..., :-width]) / width, -1, axis)


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    ref = np.load(sys.argv[1] + "/transient.npy").astype(np.float64)
    h, w, t, k = ref.shape
    total = ref.sum((2, 3))
    lit = total > 1e-3 * total.max()
    t4 = t // 4 * 4
    ref4 = ref[:, :, :t4].reshape(h, w, t4 // 4, 4, k).sum(3)
    for run in sys.argv[2:]:
        c = np.load(run + "/transient.npy").astype(np.float64)
        if c.shape != ref.shape:
            sys.exit(f"{run}: shape {c.shape}, reference {ref.shape}")
        d = c - ref
        comb = np.abs(d - running_mean(d, 9, axis=2)).sum((2, 3))[lit] / total[lit]
        per_bin = np.abs(d).sum((2, 3))[lit] / total[lit]
        rebinned = np.abs(c[:, :, :t4].reshape(h, w, t4 // 4, 4, k).sum(3) - ref4).sum((2, 3))[lit] / total[lit]
        print(f"{run}: comb {100 * np.median(comb):.3f}% (p90 {100 * np.percentile(comb, 90):.2f}%), "
              f"rebinned by 4 {100 * np.median(rebinned):.3f}% (p90 {100 * np.percentile(rebinned, 90):.2f}%), "
              f"per bin {100 * np.median(per_bin):.3f}%")


if __name__ == "__main__":
    main()
