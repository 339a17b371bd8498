#!/usr/bin/python3
"""Scaling sweep: renders a scene (default the Cornell box) at patch counts from 4k to 1M and fits how links,
link seconds, solve seconds and peak memory grow with the number of patches.

usage: /usr/bin/python3 bench/scaling_sweep.py [--method hierarchical|flat|scene] [--tolerance 0.001]
           [--targets 4000,16000,64000,256000,1000000 | --edges 0.05,0.025] [--max-patches N]
           [--bins 512] [--bin-width 0.01] [--size 96] [--spp 4] [--threads N] [--timeout S]
           [--scene meshes/cornell-box.json] [--tprf build/bin/tprf] [--out bench/out] [--name NAME]

Each variant is the scene with patches.max_edge set, the links block set by --method ("scene": left as the
scene file has it, or absent, which is what a build from before the links block needs), the camera and
time axis set by --size/--spp/--bins/--bin-width, rendered by one `tprf render -q` process under
/usr/bin/time -v. The numbers come from render.json (patches, links, seconds per phase, peak_rss_mb,
solver.*) and from time -v (max RSS, wall). The max_edge of each target is found from the patch count
that build_patches would give (rectangles and OBJ meshes are counted here exactly; for other scenes
pass --edges).

Defaults: 512 bins of 0.01 m (the window of the default scene's 1024 bins of 0.005 m, with half the
bins), 96 x 96 pixels, spp 4. With --method flat the default --max-patches is 20000 (flat links at
64k patches need about 15 GB); otherwise 1.1M. A render that fails (for example exit 2: its memory
estimate is over tprf's --max-memory) is recorded and ends the sweep: larger ones would fail too.

Writes OUT/NAME.csv (one row per render, every render.json field flattened) and OUT/NAME.json (rows,
fits, settings); NAME defaults to scaling_<method>[_tol<tolerance>]. Renders go to a scratch folder
OUT/.sweep-scratch-* that is removed at the end (cubes can be GBs; /tmp may be in memory).
"""

import argparse
import datetime
import json
import math
import os
import pathlib
import platform
import shutil
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tprf_runs as tr  # noqa: E402

FITS = [("links", "links"), ("link seconds", "seconds.links"), ("solve seconds", "seconds.solve"),
        ("total seconds", "seconds.total"), ("peak RSS MB", "peak_rss_mb")]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(tr.ROOT / "meshes" / "cornell-box.json"))
    p.add_argument("--method", choices=["hierarchical", "flat", "scene"], default="hierarchical")
    p.add_argument("--tolerance", type=float, default=None, help="links.tolerance (hierarchical; default: tprf's)")
    p.add_argument("--targets", default="4000,16000,64000,256000,1000000", help="patch counts, comma-separated")
    p.add_argument("--edges", default=None, help="max_edge values instead of --targets, comma-separated")
    p.add_argument("--max-patches", type=int, default=None,
                   help="skip targets above this (default 20000 for flat, else 1100000)")
    p.add_argument("--bins", type=int, default=512)
    p.add_argument("--bin-width", type=float, default=0.01)
    p.add_argument("--size", type=int, default=96, help="camera width and height")
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--timeout", type=float, default=None, help="seconds per render")
    p.add_argument("--tprf", default=tr.default_tprf())
    p.add_argument("--out", default=str(tr.ROOT / "bench" / "out"))
    p.add_argument("--name", default=None)
    return p.parse_args()


def plan(args, scene):
    """[(target or None, max_edge, expected patches or None)] in increasing size."""
    count = tr.patch_counter(scene)
    if args.edges:
        edges = sorted((float(e) for e in args.edges.split(",")), reverse=True)
        return [(None, e, count(e) if count else None) for e in edges]
    if count is None:
        sys.exit("scaling_sweep: this scene has non-OBJ meshes; pass --edges")
    out = []
    for target in sorted(int(float(t)) for t in args.targets.split(",")):
        edge = tr.max_edge_for(count, target)
        out.append((target, edge, count(edge)))
    return out


def main():
    args = parse_args()
    tr.check_tprf(args.tprf)
    max_patches = args.max_patches or (20000 if args.method == "flat" else 1100000)
    name = args.name or ("scaling_" + args.method +
                         (f"_tol{args.tolerance:g}" if args.method == "hierarchical" and args.tolerance else ""))
    base = tr.load_scene(args.scene)
    tr.set_links(base, args.method, args.tolerance)
    tr.set_camera_time(base, args)
    runs = plan(args, base)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    rows, stopped = [], None
    scratch = tempfile.mkdtemp(prefix=".sweep-scratch-", dir=out)
    try:
        for target, edge, expected in runs:
            if expected is not None and expected > max_patches:
                stopped = f"max_edge {edge} ({expected} patches) is above --max-patches {max_patches}"
                break
            scene = json.loads(json.dumps(base))
            scene.setdefault("patches", {})["max_edge"] = edge
            print(f"[sweep] max_edge {edge}: {expected or '?'} patches, {args.method} ...", file=sys.stderr, flush=True)
            try:
                rec, _ = tr.render(args.tprf, scene, scratch, f"e{edge}", args.threads, args.timeout)
            except tr.RenderFailed as e:
                stopped = f"max_edge {edge} ({expected or '?'} patches): exit {e.status}: {e}"
                break
            rec.update({"target": target, "max_edge": edge, "method": args.method, "tolerance": args.tolerance})
            rows.append(rec)
            print(f"[sweep]   {rec['patches']} patches, {rec['links']} links, {rec['seconds.total']:.1f} s, "
                  f"{rec['peak_rss_mb']:.0f} MB", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    if stopped:
        print(f"[sweep] stopped: {stopped}", file=sys.stderr)
    report(args, rows, stopped, out, name)


def report(args, rows, stopped, out, name):
    n = [r["patches"] for r in rows]
    fits = {label: tr.loglog_slope(n, [r.get(key) for r in rows]) for label, key in FITS}
    # Link memory: whatever render.json calls it (a key naming links and MB or bytes), if anything.
    mem_keys = [k for k in (rows[0] if rows else {}) if "link" in k and ("mb" in k or "bytes" in k)]
    for k in mem_keys:
        fits[k] = tr.loglog_slope(n, [r.get(k) for r in rows])

    headers = ["max_edge", "patches", "links", "links/patch", "links s", "solve s", "gather s", "total s",
               "peak MB", "time -v MB"] + mem_keys
    table = []
    for r in rows:
        table.append([r["max_edge"], r["patches"], r["links"], tr.fmt(r["links"] / r["patches"]),
                      tr.fmt(r["seconds.links"]), tr.fmt(r["seconds.solve"]), tr.fmt(r["seconds.gather"]),
                      tr.fmt(r["seconds.total"]), tr.fmt(r["peak_rss_mb"]), tr.fmt(r.get("time_v.max_rss_mb"))]
                     + [tr.fmt(r.get(k)) for k in mem_keys])
    when = datetime.datetime.now().isoformat(timespec="seconds")
    print(f"\n{args.method} links" + (f", tolerance {args.tolerance:g}" if args.tolerance else "") +
          f"; {args.bins} bins of {args.bin_width} m, {args.size}x{args.size} px, spp {args.spp}; "
          f"{os.cpu_count()} cores, {platform.node()}, {when}\n")
    print(tr.markdown_table(headers, table))
    nlogn = tr.loglog_slope(n, [x * math.log(x) for x in n]) if len(n) >= 2 else None
    print(f"\nexponents (least squares of log y on log patches; N log N over these points: {tr.fmt(nlogn, 3)}):")
    for label, slope in fits.items():
        local = None
        key = dict(FITS).get(label, label)
        if len(rows) >= 2:
            local = tr.loglog_slope(n[-2:], [r.get(key) for r in rows[-2:]])
        print(f"  {label:16s} {tr.fmt(slope, 3):>6s}   (last two points: {tr.fmt(local, 3)})")
    if stopped:
        print(f"\nstopped: {stopped}")

    csv_path, json_path = out / f"{name}.csv", out / f"{name}.json"
    tr.write_csv(csv_path, rows)
    settings = {k: v for k, v in vars(args).items()}
    json_path.write_text(json.dumps({"date": when, "host": platform.node(), "cores": os.cpu_count(),
                                     "settings": settings, "stopped": stopped, "exponents": fits,
                                     "nlogn_exponent": nlogn,
                                     "rows": rows}, indent=1) + "\n")
    print(f"\nwrote {csv_path} and {json_path}")


if __name__ == "__main__":
    main()
