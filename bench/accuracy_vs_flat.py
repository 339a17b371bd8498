#!/usr/bin/python3
"""Accuracy per cost of hierarchical links: renders one scene with flat links (the reference) and with
hierarchical links at several tolerances, and reports how far each is from the flat render and what it
cost.

usage: /usr/bin/python3 bench/accuracy_vs_flat.py [--scene meshes/cornell-box.json] [--max-edge 0.05]
           [--tolerances 0.01,0.003,0.001,0.0003] [--bins N] [--bin-width W] [--size N] [--spp N]
           [--rebin 4] [--lit 1e-3] [--threads N] [--tprf build/bin/tprf] [--out bench/out] [--name NAME]
           [--reference-method flat] [--method hierarchical] [--reference-dir DIR]

Metrics of each render H against the flat render F (transient.npy (H, W, T, 3), steady.npy (H, W, 3)):
  transient  per pixel, the relative L1 of its time profile after summing every --rebin consecutive bins
             (sum over rebinned bins and channels of |H - F|, over the same sum of |F|); the median and the
             90th percentile over the lit pixels: those whose F profile holds at least --lit times the
             largest pixel's light;
  steady     the relative L1 of the whole steady image (sum |H - F| / sum |F|), and the median over lit
             pixels of the per-pixel relative L1 (over channels);
and links, seconds (links, solve, total) and peak RSS from render.json.

Writes OUT/NAME.csv, OUT/NAME.json and OUT/NAME.png (transient and steady error against links and against
seconds, log-log; the flat render's cost as a dashed line). NAME defaults to accuracy_<scene>_<max_edge>.
--method and --reference-method (flat, hierarchical or scene: as the scene file says) exist so that the
script itself can be tested on a build without hierarchical links (e.g. --method flat: every error 0).
--reference-dir keeps the reference render in DIR, and reuses it when DIR already holds one of the same
scene (DIR/scene.json; any other scene is refused): two builds can then be set against one flat render
(the statue's takes 8 minutes and 14 GB). The reference is whatever build rendered it first.
"""

import argparse
import datetime
import json
import os
import pathlib
import platform
import shutil
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tprf_runs as tr  # noqa: E402


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(tr.ROOT / "meshes" / "cornell-box.json"))
    p.add_argument("--max-edge", type=float, default=None, help="patches.max_edge (default: the scene's)")
    p.add_argument("--tolerances", default="0.01,0.003,0.001,0.0003")
    p.add_argument("--method", choices=["hierarchical", "flat", "scene"], default="hierarchical")
    p.add_argument("--reference-method", choices=["hierarchical", "flat", "scene"], default="flat")
    p.add_argument("--reference-dir", default=None, help="keep the reference render here; reuse it if present")
    p.add_argument("--bins", type=int, default=None)
    p.add_argument("--bin-width", type=float, default=None)
    p.add_argument("--size", type=int, default=None, help="camera width and height")
    p.add_argument("--spp", type=int, default=None)
    tr.add_run_args(p)
    return p.parse_args()


def rebinned(cube, k):
    """(H, W, T, 3) -> (H, W, T // k, 3), every k consecutive bins summed (a partial last group dropped)."""
    h, w, t, c = cube.shape
    t = t // k * k
    return cube[:, :, :t, :].astype(np.float64).reshape(h, w, t // k, k, c).sum(axis=3)


class Reference:
    def __init__(self, out_dir, rebin, lit):
        self.rebin = rebin
        self.cube = rebinned(np.load(out_dir / "transient.npy", mmap_mode="r"), rebin)
        self.steady = np.load(out_dir / "steady.npy").astype(np.float64)
        self.pixel_l1 = np.abs(self.cube).sum(axis=(2, 3))
        self.lit = self.pixel_l1 >= lit * self.pixel_l1.max() if self.pixel_l1.max() > 0 else self.pixel_l1 > 0
        self.steady_pixel = np.abs(self.steady).sum(axis=2)

    def errors(self, out_dir):
        cube = rebinned(np.load(out_dir / "transient.npy", mmap_mode="r"), self.rebin)
        if cube.shape != self.cube.shape:
            sys.exit(f"accuracy_vs_flat: cube shapes differ: {cube.shape} vs {self.cube.shape}")
        per_pixel = np.abs(cube - self.cube).sum(axis=(2, 3))[self.lit] / self.pixel_l1[self.lit]
        steady = np.load(out_dir / "steady.npy").astype(np.float64)
        diff = np.abs(steady - self.steady)
        lit_steady = self.lit & (self.steady_pixel > 0)
        return {"transient_rel_l1_median": float(np.median(per_pixel)),
                "transient_rel_l1_p90": float(np.percentile(per_pixel, 90)),
                "steady_rel_l1": float(diff.sum() / np.abs(self.steady).sum()),
                "steady_pixel_rel_l1_median": float(np.median(diff.sum(axis=2)[lit_steady] /
                                                              self.steady_pixel[lit_steady])),
                "lit_pixels": int(self.lit.sum())}


def plot(rows, ref, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    floor = 1e-6  # zeros (identical renders) are drawn here, on log axes
    for ax, (xkey, xlabel) in zip(axes, [("links", "links"), ("seconds.total", "render seconds (total)")]):
        x = [r[xkey] for r in rows]
        for ykey, label, marker in [("transient_rel_l1_median", f"transient, median pixel rel. L1 (rebin {ref.rebin})", "o"),
                                    ("steady_rel_l1", "steady image rel. L1", "s")]:
            y = [max(r[ykey], floor) for r in rows]
            # Along links the points are joined in tolerance order; seconds are noisy, so no lines there.
            ax.plot(x, y, marker=marker, label=label, linestyle="-" if xkey == "links" else "none")
            for xi, yi, r in zip(x, y, rows):
                ax.annotate(f"{r['tolerance']:g}", (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.axvline(ref.record[xkey], color="grey", linestyle="--", label=f"flat: {tr.fmt(ref.record[xkey])}")
        ax.axhline(0.01, color="C0", linestyle=":", linewidth=0.8)
        ax.axhline(0.005, color="C1", linestyle=":", linewidth=0.8)
        tr.style_loglog(ax, xlabel, "error against flat links")
    tr.finish_figure(fig, axes, f"hierarchical vs flat links: {ref.title} (labels: tolerance; dotted: 1% and 0.5%)",
                     path)


def main():
    args = parse_args()
    base = tr.base_scene(args)
    if args.max_edge:
        base.setdefault("patches", {})["max_edge"] = args.max_edge
    stem = pathlib.Path(args.scene).stem
    edge = base.get("patches", {}).get("max_edge")
    name = args.name or f"accuracy_{stem}_{edge if edge else 'default'}"
    tolerances = [float(t) for t in args.tolerances.split(",")]
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    scratch = pathlib.Path(tempfile.mkdtemp(prefix=".accuracy-scratch-", dir=out))
    rows = []
    try:
        scene = json.loads(json.dumps(base))
        tr.set_links(scene, args.reference_method, None)
        print(f"[accuracy] reference ({args.reference_method}) ...", file=sys.stderr, flush=True)
        kept = pathlib.Path(args.reference_dir) if args.reference_dir else None
        if kept and (kept / "record.json").exists():
            if json.loads((kept / "scene.json").read_text()) != scene:
                sys.exit(f"accuracy_vs_flat: {kept} holds the reference of another scene")
            print(f"[accuracy]   reused from {kept}", file=sys.stderr, flush=True)
            rec, ref_dir = json.loads((kept / "record.json").read_text()), kept
        else:
            rec, ref_dir = tr.render(args.tprf, scene, scratch, "reference", args.threads, args.timeout, keep=True)
        ref = Reference(ref_dir, args.rebin, args.lit)
        ref.record = rec
        ref.title = f"{stem}, max_edge {edge}, {rec['patches']} patches, {rec['bins']} bins"
        if kept and ref_dir != kept:
            shutil.rmtree(kept, ignore_errors=True)
            shutil.move(str(ref_dir), str(kept))
            (kept / "scene.json").write_text(json.dumps(scene, indent=1))
            (kept / "record.json").write_text(json.dumps(rec, indent=1))
        elif not kept:
            shutil.rmtree(ref_dir)
        for tol in tolerances:
            scene = json.loads(json.dumps(base))
            tr.set_links(scene, args.method, tol)
            print(f"[accuracy] {args.method}, tolerance {tol:g} ...", file=sys.stderr, flush=True)
            try:
                rec, run_dir = tr.render(args.tprf, scene, scratch, f"tol{tol:g}", args.threads, args.timeout,
                                         keep=True)
            except tr.RenderFailed as e:
                print(f"[accuracy]   failed: exit {e.status}: {e}", file=sys.stderr)
                continue
            rec.update(ref.errors(run_dir), tolerance=tol, method=args.method)
            shutil.rmtree(run_dir)
            rows.append(rec)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    headers = ["tolerance", "links", "links/flat", "links s", "solve s", "total s", "peak MB",
               f"transient median (rebin {args.rebin})", "transient p90", "steady rel L1", "steady pixel median"]
    table = [["flat", ref.record["links"], "1", tr.fmt(ref.record["seconds.links"]),
              tr.fmt(ref.record["seconds.solve"]), tr.fmt(ref.record["seconds.total"]),
              tr.fmt(ref.record["peak_rss_mb"]), "0", "0", "0", "0"]]
    for r in rows:
        table.append([f"{r['tolerance']:g}", r["links"], tr.fmt(r["links"] / max(ref.record["links"], 1)),
                      tr.fmt(r["seconds.links"]), tr.fmt(r["seconds.solve"]), tr.fmt(r["seconds.total"]),
                      tr.fmt(r["peak_rss_mb"]), f"{100 * r['transient_rel_l1_median']:.3g}%",
                      f"{100 * r['transient_rel_l1_p90']:.3g}%", f"{100 * r['steady_rel_l1']:.3g}%",
                      f"{100 * r['steady_pixel_rel_l1_median']:.3g}%"])
    when = datetime.datetime.now().isoformat(timespec="seconds")
    print(f"\n{ref.title}; {ref.record['camera.width']}x{ref.record['camera.height']} px; lit pixels: "
          f"{int(ref.lit.sum())} of {ref.lit.size} (>= {args.lit:g} x the brightest); {os.cpu_count()} cores, "
          f"{platform.node()}, {when}\n")
    print(tr.markdown_table(headers, table))

    ref.record.update(tolerance=None, method=args.reference_method)
    all_rows = [ref.record] + rows
    tr.write_results(out, name, args, when, {"reference": ref.record, "rows": rows}, all_rows,
                     (lambda path: plot(rows, ref, path)) if rows else None)


if __name__ == "__main__":
    main()
