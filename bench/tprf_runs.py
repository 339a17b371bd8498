"""Shared by bench/scaling_sweep.py and bench/accuracy_vs_flat.py: scene variants, one `tprf render`
process per variant (under /usr/bin/time -v when it exists), render.json flattened, log-log fits.

Only the standard library here (numpy is imported by the scripts that need it).
"""

import json
import math
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def default_tprf():
    """$TPRF, else build/bin/tprf."""
    return os.environ.get("TPRF", str(ROOT / "build" / "bin" / "tprf"))


def load_scene(path):
    """The scene as a dict, with every mesh file made absolute (variants are written elsewhere)."""
    path = pathlib.Path(path).resolve()
    scene = json.loads(path.read_text())
    for obj in scene.get("objects", []):
        if "file" in obj and not os.path.isabs(obj["file"]):
            obj["file"] = str(path.parent / obj["file"])
    return scene


def set_links(scene, method, tolerance):
    """method: "flat" or "hierarchical" writes the links block; "scene" keeps the scene's own (or none,
    which is also what a build from before the links block needs)."""
    if method == "scene":
        return
    links = {"method": method}
    if method == "hierarchical" and tolerance is not None:
        links["tolerance"] = tolerance
    scene["links"] = links


def set_camera_time(scene, args):
    """--size, --spp, --bins, --bin-width (each when given)."""
    cam = scene["camera"]
    if getattr(args, "size", None):
        cam["width"] = cam["height"] = args.size
    if getattr(args, "spp", None):
        cam["spp"] = args.spp
    if getattr(args, "bins", None):
        scene["time"]["bins"] = args.bins
    if getattr(args, "bin_width", None):
        scene["time"]["bin_width"] = args.bin_width


def flatten(d, prefix=""):
    """{"seconds": {"links": 1}} -> {"seconds.links": 1}; lists are dropped."""
    out = {}
    for k, v in d.items():
        key = prefix + k
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        elif not isinstance(v, list):
            out[key] = v
    return out


def parse_time_v(text):
    """Maximum RSS (MB) and wall seconds from GNU time -v's report."""
    out = {}
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", text)
    if m:
        out["time_v.max_rss_mb"] = int(m.group(1)) / 1024.0
    m = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", text)
    if m:
        parts = [float(p) for p in m.group(1).split(":")]
        out["time_v.wall_s"] = sum(p * 60 ** i for i, p in enumerate(reversed(parts)))
    return out


class RenderFailed(Exception):
    def __init__(self, status, message):
        super().__init__(message)
        self.status = status


def render(tprf, scene, work_dir, name, threads=None, timeout=None, keep=False, extra_args=()):
    """Writes SCENE to WORK_DIR/NAME.json, renders it to WORK_DIR/NAME/, returns (flat record, out dir).

    The record holds render.json flattened plus time_v.* when /usr/bin/time exists. The output directory
    is deleted unless keep is true (then the caller owns it). A render that exits non-zero raises
    RenderFailed with tprf's last stderr line (exit 2: bad input, or a memory estimate over --max-memory).
    """
    work_dir = pathlib.Path(work_dir)
    scene_path = work_dir / f"{name}.json"
    scene_path.write_text(json.dumps(scene, indent=1))
    out_dir = work_dir / name
    cmd = [tprf, "render", str(scene_path), "-o", str(out_dir), "-q", *extra_args]
    if threads:
        cmd += ["--threads", str(threads)]
    timed = os.path.exists("/usr/bin/time")
    time_log = work_dir / f"{name}.time"
    if timed:
        cmd = ["/usr/bin/time", "-v", "-o", str(time_log)] + cmd
    start = time.monotonic()
    try:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        shutil.rmtree(out_dir, ignore_errors=True)
        raise RenderFailed(124, f"timed out after {timeout} s")
    wall = time.monotonic() - start
    if proc.returncode != 0:
        shutil.rmtree(out_dir, ignore_errors=True)
        lines = [l for l in proc.stderr.splitlines() if l.strip() and not l.startswith("\tCommand")]
        raise RenderFailed(proc.returncode, lines[-1] if lines else f"exit status {proc.returncode}")
    record = flatten(json.loads((out_dir / "render.json").read_text()))
    record["wall_s"] = wall
    if timed and time_log.exists():
        record.update(parse_time_v(time_log.read_text()))
        time_log.unlink()
    if not keep:
        shutil.rmtree(out_dir, ignore_errors=True)
    return record, out_dir


def loglog_slope(xs, ys):
    """Least-squares slope of log y against log x over the points where both are > 0 (None below 2)."""
    pts = [(math.log(x), math.log(y)) for x, y in zip(xs, ys)
           if isinstance(x, (int, float)) and isinstance(y, (int, float)) and x > 0 and y > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    if sxx == 0:
        return None
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx


def write_csv(path, rows):
    """The rows (dicts) as a CSV whose columns are every key of any row, in first-seen order."""
    import csv
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def style_loglog(ax, xlabel, ylabel):
    """Log axes, labels and a light grid (matplotlib axes)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)


def add_run_args(parser, rebin=True):
    """The options every accuracy script shares: --rebin, --lit (when rebin), --threads, --timeout,
    --tprf, --out, --name."""
    if rebin:
        parser.add_argument("--rebin", type=int, default=4)
        parser.add_argument("--lit", type=float, default=1e-3,
                            help="lit pixel: profile >= LIT x the brightest pixel's")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--timeout", type=float, default=None)
    parser.add_argument("--tprf", default=default_tprf())
    parser.add_argument("--out", default=str(ROOT / "bench" / "out"))
    parser.add_argument("--name", default=None)


def write_results(out, name, args, when, extra, csv_rows, draw=None):
    """OUT/NAME.csv (csv_rows), OUT/NAME.json (date, host, cores, the settings and `extra`) and, when
    draw is given, OUT/NAME.png drawn by draw(path) (skipped, with a note, without matplotlib); prints
    what it wrote."""
    import platform
    out = pathlib.Path(out)
    write_csv(out / f"{name}.csv", csv_rows)
    record = {"date": when, "host": platform.node(), "cores": os.cpu_count(), "settings": vars(args)}
    (out / f"{name}.json").write_text(json.dumps({**record, **extra}, indent=1) + "\n")
    written = [out / f"{name}.csv", out / f"{name}.json"]
    if draw:
        try:
            draw(out / f"{name}.png")
            written.append(out / f"{name}.png")
        except ImportError as e:
            print(f"no plot ({e}): run with a Python that has matplotlib (Debian: /usr/bin/python3)")
    print("\nwrote " + ", ".join(str(p) for p in written))


def finish_figure(fig, axes, title, path):
    """The first axes' legend, the title, the PNG written and the figure closed."""
    import matplotlib.pyplot as plt
    axes[0].legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def base_scene(args):
    """The binary checked, and args.scene loaded with --size, --spp, --bins, --bin-width applied."""
    check_tprf(args.tprf)
    base = load_scene(args.scene)
    set_camera_time(base, args)
    return base


def markdown_table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "| " + " | ".join("---" for _ in headers) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def fmt(v, digits=4):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _read_obj(path):
    vertices, faces = [], []
    for line in pathlib.Path(path).read_text().splitlines():
        words = line.split()
        if words and words[0] == "v":
            vertices.append(tuple(float(w) for w in words[1:4]))
        elif words and words[0] == "f":
            faces.append([int(w.split("/")[0]) - 1 for w in words[1:]])
    return vertices, faces


def _linear_part(transform):
    """The 3x3 linear part of a scene transform (scale, then rotate), as rows."""
    if "matrix" in transform:
        m = transform["matrix"]
        return [m[0:3], m[4:7], m[8:11]]
    s = transform.get("scale", 1.0)
    s = [s, s, s] if isinstance(s, (int, float)) else s
    r = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    if "rotate" in transform:
        ax = transform["rotate"]["axis"]
        n = math.sqrt(sum(a * a for a in ax))
        x, y, z = (a / n for a in ax)
        a = math.radians(transform["rotate"]["angle"])
        c, s_, t = math.cos(a), math.sin(a), 1 - math.cos(a)
        r = [[t * x * x + c, t * x * y - s_ * z, t * x * z + s_ * y],
             [t * x * y + s_ * z, t * y * y + c, t * y * z - s_ * x],
             [t * x * z - s_ * y, t * y * z + s_ * x, t * z * z + c]]
    return [[r[i][j] * s[j] for j in range(3)] for i in range(3)]


def _pieces(length, max_edge):
    return max(1, math.ceil(length / max_edge - 1e-9))  # as lib/src/geometry/patches.cpp


def patch_counter(scene):
    """A function max_edge -> patch count, as build_patches counts them, for scenes of rectangles and OBJ
    meshes (None for other mesh formats): rectangles in nu x nv pieces, mesh triangles (fan-triangulated)
    in n^2 pieces, n from the longest edge."""
    rects, edges = [], []  # rectangle side lengths; longest edge of each mesh triangle
    for obj in scene["objects"]:
        sides = 2 if obj.get("two_sided") else 1
        if obj["type"] == "rectangle":
            rects += [(math.dist(obj["u"], [0, 0, 0]), math.dist(obj["v"], [0, 0, 0]))] * sides
            continue
        if not obj["file"].lower().endswith(".obj"):
            return None
        vertices, faces = _read_obj(obj["file"])
        lin = _linear_part(obj.get("transform", {}))
        vertices = [tuple(sum(lin[i][j] * v[j] for j in range(3)) for i in range(3)) for v in vertices]
        for f in faces:
            for i in range(1, len(f) - 1):
                a, b, c = vertices[f[0]], vertices[f[i]], vertices[f[i + 1]]
                edges += [max(math.dist(a, b), math.dist(b, c), math.dist(c, a))] * sides

    def count(max_edge):
        return sum(_pieces(u, max_edge) * _pieces(v, max_edge) for u, v in rects) + \
            sum(_pieces(e, max_edge) ** 2 for e in edges)
    return count


def max_edge_for(count, target):
    """The largest max_edge (to 4 significant digits) whose patch count is at least target."""
    lo, hi = 1e-6, 10.0  # count(lo) >= target > count(hi) for any sane scene
    for _ in range(100):
        mid = math.sqrt(lo * hi)
        if count(mid) >= target:
            lo = mid
        else:
            hi = mid
    step = 10.0 ** (math.floor(math.log10(lo)) - 3)  # round down to 4 significant digits
    return float(f"{math.floor(lo / step) * step:.4g}")


def check_tprf(tprf):
    if not (os.path.isfile(tprf) and os.access(tprf, os.X_OK)):
        sys.exit(f"no tprf binary at {tprf} (build it: cmake --build build --target tprf_app; or pass --tprf)")
