#!/usr/bin/env python3
"""End-to-end Cornell box renders: 96 x 96 pixels, 2048 bins, all bounces, at
several patch sizes. Prints a Markdown table of each phase's seconds and the peak memory.

usage: bench/render_cornell.py [BUILD_DIR] [MAX_EDGE ...]    (defaults: build, 0.1 0.05)
"""
import json
import os
import subprocess
import sys
import tempfile

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
build = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "build")
edges = [float(e) for e in sys.argv[2:]] or [0.1, 0.05]
scene = json.load(open(os.path.join(root, "meshes", "cornell-box.json")))
scene["time"]["bins"] = 2048
scene["camera"].update({"width": 96, "height": 96})
for o in scene["objects"]:
    if o["type"] == "mesh":
        o["file"] = os.path.join(root, "meshes", o["file"])

print("| max_edge | patches | links | bins | load | patches | links | solve | gather | write | total s | peak MB |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
with tempfile.TemporaryDirectory() as tmp:
    for edge in edges:
        scene["patches"]["max_edge"] = edge
        path = os.path.join(tmp, "scene.json")
        json.dump(scene, open(path, "w"))
        out = os.path.join(tmp, "out")
        subprocess.run([os.path.join(build, "bin", "tprf"), "render", path, "-o", out, "-q"], check=True)
        r = json.load(open(os.path.join(out, "render.json")))
        s = r["seconds"]
        print(f"| {edge} | {r['patches']} | {r['links']} | {r['bins']} | {s['load']:.2f} | {s['patches']:.2f} | "
              f"{s['links']:.2f} | {s['solve']:.2f} | {s['gather']:.2f} | {s['write']:.2f} | {s['total']:.2f} | "
              f"{r['peak_rss_mb']:.0f} |", flush=True)
