#!/usr/bin/python3
"""NLOS capture benchmark (issue 14): a confocal scan of a hidden scanned bust in front of a 2 m relay
wall, rendered by `tprf render` as a user would, timed from render.json.

Usage: bench/capture_bench.py [--tprf build/bin/tprf] [--grid 64] [--bins 512] [--cell 0.0165]
                              [--out bench/out] [--threads N] [--skip-all] [--launcher "mpirun -np 2"]
                              [--march-bin-factor F] [--march-grid-step S] [--name NAME]

Runs, each a separate `tprf render` process:
  1. third bounce only (max_bounces 3): laser spot -> hidden surface -> sensor point, no links;
  2. every bounce (max_bounces null): the batched march over hierarchical links;
  3. one laser point with every bounce: what each of GRID x GRID separate renders would cost, for the ratio.
With --launcher, run 2 is started through it (MPI ranks sharing the laser points, docs/mpi.md).
With --march-bin-factor, runs 2 and 3 march the later bounces on bins F times wider, and with
--march-grid-step run 2 marches them at every S-th grid point only, moving their light to the others
(docs/capture.md; bench/capture_march_factor.py measures what both cost in accuracy).
Prints the seconds, render.json's phases and peak memory, and writes OUT/capture_bench.json (or NAME.json).
The hidden mesh is scripts/make_statue_mesh.py's bust at --cell (0.0165: about 12k triangles).
"""

import argparse
import json
import pathlib
import shlex
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
# The mesh script needs numpy: Debian's python3 has it (python3-numpy) where another on the PATH may not.
PYTHON = "/usr/bin/python3" if pathlib.Path("/usr/bin/python3").exists() else sys.executable


def scene(mesh, grid, bins, max_bounces, single=False, march_bin_factor=1, march_grid_step=1):
    g = {"origin": [-0.9, -0.9, 0], "u": [1.8, 0, 0], "v": [0, 1.8, 0], "nu": grid, "nv": grid}
    if single:  # the middle point of the full grid, alone
        step = 1.8 / grid
        g = {"origin": [-step / 2, -step / 2, 0], "u": [step, 0, 0], "v": [0, step, 0], "nu": 1, "nv": 1}
    return {
        "time": {"bins": bins, "bin_width": 4.096 / bins, "start": 0.0},
        "objects": [
            {"type": "rectangle", "origin": [-1, -1, 0], "u": [2, 0, 0], "v": [0, 2, 0], "albedo": 0.8},
            # The bust faces -y and stands along +z; turned to face the wall (-z), 1 m in front of it.
            {"type": "mesh", "file": str(mesh), "albedo": 0.7,
             "transform": {"scale": 0.5, "rotate": {"axis": [1, 0, 0], "angle": 90}, "translate": [0, 0.25, 1.0]}},
        ],
        "patches": {"max_edge": 0.05},
        "links": {"method": "hierarchical", "tolerance": 0.001},
        "capture": {"type": "confocal", "laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, -1.5, 0.3]},
                    "grid": g, "max_bounces": max_bounces, "march_bin_factor": march_bin_factor,
                    "march_grid_step": march_grid_step},
    }


def render(tprf, workdir, name, body, threads, launcher=""):
    path = workdir / f"{name}.json"
    path.write_text(json.dumps(body, indent=1))
    out = workdir / name
    cmd = shlex.split(launcher) + [str(tprf), "render", str(path), "-o", str(out), "-q"]
    if threads:
        cmd += ["--threads", str(threads)]
    start = time.perf_counter()
    subprocess.run(cmd, check=True)
    wall = time.perf_counter() - start
    record = json.loads((out / "render.json").read_text())
    record["wall_seconds"] = wall
    return record


def describe(name, r):
    c = r.get("capture", {})
    s = r["seconds"]
    cs = c.get("seconds", {})
    return (f"{name:<24} {r['wall_seconds']:8.2f} s  (patches {s['patches']:.2f}, links {s['links']:.2f}, "
            f"views {cs.get('views', 0):.2f}, solve {cs.get('solve', 0):.2f}, gather {cs.get('gather', 0):.2f}, "
            f"write {s['write']:.2f}); peak {r['peak_rss_mb']:.0f} MB; {r['patches']} patches, {r['links']} links, "
            f"batch {c.get('batch')}, marches {c.get('marches')}, ranks {c.get('ranks', 1)}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tprf", type=pathlib.Path, default=ROOT / "build" / "bin" / "tprf")
    parser.add_argument("--grid", type=int, default=64)
    parser.add_argument("--bins", type=int, default=512)
    parser.add_argument("--cell", type=float, default=0.0165)
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "bench" / "out")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--skip-all", action="store_true", help="only the third-bounce run")
    parser.add_argument("--launcher", default="", help="put before tprf for the every-bounce run, e.g. 'mpirun -np 2'")
    parser.add_argument("--march-bin-factor", type=int, default=1, help="capture.march_bin_factor of the every-bounce runs")
    parser.add_argument("--march-grid-step", type=int, default=1, help="capture.march_grid_step of the every-bounce scan")
    parser.add_argument("--name", default="capture_bench", help="the results file's name, without .json")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="tprf_capture_bench_") as tmp:
        work = pathlib.Path(tmp)
        mesh = work / "bust.ply"
        subprocess.run([PYTHON, str(ROOT / "scripts" / "make_statue_mesh.py"), str(mesh), "--cell",
                        str(args.cell)], check=True, stdout=subprocess.DEVNULL)
        header = mesh.read_bytes()[:400].decode("latin-1")
        faces = int(header.split("element face ")[1].split()[0])
        print(f"hidden mesh: {faces} triangles; {args.grid}x{args.grid} confocal, {args.bins} bins")
        results = {"grid": args.grid, "bins": args.bins, "triangles": faces, "march_bin_factor": args.march_bin_factor,
                   "march_grid_step": args.march_grid_step}
        results["third"] = render(args.tprf, work, "third", scene(mesh, args.grid, args.bins, 3), args.threads)
        print(describe("third bounce only", results["third"]))
        if not args.skip_all:
            results["all"] = render(args.tprf, work, "all",
                                    scene(mesh, args.grid, args.bins, None, march_bin_factor=args.march_bin_factor,
                                          march_grid_step=args.march_grid_step),
                                    args.threads, args.launcher)
            print(describe("every bounce", results["all"]))
            results["single"] = render(args.tprf, work, "single",
                                       scene(mesh, args.grid, args.bins, None, True, args.march_bin_factor), args.threads)
            print(describe("one laser point", results["single"]))
            separate = results["single"]["wall_seconds"] * args.grid * args.grid
            ratio = separate / results["all"]["wall_seconds"]
            results["separate_seconds"] = separate
            results["ratio"] = ratio
            print(f"{args.grid * args.grid} separate renders: {separate:.0f} s; the batched capture is {ratio:.0f}x "
                  f"faster")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
