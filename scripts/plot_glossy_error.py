#!/usr/bin/env python3
"""The glossy cells' error against their resolution (docs/method.md, "Glossy patches in the transport").

Runs GlossyTransport.ErrorAgainstTheResolution of the test binary (a diffuse wall seen in a metal floor
of roughness 0.2 and 0.5, R = 2, 3, 4, each floor pixel against the integral over the wall) and draws
the median and p90 error per pixel against R, with each render's seconds.

    scripts/plot_glossy_error.py [BUILD_DIR] [OUT_PNG]   (defaults: build, docs/images/glossy-error.png)
"""
import os
import re
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    build = sys.argv[1] if len(sys.argv) > 1 else "build"
    out = sys.argv[2] if len(sys.argv) > 2 else "docs/images/glossy-error.png"
    env = dict(os.environ, TPRF_GLOSSY_TABLE="1")
    run = subprocess.run([os.path.join(build, "tests", "tprf_tests"),
                          "--gtest_filter=GlossyTransport.ErrorAgainstTheResolution"],
                         env=env, capture_output=True, text=True, check=True)
    rows = re.findall(r"roughness ([\d.]+)\s+R (\d+)\s+median ([\d.]+)\s+p90 ([\d.]+).*?seconds ([\d.]+)", run.stdout)
    if not rows:
        sys.exit("no table in the test's output:\n" + run.stdout)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.6))
    for k, roughness in enumerate(sorted({r[0] for r in rows})):
        sel = [r for r in rows if r[0] == roughness]
        rings = [int(r[1]) for r in sel]
        colour = f"C{k}"
        ax.plot(rings, [100 * float(r[2]) for r in sel], "o-", color=colour, label=f"roughness {roughness}, median")
        ax.plot(rings, [100 * float(r[3]) for r in sel], "s--", color=colour, label=f"roughness {roughness}, p90")
        bx.plot(rings, [float(r[4]) for r in sel], "o-", color=colour, label=f"roughness {roughness}")
        for r in sel:
            print(f"roughness {r[0]}  R {r[1]}  median {100 * float(r[2]):.1f}%  p90 {100 * float(r[3]):.1f}%  {r[4]} s")
    ax.set_yscale("log")
    for a in (ax, bx):
        a.set_xticks(sorted({int(r[1]) for r in rows}))
    ax.set_xlabel("glossy_resolution R (4 R^2 cells)")
    ax.set_ylabel("error per pixel, %")
    ax.set_title("wall seen in a metal floor")
    ax.legend(fontsize=7)
    bx.set_xlabel("glossy_resolution R")
    bx.set_ylabel("render seconds")
    bx.set_title("the test's render (2 cores)")
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("wrote", out)


if __name__ == "__main__":
    main()
