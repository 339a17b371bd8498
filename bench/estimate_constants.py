#!/usr/bin/env python3
"""Re-measures the resource estimate's constants and checks the estimate against renders.

    python3 bench/estimate_constants.py [--build build] [--threads 2] [--no-bench] [--no-renders]

1. Constants. Every measured constant of lib/src/pipeline/info.cpp is written
       constexpr double kName = value;  // BM_Case[/args]: counter
   naming the tprf_bench case and the counter that measures it, in the constant's unit. This runs those
   cases once (build/bench/tprf_bench, JSON) and prints each constant beside its measured value. A few
   counters are worked out here from a case's others (DERIVED below); `tprf_tiny_render` is a render of
   two patches (TINY): its peak resident memory (the process before any stage) and its write phase's
   seconds (what that phase costs besides the cubes). Nothing is asserted: a constant far from its
   measure is for the reader to update.
2. Renders. Renders every sample scene of meshes/ with `tprf render --threads N` and prints what
   `tprf info` estimated (peak memory, seconds) beside what render.json measured. Exits 1 when either
   is off by more than a factor of 2 for some scene: the estimate's promise. (Seconds depend on the
   machine and on what else runs on it: this is a benchmark, and no CTest test asserts them.)

Needs a Release build with the benchmarks (cmake --build build).
"""
import argparse
import json
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
INFO = ROOT / "lib" / "src" / "pipeline" / "info.cpp"
SCENES = ["corner.json", "cornell-box.json", "cornell-box.xml", "plates.json", "mesh-on-floor.json",
          "statue-on-floor.json", "glossy-box.json"]
MIB = 1024.0 * 1024.0  # render.json's peak_rss_mb is VmHWM in MiB
CONSTANT = re.compile(r"^\s*constexpr double (k\w+) = ([^;]+);(?:\s*//\s*(\S+): (\w+))?")

# Counters worked out from a case's others and the constants they are fitted with.
DERIVED = {
    "links_scale": lambda c, k: c["links"] / c["patches"] ** k["kHierarchicalLinksExponent"]
                                / math.sqrt(0.003 / c["tolerance"]),
    "seconds_scale": lambda c, k: c["seconds"] / c["patches"] ** k["kHierarchicalLinkSecondsExponent"]
                                  / math.sqrt(0.003 / c["tolerance"]),
    "ring_share_patches": lambda c, k: c["patches"] * min(c["ring_share"], 1.0) ** 3,
}
# The scene of tprf_tiny_render: two patches, 8 bins, 8 x 8 pixels.
TINY = {"time": {"bins": 8, "bin_width": 0.5, "unit": "m"},
        "camera": {"position": [0.5, -1.1, 0.9], "look_at": [0.5, 0.55, 0.25], "up": [0, 0, 1], "fov": 45,
                   "width": 8, "height": 8, "spp": 1},
        "lights": [{"type": "point", "position": [0.3, 0.45, 0.35], "intensity": 1.0}],
        "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0]},
                    {"type": "rectangle", "origin": [0, 1, 0], "u": [1, 0, 0], "v": [0, 0, 1]}],
        "patches": {"max_edge": 2.0}}
# Cases that must run before another, whose counter compares against them.
BEFORE = {"BM_TransientSolveBatch/K:16/grey:1": ["BM_TransientSolveBatch/K:1/grey:1"]}


def read_constants():
    """{name: value} of every constexpr double, and [(name, case, counter)] of the measured ones."""
    values, measured = {"kMB": 1e6, "kGB": 1e9}, []
    for line in INFO.read_text().splitlines():
        m = CONSTANT.match(line)
        if not m:
            continue
        name, expression, case, counter = m.groups()
        values[name] = float(eval(expression, {"__builtins__": {}}, dict(values)))
        if case:
            measured.append((name, case, counter))
    return values, measured


def case_name(name):
    """A tprf_bench result's name without the options Google Benchmark appends."""
    keep = [p for p in name.split("/") if not re.match(r"(iterations|min_time|repeats|threads):|real_time$", p)]
    return "/".join(keep)


def run_benchmarks(build, cases):
    wanted = list(dict.fromkeys(c for case in cases for c in BEFORE.get(case, []) + [case]))
    pattern = "^(" + "|".join(re.escape(c) for c in wanted) + ")(/|$)"
    with tempfile.NamedTemporaryFile(suffix=".json") as out:
        subprocess.run([str(build / "bench" / "tprf_bench"), "--benchmark_filter=" + pattern,
                        "--benchmark_out=" + out.name, "--benchmark_out_format=json"],
                       check=True, stdout=subprocess.DEVNULL)
        results = json.load(open(out.name))["benchmarks"]
    return {case_name(r["name"]): r for r in results if r.get("run_type", "iteration") == "iteration"}


def tiny_render(build):
    """tprf_tiny_render's counters: the render's peak resident memory, bytes, and its write phase, seconds."""
    with tempfile.TemporaryDirectory() as scratch:
        scene = Path(scratch) / "tiny.json"
        scene.write_text(json.dumps(TINY))
        subprocess.run([str(build / "bin" / "tprf"), "render", str(scene), "-o", str(Path(scratch) / "out"), "-q",
                        "--threads", "2"], check=True, stdout=subprocess.DEVNULL)
        record = json.load(open(Path(scratch) / "out" / "render.json"))
    return {"peak_bytes": record["peak_rss_mb"] * MIB, "write_seconds": record["seconds"]["write"]}


def report_constants(build):
    values, measured = read_constants()
    results = run_benchmarks(build, [case for _, case, _ in measured if case.startswith("BM_")])
    results["tprf_tiny_render"] = tiny_render(build)
    print(f"{'constant':32} {'info.cpp':>12} {'measured':>12} {'ratio':>7}  measured by")
    for name, case, counter in measured:
        if case not in results:
            value = None
        elif counter in DERIVED:
            value = DERIVED[counter](results[case], values)
        else:
            value = results[case].get(counter)
        shown = f"{value:12.4g} {value / values[name]:7.2f}" if value is not None else f"{'-':>12} {'-':>7}"
        print(f"{name:32} {values[name]:12.4g} {shown}  {case}: {counter}")


def estimate(build, scene, threads):
    """`tprf info`'s estimated peak (MB) and seconds; the process is stopped once it has printed them
    (it would go on to build the links)."""
    info = subprocess.Popen([str(build / "bin" / "tprf"), "info", str(scene), "--threads", str(threads), "-q"],
                            stdout=subprocess.PIPE, text=True)
    text = ""
    for line in info.stdout:
        text += line
        if line.startswith("estimate seconds"):
            break
    info.kill()
    info.wait()
    peak = float(re.search(r"peak memory (\d+) MB", text).group(1))
    seconds = dict(re.findall(r"(\w+) ([\d.]+)", re.search(r"estimate seconds: (.*)", text).group(1)))
    return peak, {k: float(v) for k, v in seconds.items()}


def render(build, scene, threads, out):
    subprocess.run([str(build / "bin" / "tprf"), "render", str(scene), "-o", str(out), "--threads", str(threads),
                    "-q"], check=True, stdout=subprocess.DEVNULL)
    record = json.load(open(out / "render.json"))
    return record["peak_rss_mb"] * MIB / 1e6, record["seconds"]


def report_renders(build, threads):
    worst = 1.0
    print(f"\n{'scene':22} {'peak MB est':>11} {'measured':>9} {'seconds est':>11} {'measured':>9}  phases est/measured")
    # Outside the tree: an interrupted run leaves no cubes where `git add` would take them.
    with tempfile.TemporaryDirectory(prefix="tprf-estimate-") as scratch:
        for name in SCENES:
            scene = ROOT / "meshes" / name
            peak, seconds = estimate(build, scene, threads)
            measured_peak, measured = render(build, scene, threads, Path(scratch) / name)
            phases = ", ".join(f"{p} {seconds.get(p, 0):.2f}/{measured.get(p, 0):.2f}"
                               for p in ("links", "solve", "gather", "write"))
            print(f"{name:22} {peak:11.0f} {measured_peak:9.0f} {seconds['total']:11.2f} {measured['total']:9.2f}  {phases}")
            for e, m in ((peak, measured_peak), (seconds["total"], measured["total"])):
                worst = max(worst, e / m, m / e)
    print(f"\nworst factor between estimate and measure: {worst:.2f} (the estimate aims at 2)")
    return worst <= 2.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", type=Path, default=ROOT / "build")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--no-bench", action="store_true", help="skip the constants' benchmarks")
    parser.add_argument("--no-renders", action="store_true", help="skip the sample scenes' renders")
    args = parser.parse_args()
    if not args.no_bench:
        report_constants(args.build.resolve())
    ok = True if args.no_renders else report_renders(args.build.resolve(), args.threads)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
