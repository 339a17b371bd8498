#!/usr/bin/env python3
"""Writes the sample meshes in meshes/: a regular tetrahedron in every format tprf reads, and an icosphere.

Usage: scripts/make_sample_meshes.py [OUTPUT_DIR]   (default: meshes/ beside this script's folder)

Every face is counter-clockwise seen from outside, so the front side (docs/scene.md: the side the winding faces)
points away from the solid. Coordinates are written with 6 decimals; the output is deterministic.
"""

import math
import pathlib
import sys


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def normalize(a):
    n = math.sqrt(dot(a, a))
    return tuple(x / n for x in a)


def face_normal(vertices, face):
    a, b, c = (vertices[i] for i in face)
    return normalize(cross(sub(b, a), sub(c, a)))


def orient_outward(vertices, faces):
    """Reverses faces whose winding faces the centre: the solids here are convex and star-shaped about it."""
    centre = tuple(sum(v[k] for v in vertices) / len(vertices) for k in range(3))
    out = []
    for f in faces:
        a = vertices[f[0]]
        if dot(face_normal(vertices, f), sub(a, centre)) < 0:
            f = tuple(reversed(f))
        out.append(tuple(f))
    return out


def tetrahedron():
    s = 1.0 / math.sqrt(3.0)  # circumradius 1
    vertices = [(s, s, s), (s, -s, -s), (-s, s, -s), (-s, -s, s)]
    faces = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
    return vertices, orient_outward(vertices, faces)


def icosphere(levels):
    t = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = [normalize(v) for v in [
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0),
        (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
        (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
             (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
             (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
             (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(levels):
        midpoints = {}

        def midpoint(i, j):
            key = (min(i, j), max(i, j))
            if key not in midpoints:
                a, b = vertices[i], vertices[j]
                vertices.append(normalize(tuple((x + y) / 2 for x, y in zip(a, b))))
                midpoints[key] = len(vertices) - 1
            return midpoints[key]

        refined = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            refined += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = refined
    return vertices, orient_outward(vertices, faces)


def fmt(v):
    return " ".join(f"{x:.6f}" for x in v)


def write_obj(path, vertices, faces, comment):
    lines = [f"# {comment}"] + [f"v {fmt(v)}" for v in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def write_off(path, vertices, faces):
    lines = ["OFF", f"{len(vertices)} {len(faces)} 0"] + [fmt(v) for v in vertices]
    lines += [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def write_ply(path, vertices, faces):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}",
             "property float x", "property float y", "property float z",
             f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    lines += [fmt(v) for v in vertices]
    lines += [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def write_stl(path, vertices, faces, name):
    lines = [f"solid {name}"]
    for f in faces:
        lines += [f"  facet normal {fmt(face_normal(vertices, f))}", "    outer loop"]
        lines += [f"      vertex {fmt(vertices[i])}" for i in f]
        lines += ["    endloop", "  endfacet"]
    lines.append(f"endsolid {name}")
    path.write_text("\n".join(lines) + "\n")


def main():
    default = pathlib.Path(__file__).resolve().parent.parent / "meshes"
    out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else default
    out.mkdir(parents=True, exist_ok=True)

    v, f = tetrahedron()
    write_obj(out / "tetra.obj", v, f, "regular tetrahedron, circumradius 1, outward CCW faces")
    write_ply(out / "tetra.ply", v, f)
    write_off(out / "tetra.off", v, f)
    write_stl(out / "tetra.stl", v, f, "tetra")

    v, f = icosphere(2)
    write_obj(out / "icosphere.obj", v, f, "icosphere: icosahedron subdivided twice, radius 1, outward CCW faces")


if __name__ == "__main__":
    main()
