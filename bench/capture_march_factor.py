#!/usr/bin/python3
"""A capture's approximate later bounces (issue 14): cost and error of wider march bins
(`capture.march_bin_factor` F) and of a marched lattice (`capture.march_grid_step` S).

Usage: bench/capture_march_factor.py [--tprf build/bin/tprf] [--grid 4] [--bins 512] [--factors 1,2,4,8,16]
                                     [--steps 1] [--cell 0.0165] [--out bench/out] [--threads N]

The scene is bench/capture_bench.py's: a confocal scan of a hidden scanned bust 1 m in front of a 2 m
relay wall. Runs, each a separate `tprf render` process: the third bounce only (max_bounces 3), then
every bounce once per (F, S) of --factors x --steps, the first one the reference. The later bounces of
a run are its H less the third-bounce H; each is set against the reference's, per scan point:

  light      |sum later_F - sum later_1| / sum later_1 (worst point): kept, to float rounding
  mean       |mean path of later_F - that of later_1| in scene bins (worst point): kept likewise
  L1         sum |later_F - later_1| / sum later_1 (median point): the blur, bin by bin
  L1 /F      the same after summing every F bins (median point)
  hidden L1  sum |H_F - H_1| / sum (H_1 - the spot seen straight) over the whole capture: the error
             against the light that came from the hidden scene, which reconstructions use

and the seconds of the links and the march, and the peak memory. Writes OUT/capture_march_factor.json
(or OUT/NAME.json with --name).
"""

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from capture_bench import PYTHON, ROOT, render, scene  # noqa: E402


def rebin(a, f):
    """Sums every f bins along axis 0 (the last, partial group dropped)."""
    t = a.shape[0] // f * f
    return a[:t].reshape(t // f, f, -1).sum(axis=1)


def compare(later, reference):
    """The metrics of later bounces `later` against `reference`, both (T, points)."""
    t = np.arange(reference.shape[0], dtype=np.float64)[:, None]
    light_ref, light = reference.sum(axis=0), later.sum(axis=0)
    lit = light_ref > 0
    mean_ref = (t * reference).sum(axis=0)[lit] / light_ref[lit]
    mean = (t * later).sum(axis=0)[lit] / light[lit]
    return {
        "light": float(np.max(np.abs(light[lit] - light_ref[lit]) / light_ref[lit])),
        "mean_bins": float(np.max(np.abs(mean - mean_ref))),
        "l1": float(np.median(np.abs(later - reference).sum(axis=0)[lit] / light_ref[lit])),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tprf", type=pathlib.Path, default=ROOT / "build" / "bin" / "tprf")
    parser.add_argument("--grid", type=int, default=4)
    parser.add_argument("--bins", type=int, default=512)
    parser.add_argument("--factors", default="1,2,4,8,16")
    parser.add_argument("--steps", default="1")
    parser.add_argument("--name", default="capture_march_factor")
    parser.add_argument("--cell", type=float, default=0.0165)
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "bench" / "out")
    parser.add_argument("--threads", type=int, default=0)
    args = parser.parse_args()
    runs = [(int(f), int(s)) for f in args.factors.split(",") for s in args.steps.split(",")]
    rows = []
    with tempfile.TemporaryDirectory(prefix="tprf_march_factor_") as tmp:
        work = pathlib.Path(tmp)
        mesh = work / "bust.ply"
        subprocess.run([PYTHON, str(ROOT / "scripts" / "make_statue_mesh.py"), str(mesh), "--cell", str(args.cell)],
                       check=True, stdout=subprocess.DEVNULL)
        render(args.tprf, work, "third", scene(mesh, args.grid, args.bins, 3), args.threads)
        third = np.load(work / "third" / "capture.npy").reshape(args.bins, -1).astype(np.float64)
        render(args.tprf, work, "spot", scene(mesh, args.grid, args.bins, 2), args.threads)
        spot = np.load(work / "spot" / "capture.npy").reshape(args.bins, -1).astype(np.float64)
        H = {}
        for f, step in runs:
            body = scene(mesh, args.grid, args.bins, None, march_bin_factor=f)
            body["capture"]["march_grid_step"] = step
            name = f"all{f}_{step}"
            r = render(args.tprf, work, name, body, args.threads)
            H[f, step] = np.load(work / name / "capture.npy").reshape(args.bins, -1).astype(np.float64)
            c = r["capture"]
            rows.append({"factor": f, "step": step, "links": r["links"], "seconds_links": r["seconds"]["links"],
                         "seconds_solve": c["seconds"]["solve"], "seconds_gather": c["seconds"]["gather"],
                         "seconds_total": r["seconds"]["total"], "peak_mb": r["peak_rss_mb"],
                         "batch": c.get("batch"), "marches": c.get("marches")})
    ref = H[runs[0]]
    reference = ref - third
    for row in rows:
        f = row["factor"]
        later = H[f, row["step"]] - third
        row.update(compare(later, reference))
        lit = reference.sum(axis=0) > 0
        coarse_ref, coarse = rebin(reference, f), rebin(later, f)
        row["l1_rebinned"] = float(np.median(np.abs(coarse - coarse_ref).sum(axis=0)[lit] /
                                             coarse_ref.sum(axis=0)[lit]))
        row["h_l1"] = float(np.abs(H[f, row["step"]] - ref).sum() / ref.sum())
        # Against the light from the hidden scene alone (H less the spot seen straight: orders 1 and 2).
        hidden = ref - spot
        row["hidden_l1"] = float(np.abs(H[f, row["step"]] - ref).sum() / hidden.sum())
        row["later_share"] = float(reference.sum() / hidden.sum())
    print(f"{args.grid}x{args.grid} confocal scan, {args.bins} bins; the later bounces carry "
          f"{100 * rows[0]['later_share']:.1f}% of the light from the hidden scene (H less the spot seen straight)\n")
    print("| F | S | links | links s | march s | film s | total s | peak MB | light | mean (bins) | L1 | L1 /F | "
          "hidden L1 |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['factor']} | {r['step']} | {r['links']:,} | {r['seconds_links']:.2f} | {r['seconds_solve']:.2f} | "
              f"{r['seconds_gather']:.2f} | {r['seconds_total']:.2f} | {r['peak_mb']:.0f} | {r['light']:.1e} | "
              f"{r['mean_bins']:.3f} | {100 * r['l1']:.2f}% | {100 * r['l1_rebinned']:.2f}% | {100 * r['hidden_l1']:.3f}% |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(
        json.dumps({"grid": args.grid, "bins": args.bins, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
