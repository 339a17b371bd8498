#!/usr/bin/python3
"""Writes meshes/statue.ply: a procedural "scanned" bust on a plinth, about 60k triangles, binary PLY.

Usage: /usr/bin/python3 scripts/make_statue_mesh.py [OUTPUT.ply] [--cell H]
       (default: meshes/statue.ply beside this script's folder; H = 0.0079, the grid cell in mesh units)

The mesh is what a scan of a small marble bust looks like after surface reconstruction: one closed,
organic surface with detail at every scale, triangulated on a grid (as Poisson reconstruction and
marching cubes do), with no two faces alike. It is built from

  - a signed distance function: a plinth, chest, shoulders, neck, head, jaw, nose, brow and ears joined
    by smooth minimum, eye sockets carved out; plus fractal gradient noise (weathered stone, and a
    rougher, curly layer where the hair is);
  - naive surface nets on a regular grid (one vertex per cell the surface crosses, one quad per grid
    edge it crosses, split along the shorter diagonal), then three Newton steps that move every vertex
    onto the zero set.

Units: the bust is 1.0 tall (z up, base at z = 0, centred on the z axis), faces -y. Every face is
counter-clockwise seen from outside (docs/scene.md: the front side is the side the winding faces). The noise
uses an integer hash, not a random generator, so the file is the same on every machine and numpy
version (up to the last bit of float32 rounding of transcendental functions, which numpy takes from
the C library). Needs numpy (Debian: python3-numpy).
"""

import argparse
import pathlib
import sys

import numpy as np

# --------------------------------------------------------------------------------------------------
# Noise: 3D gradient noise on an integer lattice, gradients chosen by a 32-bit hash (fixed seed).

SEED = 20240611
_GRADIENTS = np.array([[1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0], [1, 0, 1], [-1, 0, 1],
                       [1, 0, -1], [-1, 0, -1], [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1],
                       [1, 1, 0], [-1, 1, 0], [0, -1, 1], [0, -1, -1]], dtype=np.float64)


def _hash(ix, iy, iz, seed):
    """A 32-bit integer hash of lattice coordinates (murmur3's finaliser on a mixed key)."""
    with np.errstate(over="ignore"):
        h = (ix.astype(np.uint32) * np.uint32(0x8DA6B343)) ^ (iy.astype(np.uint32) * np.uint32(0xD8163841)) \
            ^ (iz.astype(np.uint32) * np.uint32(0xCB1AB31F)) ^ np.uint32(seed)
        h ^= h >> np.uint32(16)
        h *= np.uint32(0x85EBCA6B)
        h ^= h >> np.uint32(13)
        h *= np.uint32(0xC2B2AE35)
        h ^= h >> np.uint32(16)
    return h


def gradient_noise(p, seed):
    """Perlin-style gradient noise at points p (..., 3); roughly in [-1, 1], zero on the lattice."""
    cell = np.floor(p)
    f = p - cell
    i = cell.astype(np.int64)
    fade = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    total = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                g = _GRADIENTS[_hash(i[..., 0] + dx, i[..., 1] + dy, i[..., 2] + dz, seed) & np.uint32(15)]
                d = f - np.array([dx, dy, dz], dtype=np.float64)
                w = (fade[..., 0] if dx else 1.0 - fade[..., 0]) * (fade[..., 1] if dy else 1.0 - fade[..., 1]) \
                    * (fade[..., 2] if dz else 1.0 - fade[..., 2])
                total = total + w * np.einsum("...k,...k->...", g, d)
    return total


def fbm(p, base_frequency, octaves, seed, gain=0.5):
    total = 0.0
    amplitude = 1.0
    frequency = base_frequency
    for octave in range(octaves):
        total = total + amplitude * gradient_noise(p * frequency, seed + 7919 * octave)
        amplitude *= gain
        frequency *= 2.0
    return total


# --------------------------------------------------------------------------------------------------
# The bust as a signed distance function (negative inside). Points are arrays (..., 3).

def ellipsoid(p, centre, radii):
    q = (p - centre) / radii
    k0 = np.linalg.norm(q, axis=-1)
    k1 = np.linalg.norm(q / radii, axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


def capsule(p, a, b, radius):
    a, b = np.asarray(a, float), np.asarray(b, float)
    pa, ba = p - a, b - a
    h = np.clip(np.einsum("...k,k->...", pa, ba) / ba.dot(ba), 0.0, 1.0)
    return np.linalg.norm(pa - h[..., None] * ba, axis=-1) - radius


def rounded_box(p, centre, half, radius):
    q = np.abs(p - centre) - (np.asarray(half) - radius)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    return outside + np.minimum(np.max(q, axis=-1), 0.0) - radius


def smin(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def smax(a, b, k):
    return -smin(-a, -b, k)


def mirrored_x(p):
    q = p.copy()
    q[..., 0] = np.abs(q[..., 0])
    return q


def statue_sdf(p):
    m = mirrored_x(p)  # the bust is symmetric in x; its noise is not
    plinth = rounded_box(p, np.array([0.0, 0.0, 0.06]), [0.17, 0.15, 0.06], 0.012)
    step = rounded_box(p, np.array([0.0, 0.0, 0.135]), [0.13, 0.11, 0.02], 0.008)
    chest = ellipsoid(p, np.array([0.0, 0.0, 0.30]), np.array([0.30, 0.16, 0.17]))
    chest = smax(chest, 0.15 - p[..., 2], 0.02)  # cut flat where it sits on the plinth
    shoulder = ellipsoid(m, np.array([0.19, 0.015, 0.37]), np.array([0.13, 0.11, 0.075]))
    pectoral = ellipsoid(m, np.array([0.08, -0.09, 0.31]), np.array([0.11, 0.07, 0.08]))
    neck = capsule(p, [0.0, 0.015, 0.38], [0.0, -0.005, 0.62], 0.068)
    head = ellipsoid(p, np.array([0.0, -0.005, 0.76]), np.array([0.118, 0.14, 0.16]))
    jaw = ellipsoid(p, np.array([0.0, -0.065, 0.665]), np.array([0.085, 0.085, 0.07]))
    chin = ellipsoid(p, np.array([0.0, -0.125, 0.64]), np.array([0.035, 0.03, 0.03]))
    nose = capsule(p, [0.0, -0.138, 0.775], [0.0, -0.172, 0.715], 0.017)
    brow = ellipsoid(p, np.array([0.0, -0.108, 0.795]), np.array([0.085, 0.035, 0.026]))
    cheek = ellipsoid(m, np.array([0.055, -0.10, 0.72]), np.array([0.045, 0.04, 0.04]))
    ear = ellipsoid(m, np.array([0.118, 0.005, 0.75]), np.array([0.022, 0.04, 0.055]))
    lips = ellipsoid(p, np.array([0.0, -0.13, 0.683]), np.array([0.035, 0.018, 0.015]))
    socket = ellipsoid(m, np.array([0.047, -0.148, 0.765]), np.array([0.03, 0.025, 0.02]))
    hair = ellipsoid(p, np.array([0.0, 0.015, 0.79]), np.array([0.128, 0.15, 0.155]))
    hair = smax(hair, -(p[..., 1] + 0.06) + 0.35 * (p[..., 2] - 0.80), 0.03)  # hairline above the brow

    d = smin(plinth, step, 0.01)
    body = smin(chest, shoulder, 0.06)
    body = smin(body, pectoral, 0.05)
    d = smin(d, body, 0.015)
    d = smin(d, neck, 0.05)
    face = smin(head, jaw, 0.04)
    face = smin(face, chin, 0.02)
    face = smin(face, cheek, 0.03)
    face = smin(face, brow, 0.02)
    face = smin(face, nose, 0.012)
    face = smin(face, lips, 0.01)
    face = smin(face, ear, 0.01)
    face = smax(face, -socket, 0.012)
    face = smin(face, hair, 0.02)
    d = smin(d, face, 0.04)

    # Weathered stone everywhere, curls where the hair is (a smooth mask of the hair's volume).
    d = d + 0.0035 * fbm(p, 6.0, 4, SEED)
    curls = np.clip(-hair / 0.02 + 0.5, 0.0, 1.0) * np.clip((p[..., 2] - 0.74) / 0.04, 0.0, 1.0)
    d = d - 0.012 * curls * np.abs(fbm(p, 18.0, 3, SEED + 1, gain=0.45))
    return d


# --------------------------------------------------------------------------------------------------
# Naive surface nets.

BOX_LO = np.array([-0.40, -0.26, -0.02])
BOX_HI = np.array([0.40, 0.24, 1.0])

# The 12 edges of a cell as pairs of corner offsets.
_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.abs(_CORNERS[a] - _CORNERS[b]).sum() == 1]


def sample_grid(cell):
    n = np.ceil((BOX_HI - BOX_LO) / cell).astype(int) + 1
    axes = [BOX_LO[k] + cell * np.arange(n[k]) for k in range(3)]
    values = np.empty(tuple(n))
    for i in range(n[0]):  # slab by slab: the noise's temporaries stay small
        yy, zz = np.meshgrid(axes[1], axes[2], indexing="ij")
        values[i] = statue_sdf(np.stack([np.full_like(yy, axes[0][i]), yy, zz], axis=-1))
    if (values[[0, -1]] <= 0).any() or (values[:, [0, -1]] <= 0).any() or (values[:, :, [0, -1]] <= 0).any():
        sys.exit("make_statue_mesh: the surface leaves the sampling box")
    return values, n


def surface_nets(values, n, cell):
    inside = values < 0
    # Cells (lower corner index) whose corners are not all on one side.
    cn = n - 1
    count = np.zeros(tuple(cn), dtype=np.int8)
    for c in _CORNERS:
        count += inside[c[0]:c[0] + cn[0], c[1]:c[1] + cn[1], c[2]:c[2] + cn[2]]
    active = np.argwhere((count > 0) & (count < 8))
    vertex_of = np.full(tuple(cn), -1, dtype=np.int64)
    vertex_of[tuple(active.T)] = np.arange(len(active))

    # Vertex of a cell: the mean of the points where the zero set crosses its edges.
    total = np.zeros((len(active), 3))
    crossings = np.zeros(len(active))
    corner_values = [values[tuple((active + c).T)] for c in _CORNERS]
    for a, b in _EDGES:
        va, vb = corner_values[a], corner_values[b]
        crosses = (va < 0) != (vb < 0)
        t = np.where(crosses, va / np.where(crosses, va - vb, 1.0), 0.0)
        point = _CORNERS[a] + t[:, None] * (_CORNERS[b] - _CORNERS[a])
        total += np.where(crosses[:, None], point, 0.0)
        crossings += crosses
    vertices = BOX_LO + cell * (active + total / crossings[:, None])

    # One quad per grid edge that the zero set crosses, around that edge, wound so its normal points
    # from inside to outside.
    quads = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        lo = [slice(0, n[k]) for k in range(3)]
        hi = list(lo)
        lo[axis], hi[axis] = slice(0, n[axis] - 1), slice(1, n[axis])
        change = inside[tuple(lo)] != inside[tuple(hi)]
        # Edges on the box's faces in u or v touch fewer than 4 cells; the surface never reaches them.
        idx = np.argwhere(change)
        idx = idx[(idx[:, u] > 0) & (idx[:, v] > 0) & (idx[:, u] < n[u] - 1) & (idx[:, v] < n[v] - 1)]
        ring = []
        for du, dv in ((-1, -1), (0, -1), (0, 0), (-1, 0)):  # counter-clockwise about +axis
            c = idx.copy()
            c[:, u] += du
            c[:, v] += dv
            ring.append(vertex_of[tuple(c.T)])
        ring = np.stack(ring, axis=1)
        if (ring < 0).any():
            sys.exit("make_statue_mesh: a crossed edge without its four cells (a bug)")
        outward_positive = inside[tuple(idx.T)]  # inside at the lower end: the normal points along +axis
        ring[~outward_positive] = ring[~outward_positive][:, ::-1]
        quads.append(ring)
    return vertices, np.concatenate(quads)


def split_quads(vertices, quads):
    """Two triangles per quad, cut along the shorter diagonal."""
    p = vertices[quads]
    d02 = np.linalg.norm(p[:, 0] - p[:, 2], axis=1)
    d13 = np.linalg.norm(p[:, 1] - p[:, 3], axis=1)
    along02 = d02 <= d13
    a = np.where(along02[:, None], quads[:, [0, 1, 2]], quads[:, [1, 2, 3]])
    b = np.where(along02[:, None], quads[:, [0, 2, 3]], quads[:, [1, 3, 0]])
    return np.concatenate([a, b])


def project(vertices, steps=3, h=1e-4):
    """Newton steps onto the zero set along the numerical gradient."""
    for _ in range(steps):
        d = statue_sdf(vertices)
        grad = np.stack([(statue_sdf(vertices + h * e) - statue_sdf(vertices - h * e)) / (2 * h)
                         for e in np.eye(3)], axis=1)
        g2 = np.maximum((grad * grad).sum(axis=1), 1e-12)
        vertices = vertices - (d / g2)[:, None] * grad
    return vertices


# --------------------------------------------------------------------------------------------------

def check(vertices, faces):
    """Closedness (every edge in exactly two faces, opposite ways) and outward winding."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.minimum(e[:, 0], e[:, 1]) * len(vertices) + np.maximum(e[:, 0], e[:, 1])
    _, uses = np.unique(key, return_counts=True)
    directed = np.unique(e[:, 0] * len(vertices) + e[:, 1])
    p = vertices[faces]
    volume = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    return {"open_or_nonmanifold_edges": int((uses != 2).sum()), "repeated_directed_edges": len(e) - len(directed),
            "volume": volume, "area": area.sum(), "min_triangle_area": area.min()}


def write_ply(path, vertices, faces, comment):
    header = ("ply\nformat binary_little_endian 1.0\n" + "".join(f"comment {c}\n" for c in comment) +
              f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    face_records = np.zeros(len(faces), dtype=np.dtype([("n", "u1"), ("v", "<i4", (3,))]))
    face_records["n"] = 3
    face_records["v"] = faces
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(vertices.astype("<f4").tobytes())
        f.write(face_records.tobytes())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    default = pathlib.Path(__file__).resolve().parent.parent / "meshes" / "statue.ply"
    parser.add_argument("output", nargs="?", type=pathlib.Path, default=default)
    parser.add_argument("--cell", type=float, default=0.0079, help="grid cell (mesh units; smaller: more triangles)")
    args = parser.parse_args()

    values, n = sample_grid(args.cell)
    vertices, quads = surface_nets(values, n, args.cell)
    vertices = project(vertices)
    faces = split_quads(vertices, quads)
    # Base on z = 0, centred in x and y (the plinth's footprint), 1.0 tall.
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vertices = (vertices - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])) / (hi[2] - lo[2])
    stats = check(vertices, faces)
    if stats["volume"] <= 0:
        sys.exit("make_statue_mesh: faces wound inward (a bug)")
    write_ply(args.output, vertices, faces,
              ["tprf scripts/make_statue_mesh.py: procedural bust on a plinth, 1.0 tall, z up, faces -y",
               f"grid cell {args.cell}, noise seed {SEED}"])
    size = args.output.stat().st_size
    print(f"{args.output}: {len(vertices)} vertices, {len(faces)} triangles, {size / 1e6:.2f} MB; "
          f"bounding box {np.round(vertices.max(axis=0) - vertices.min(axis=0), 3).tolist()}, "
          f"area {stats['area']:.3f}, volume {stats['volume']:.4f}, "
          f"edges not shared by exactly two faces: {stats['open_or_nonmanifold_edges']}, "
          f"smallest triangle {stats['min_triangle_area']:.2e}")


if __name__ == "__main__":
    main()
