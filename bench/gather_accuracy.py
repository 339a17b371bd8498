#!/usr/bin/python3
"""Accuracy per second of the camera gather (issue 13): renders one scene at several samples per pixel
(spp) and patch sizes (max_edge) and reports each render's error against a converged reference render,
with its seconds.

usage: /usr/bin/python3 bench/gather_accuracy.py [--scene meshes/corner.json] [--size 64] [--bins 600]
           [--spp 4,16,64,256] [--max-edge 0.1,0.05,0.025] [--ref-spp 1024] [--ref-max-edge 0.0125]
           [--ref-tolerance 0.0003] [--ref-check] [--keep-reference] [--rebin 4] [--lit 1e-3] [--threads N]
           [--tprf build/bin/tprf] [--out bench/out] [--name NAME]

The reference is a tprf render with many samples per pixel (--ref-spp) and small patches (--ref-max-edge;
hierarchical links at --ref-tolerance, so that it fits in memory): converged in the two quantities the
sweep varies. It is kept in OUT/NAME-reference/ with the settings and the binary (commit, size, time) that made it,
and reused while both are unchanged, or with --keep-reference while the settings are (a reference at
many samples and small patches stays converged across changes that only make fewer samples cheaper or
better; delete the folder to render it again). --ref-check also renders the
reference's spp at twice its patch size (compared with the reference) and a quarter of its spp at that
patch size (compared with the former): the reference's own error is well below those (both errors fall
at least linearly), so a sweep's error is meaningful down to about a third of the larger of them.

Metrics (as bench/accuracy_vs_flat.py): per lit pixel, the relative L1 of its time profile after summing
every --rebin bins, over the reference's; the median and the 90th percentile over the pixels whose
reference profile holds at least --lit times the brightest pixel's light; the steady image's relative L1.

Writes OUT/NAME.csv, OUT/NAME.json and OUT/NAME.png (median error against render seconds, one line per
max_edge along spp; and against gather seconds).
"""

import argparse
import datetime
import hashlib
import json
import os
import pathlib
import platform
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tprf_runs as tr  # noqa: E402
from accuracy_vs_flat import Reference  # noqa: E402


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(tr.ROOT / "meshes" / "corner.json"))
    p.add_argument("--size", type=int, default=None, help="camera width and height")
    p.add_argument("--bins", type=int, default=None)
    p.add_argument("--bin-width", type=float, default=None)
    p.add_argument("--spp", default="4,16,64,256")
    p.add_argument("--max-edge", default="0.1,0.05,0.025")
    p.add_argument("--method", choices=["hierarchical", "flat", "scene"], default="scene",
                   help="links of the sweep's renders (default: as the scene says)")
    p.add_argument("--ref-spp", type=int, default=1024)
    p.add_argument("--ref-max-edge", type=float, default=0.0125)
    p.add_argument("--ref-tolerance", type=float, default=0.0003)
    p.add_argument("--ref-check", action="store_true")
    p.add_argument("--keep-reference", action="store_true",
                   help="reuse a kept reference of the same settings even if another binary made it")
    tr.add_run_args(p)
    return p.parse_args()


def variant(base, spp, max_edge, method, tolerance=None):
    scene = json.loads(json.dumps(base))
    scene["camera"]["spp"] = spp
    scene.setdefault("patches", {})["max_edge"] = max_edge
    tr.set_links(scene, method, tolerance)
    return scene


def binary_stamp(path):
    """The binary's size and time, and the commit of the checkout (what made a kept reference)."""
    st = os.stat(path)
    try:
        commit = subprocess.run(["git", "-C", str(tr.ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return f"{commit}:{st.st_size}-{int(st.st_mtime)}"


def reference(args, base, out, name):
    """The reference render's directory, rendered unless a kept one has the same scene and binary."""
    scene = variant(base, args.ref_spp, args.ref_max_edge, "hierarchical", args.ref_tolerance)
    key = hashlib.sha256(json.dumps(scene, sort_keys=True).encode()).hexdigest()
    ref_dir = out / f"{name}-reference"
    stamp = ref_dir / "settings.sha256"
    if stamp.exists() and (ref_dir / "transient.npy").exists():
        kept_key, _, kept_binary = stamp.read_text().strip().partition(" ")
        if kept_key == key and (args.keep_reference or kept_binary == binary_stamp(args.tprf)):
            print(f"[gather] reusing the reference in {ref_dir} (made by {kept_binary or '?'})", file=sys.stderr)
            return ref_dir, json.loads((ref_dir / "record.json").read_text())
    shutil.rmtree(ref_dir, ignore_errors=True)
    print(f"[gather] reference: spp {args.ref_spp}, max_edge {args.ref_max_edge}, hierarchical "
          f"{args.ref_tolerance:g} ...", file=sys.stderr, flush=True)
    rec, run_dir = tr.render(args.tprf, scene, out, f"{name}-reference", args.threads, args.timeout, keep=True)
    (run_dir / "record.json").write_text(json.dumps(rec))
    stamp.write_text(f"{key} {binary_stamp(args.tprf)}\n")
    return run_dir, rec


def plot(rows, title, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    edges = sorted({r["max_edge"] for r in rows})
    for ax, (xkey, xlabel) in zip(axes, [("seconds.total", "render seconds (total)"),
                                         ("seconds.gather", "gather seconds")]):
        for k, edge in enumerate(edges):
            pts = sorted((r for r in rows if r["max_edge"] == edge), key=lambda r: r["spp"])
            x = [r[xkey] for r in pts]
            y = [r["transient_rel_l1_median"] for r in pts]
            ax.plot(x, y, marker="o", color=f"C{k}", label=f"max_edge {edge:g} ({pts[0]['patches']} patches)")
            for r, xi, yi in zip(pts, x, y):
                ax.annotate(f"{r['spp']}", (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7)
        for level in (0.02, 0.005):
            ax.axhline(level, color="grey", linestyle=":", linewidth=0.8)
        tr.style_loglog(ax, xlabel, "median pixel rel. L1 of the time profile")
    tr.finish_figure(fig, axes, f"{title} (labels: spp; dotted: 2% and 0.5%)", path)


def main():
    args = parse_args()
    base = tr.base_scene(args)
    stem = pathlib.Path(args.scene).stem
    name = args.name or f"gather_{stem}"
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    spps = [int(s) for s in args.spp.split(",")]
    edges = [float(e) for e in args.max_edge.split(",")]

    ref_dir, ref_rec = reference(args, base, out, name)
    ref = Reference(ref_dir, args.rebin, args.lit)
    if not ref.lit.any():
        sys.exit(f"gather_accuracy: no light reaches the camera in the reference's window ({ref_dir}): "
                 "more --bins or a wider --bin-width")
    cam = base["camera"]
    title = (f"{stem}, {cam['width']}x{cam['height']} px, {base['time']['bins']} bins; reference spp "
             f"{args.ref_spp}, max_edge {args.ref_max_edge:g} ({ref_rec['patches']} patches)")
    scratch = pathlib.Path(tempfile.mkdtemp(prefix=".gather-scratch-", dir=out))
    rows, checks = [], []
    try:
        if args.ref_check:
            # Patches: the reference's spp at twice its patch size, against the reference. Samples: a
            # quarter of its spp at that patch size, against the first check (spp converges the same
            # way at either patch size, and this avoids a second link stage at the reference's).
            print("[gather] check: ref max_edge x2 ...", file=sys.stderr, flush=True)
            coarse = variant(base, args.ref_spp, 2 * args.ref_max_edge, "hierarchical", args.ref_tolerance)
            rec, coarse_dir = tr.render(args.tprf, coarse, scratch, "check_patches", args.threads, args.timeout, keep=True)
            rec.update(ref.errors(coarse_dir), check="ref max_edge x2, against the reference")
            checks.append(rec)
            print("[gather] check: ref spp / 4 ...", file=sys.stderr, flush=True)
            coarse["camera"]["spp"] = max(1, args.ref_spp // 4)
            rec, run_dir = tr.render(args.tprf, coarse, scratch, "check_spp", args.threads, args.timeout, keep=True)
            rec.update(Reference(coarse_dir, args.rebin, args.lit).errors(run_dir),
                       check="ref spp / 4 at max_edge x2, against the first check")
            shutil.rmtree(run_dir)
            shutil.rmtree(coarse_dir)
            checks.append(rec)
        for edge in edges:
            for spp in spps:
                print(f"[gather] max_edge {edge:g}, spp {spp} ...", file=sys.stderr, flush=True)
                rec, run_dir = tr.render(args.tprf, variant(base, spp, edge, args.method), scratch, "run",
                                         args.threads, args.timeout, keep=True)
                rec.update(ref.errors(run_dir), spp=spp, max_edge=edge)
                shutil.rmtree(run_dir)
                rows.append(rec)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    when = datetime.datetime.now().isoformat(timespec="seconds")
    print(f"\n{title}; lit pixels: {int(ref.lit.sum())} of {ref.lit.size}; {os.cpu_count()} cores, "
          f"{platform.node()}, {when}\n")
    pct = lambda v: f"{100 * v:.3g}%"  # noqa: E731
    if checks:
        print(tr.markdown_table(["reference check", "patches", "spp", "transient median", "p90", "steady"],
                                [[c["check"], c["patches"], c["camera.spp"], pct(c["transient_rel_l1_median"]),
                                  pct(c["transient_rel_l1_p90"]), pct(c["steady_rel_l1"])] for c in checks]))
        print()
    headers = ["max_edge", "patches", "spp", "gather s", "total s", "peak MB",
               f"transient median (rebin {args.rebin})", "p90", "steady rel L1"]
    print(tr.markdown_table(headers, [[f"{r['max_edge']:g}", r["patches"], r["spp"], tr.fmt(r["seconds.gather"], 3),
                                       tr.fmt(r["seconds.total"], 3), tr.fmt(r["peak_rss_mb"], 4),
                                       pct(r["transient_rel_l1_median"]), pct(r["transient_rel_l1_p90"]),
                                       pct(r["steady_rel_l1"])] for r in rows]))
    tr.write_results(out, name, args, when, {"reference": ref_rec, "checks": checks, "rows": rows}, checks + rows,
                     (lambda path: plot(rows, title, path)) if rows else None)


if __name__ == "__main__":
    main()
