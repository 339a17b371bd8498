#!/usr/bin/env python3
"""Filtered backprojection of a confocal NLOS capture (tprf's capture.hdf5, tal's layout).

Reads the capture the way tal's NLOSCaptureData does (H (T, nu, nv) float32, sensor_grid_xyz (nu, nv, 3),
delta_t and t_start in metres of optical path, t_accounts_first_and_last_bounces, H_format), then

  1. gates out the direct spot (the laser spot seen by the sensor at path ~0, the largest values of H),
  2. backprojects: for every voxel v of a box in front of the wall,
         B(v) = sum_s w(v, s) H[t(v, s), s],   t(v, s) = (2 |v - s| + legs(s) - t_start) / delta_t
     with legs(s) = |laser - s| + |s - sensor| when the capture accounts for the device legs (0 otherwise),
     H read linearly between bin centres (--time bin: the bin floor(t) that holds the path, as tal's bp),
     w = |v - s|^4 (undoes the 1/r^2 falloff of both legs of a confocal path) or 1 (--weight none);
     H is first smoothed along time by a Gaussian of twice the depth step (FWHM, in path), so that depth
     slices coarser than a bin sample it without aliasing,
  3. filters the volume with a negative second derivative along depth (Velten et al. 2012) or a negative
     3D Laplacian (Arellano et al. 2017), and keeps its positive part,
  4. writes depth.png (the depth of the maximum along z for each (x, y), masked where that maximum is
     weak) and front.png (the maximum over depth), and prints the target's depth: the median depth of
     the pixels above the threshold. With --expect-depth D it exits 1 when |depth - D| > --tolerance.

numpy, h5py and matplotlib only. The backprojection is vectorised over (voxel, sensor point) pairs, a
chunk of voxels at a time to bound memory.
"""

import argparse
import os
import sys
import time

import numpy as np

H_FORMAT_T_SX_SY = 1  # tal.enums.HFormat.T_Sx_Sy


def fail(message):
    print(f"reconstruct.py: {message}", file=sys.stderr)
    sys.exit(2)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("capture", help="capture.hdf5 written by tprf render (a confocal capture)")
    p.add_argument("-o", "--out", default=".", help="folder for depth.png, front.png and volume.npy (default: .)")
    p.add_argument("--nxy", type=int, nargs=2, default=None, metavar=("NX", "NY"),
                   help="voxels across the grid's extent (default: the grid's own nu, nv)")
    p.add_argument("--z-range", type=float, nargs=2, default=(0.2, 1.4), metavar=("ZMIN", "ZMAX"),
                   help="depths of the first and last slice, metres in front of the wall (default: 0.2 1.4)")
    p.add_argument("--nz", type=int, default=64, help="depth slices (default: 64)")
    p.add_argument("--gate", type=float, default=0.05,
                   help="bins whose path (without the device legs) lies below GATE metres are zeroed: the direct "
                        "spot (default: 0.05)")
    p.add_argument("--smooth", type=float, default=None, metavar="FWHM",
                   help="Gaussian along time before the backprojection, FWHM in metres of path (default: twice the "
                        "depth step, so that slices coarser than a bin do not alias its detail; 0: none)")
    p.add_argument("--time", choices=("linear", "bin"), default="linear",
                   help="H at a voxel's path: linear between bin centres (default) or the bin that holds it")
    p.add_argument("--weight", choices=("r4", "none"), default="r4",
                   help="radiometric weight |v - s|^4 per term (default) or none")
    p.add_argument("--filter", choices=("lap-z", "lap-3d", "none"), default="lap-z",
                   help="negative second derivative along depth (default), negative 3D Laplacian, or none")
    p.add_argument("--threshold", type=float, default=0.3,
                   help="pixels whose maximum over depth is below THRESHOLD x the volume's maximum are masked "
                        "(default: 0.3)")
    p.add_argument("--expect-depth", type=float, default=None, help="the target's true depth, metres")
    p.add_argument("--tolerance", type=float, default=0.02, help="largest accepted depth error, metres (default: 0.02)")
    p.add_argument("--chunk", type=int, default=2_000_000,
                   help="(voxel, sensor point) pairs per step; bounds memory at about 30 bytes each (default: 2e6)")
    return p.parse_args(argv)


def read_capture(path):
    """The fields a confocal backprojection needs, as tal's NLOSCaptureData names them."""
    import h5py
    with h5py.File(path, "r") as f:
        data = {
            "H": f["H"][()],
            "H_format": int(np.squeeze(f["H_format"][()])),
            "sensor_grid_xyz": f["sensor_grid_xyz"][()].astype(np.float64),
            "sensor_grid_normals": f["sensor_grid_normals"][()].astype(np.float64),
            "laser_grid_xyz": f["laser_grid_xyz"][()].astype(np.float64),
            "sensor_xyz": f["sensor_xyz"][()].astype(np.float64).reshape(3),
            "laser_xyz": f["laser_xyz"][()].astype(np.float64).reshape(3),
            "delta_t": float(f["delta_t"][()]),
            "t_start": float(f["t_start"][()]),
            "t_accounts_first_and_last_bounces": bool(np.squeeze(f["t_accounts_first_and_last_bounces"][()])),
        }
    if data["H_format"] != H_FORMAT_T_SX_SY or data["H"].ndim != 3:
        fail(f"{path}: H_format {data['H_format']}, H {data['H'].shape}: not a (T, Sx, Sy) capture")
    if data["sensor_grid_xyz"].shape != data["H"].shape[1:] + (3,):
        fail(f"{path}: sensor_grid_xyz {data['sensor_grid_xyz'].shape} does not match H {data['H'].shape}")
    if not np.allclose(data["sensor_grid_xyz"], data["laser_grid_xyz"]):
        fail(f"{path}: the laser grid differs from the sensor grid: not a confocal capture")
    return data


def device_legs(data):
    """Per sensor point, the path that H's time includes besides the hidden part (0 by the NLOS convention)."""
    s = data["sensor_grid_xyz"].reshape(-1, 3)
    if not data["t_accounts_first_and_last_bounces"]:
        return np.zeros(len(s))
    return np.linalg.norm(s - data["laser_xyz"], axis=1) + np.linalg.norm(s - data["sensor_xyz"], axis=1)


def gate_direct(H, data, legs, gate):
    """Zero every bin whose path, less the device legs, lies below `gate`: the laser spot itself."""
    T = H.shape[0]
    starts = data["t_start"] + np.arange(T) * data["delta_t"]            # path at each bin's start
    ends = starts + data["delta_t"]
    gated = ends[:, None] - legs[None, :] <= gate                        # (T, ns): the whole bin below the gate
    gated |= starts[:, None] - legs[None, :] < gate                      # ... or starting below it
    out = H.copy()
    out[gated] = 0.0
    return out, gated


def make_volume(data, nxy, z_range, nz):
    """Voxel centres over the sensor grid's extent, depth along the wall's front normal there."""
    g = data["sensor_grid_xyz"]
    nu, nv = g.shape[:2]
    nx, ny = nxy if nxy else (nu, nv)
    # The grid's own bounds (its cells, not its centres), so that voxels and grid points line up when nx = nu.
    du = (g[-1, 0] - g[0, 0]) / max(nu - 1, 1)
    dv = (g[0, -1] - g[0, 0]) / max(nv - 1, 1)
    corner = g[0, 0] - 0.5 * du - 0.5 * dv
    U, V = du * nu, dv * nv
    normal = data["sensor_grid_normals"].reshape(-1, 3).mean(axis=0)
    normal /= np.linalg.norm(normal)
    a = (np.arange(nx) + 0.5) / nx
    b = (np.arange(ny) + 0.5) / ny
    z = np.linspace(z_range[0], z_range[1], nz)
    xyz = (corner[None, None, None, :] + a[:, None, None, None] * U + b[None, :, None, None] * V
           + z[None, None, :, None] * normal)
    return xyz, z, normal


def smooth_time(H, fwhm_bins):
    """Gaussian along time (axis 0) of the given FWHM in bins: the anti-alias for depth slices coarser than a bin."""
    if fwhm_bins <= 0:
        return H
    sigma = fwhm_bins / (2.0 * np.sqrt(2.0 * np.log(2.0)))
    half = int(np.ceil(4 * sigma))
    x = np.arange(-half, half + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    kernel /= kernel.sum()
    T = H.shape[0]
    P = np.concatenate([np.zeros((half,) + H.shape[1:]), H, np.zeros((half,) + H.shape[1:])])
    out = np.zeros_like(H)
    for i, w in enumerate(kernel):
        out += w * P[i:i + T]
    return out


def backproject(H, data, legs, xyz, weight, chunk, interpolate=True):
    """B[i, j, k] = sum_s w H[t(v_ijk, s), s], vectorised over chunks of voxels x all sensor points.

    |v - s|^2 = |v|^2 + |s|^2 - 2 v.s (one matrix product per chunk), in float32 about the grid's centre."""
    T = H.shape[0]
    s = data["sensor_grid_xyz"].reshape(-1, 3)
    ns = len(s)
    centre = s.mean(axis=0)
    s = (s - centre).astype(np.float32)
    v_all = (xyz.reshape(-1, 3) - centre).astype(np.float32)
    ss = np.einsum("ij,ij->i", s, s)
    Hs = np.ascontiguousarray(H.reshape(T, ns).T, dtype=np.float32).ravel()  # (ns * T,): a point's bins together
    base = (np.arange(ns) * T).astype(np.int32)
    # t = (2 r + legs - t_start) / delta_t = r * k + off[s]
    k = np.float32(2.0 / data["delta_t"])
    off = ((legs - data["t_start"]) / data["delta_t"]).astype(np.float32)
    out = np.zeros(len(v_all))
    step = max(1, chunk // ns)                                           # voxels per step
    for v0 in range(0, len(v_all), step):
        v = v_all[v0:v0 + step]
        r2 = v @ (np.float32(-2.0) * s.T)                                # (n, ns)
        r2 += np.einsum("ij,ij->i", v, v)[:, None]
        r2 += ss[None, :]
        np.maximum(r2, 0.0, out=r2)
        t = np.sqrt(r2)
        t *= k
        t += off[None, :]
        if interpolate:                                                  # linear between bin centres
            t -= np.float32(0.5)
            ok = (t >= 0) & (t < T - 1)
            ti = t.astype(np.int32)                                      # floor, where ok (t >= 0)
            ti[~ok] = 0
            t -= ti                                                      # the fraction
            ti += base[None, :]
            vals = Hs[ti]
            vals *= np.float32(1.0) - t
            t *= Hs[ti + 1]
            vals += t
        else:                                                            # the bin that holds the path
            ok = (t >= 0) & (t < T)
            ti = t.astype(np.int32)                                      # floor, where ok (t >= 0)
            ti[~ok] = 0
            ti += base[None, :]
            vals = Hs[ti]
        vals[~ok] = 0.0
        if weight == "r4":
            r2 *= r2
            out[v0:v0 + step] = np.einsum("ij,ij->i", vals, r2, dtype=np.float64)
        else:
            out[v0:v0 + step] = vals.sum(axis=1, dtype=np.float64)
    return out.reshape(xyz.shape[:3])


def laplacian_filter(B, kind, spacing):
    """Negative second derivative along depth, or negative 3D Laplacian; positive part."""
    if kind == "none":
        return B.copy()
    P = np.pad(B, 1, mode="edge")
    dz2 = (P[1:-1, 1:-1, 2:] - 2 * B + P[1:-1, 1:-1, :-2]) / spacing[2] ** 2
    lap = dz2
    if kind == "lap-3d":
        lap = lap + (P[2:, 1:-1, 1:-1] - 2 * B + P[:-2, 1:-1, 1:-1]) / spacing[0] ** 2
        lap = lap + (P[1:-1, 2:, 1:-1] - 2 * B + P[1:-1, :-2, 1:-1]) / spacing[1] ** 2
    return np.maximum(-lap, 0.0)


def depth_of_maximum(F, z):
    """Per (x, y): the depth of the maximum along z, refined by a parabola through it and its neighbours."""
    k = np.argmax(F, axis=2)
    peak = np.take_along_axis(F, k[..., None], axis=2)[..., 0]
    km = np.clip(k - 1, 0, len(z) - 1)
    kp = np.clip(k + 1, 0, len(z) - 1)
    fm = np.take_along_axis(F, km[..., None], axis=2)[..., 0]
    fp = np.take_along_axis(F, kp[..., None], axis=2)[..., 0]
    denom = fm - 2 * peak + fp
    inner = (k > 0) & (k < len(z) - 1) & (denom < 0)
    shift = np.where(inner, 0.5 * (fm - fp) / np.where(inner, denom, 1.0), 0.0)
    dz = z[1] - z[0] if len(z) > 1 else 0.0
    return z[k] + np.clip(shift, -0.5, 0.5) * dz, peak


def save_images(out_dir, depth, front, mask, extent, z_range, median_depth):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Arrays are (x, y); imshow wants rows = y (up) and columns = x.
    def show(img, title, label, name, **kw):
        fig, ax = plt.subplots(figsize=(5.2, 4.4), dpi=100)
        im = ax.imshow(img.T, origin="lower", extent=extent, **kw)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title)
        fig.colorbar(im, ax=ax, label=label)
        fig.tight_layout()
        fig.savefig(os.path.join(out_dir, name))
        plt.close(fig)

    cmap = matplotlib.colormaps["viridis"].copy()
    cmap.set_bad("black")
    show(np.ma.masked_array(depth, ~mask), f"depth of the maximum (median {median_depth:.3f} m)", "depth (m)",
         "depth.png", cmap=cmap, vmin=z_range[0], vmax=z_range[1])
    show(front / max(front.max(), 1e-30), "maximum over depth", "relative", "front.png", cmap="gray", vmin=0, vmax=1)


def main(argv=None):
    args = parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    data = read_capture(args.capture)
    H = data["H"].astype(np.float64)
    T, nu, nv = H.shape
    legs = device_legs(data)
    Hg, gated = gate_direct(H.reshape(T, -1), data, legs, args.gate)
    print(f"capture   {args.capture}: H {data['H'].shape}, delta_t {data['delta_t']} m, t_start {data['t_start']} m, "
          f"device legs {'in' if data['t_accounts_first_and_last_bounces'] else 'out of'} the paths")
    if gated.any():
        print(f"gate      {int(gated.sum())} bins below {args.gate} m of path (less the device legs) zeroed (largest there "
              f"{H.reshape(T, -1)[gated].max():.4g}, largest left {Hg.max():.4g})")
    else:
        print(f"gate      no bin below {args.gate} m: the window starts after the direct spot")

    xyz, z, _ = make_volume(data, args.nxy, args.z_range, args.nz)
    nx, ny = xyz.shape[:2]
    t1 = time.perf_counter()
    dz = (z[1] - z[0]) if len(z) > 1 else 0.0
    smooth = 2.0 * dz if args.smooth is None else args.smooth
    Hg = smooth_time(Hg, smooth / data["delta_t"])
    B = backproject(Hg.reshape(T, nu, nv), data, legs, xyz, args.weight, args.chunk, args.time == "linear")
    t2 = time.perf_counter()
    spacing = (np.linalg.norm(xyz[1, 0, 0] - xyz[0, 0, 0]) if nx > 1 else 1.0,
               np.linalg.norm(xyz[0, 1, 0] - xyz[0, 0, 0]) if ny > 1 else 1.0,
               z[1] - z[0] if len(z) > 1 else 1.0)
    F = laplacian_filter(B, args.filter, spacing)
    depth, front = depth_of_maximum(F, z)
    mask = front >= args.threshold * front.max()
    np.save(os.path.join(args.out, "volume.npy"), F.astype(np.float32))

    x0, x1 = xyz[0, 0, 0, 0] - spacing[0] / 2, xyz[-1, 0, 0, 0] + spacing[0] / 2
    y0, y1 = xyz[0, 0, 0, 1] - spacing[1] / 2, xyz[0, -1, 0, 1] + spacing[1] / 2
    n = int(mask.sum())
    d = float(np.median(depth[mask])) if n else float("nan")
    save_images(args.out, depth, front, mask, (x0, x1, y0, y1), args.z_range, d)
    t3 = time.perf_counter()

    print(f"volume    {nx} x {ny} x {len(z)} voxels, z {z[0]:.3f}..{z[-1]:.3f} m (step {spacing[2] * 100:.2f} cm), "
          f"over {nu} x {nv} sensor points; H smoothed to {smooth * 100:.2f} cm FWHM of path; time {args.time}, "
          f"weight {args.weight}, filter {args.filter}")
    print(f"seconds   read {t1 - t0:.2f}, backprojection {t2 - t1:.2f}, filter and images {t3 - t2:.2f}")
    if n == 0:
        print("result    no pixel above the threshold")
        return 1
    xs, ys = np.nonzero(mask)
    print(f"target    {n} pixels above {args.threshold} x max, x {xyz[xs.min(), 0, 0, 0]:.3f}..{xyz[xs.max(), 0, 0, 0]:.3f} m, "
          f"y {xyz[0, ys.min(), 0, 1]:.3f}..{xyz[0, ys.max(), 0, 1]:.3f} m; depth quartiles "
          f"{np.percentile(depth[mask], 25):.4f} / {np.percentile(depth[mask], 75):.4f} m")
    print(f"depth     {d:.4f} m (median over those pixels)")
    print(f"wrote     {os.path.join(args.out, 'depth.png')}, {os.path.join(args.out, 'front.png')}, "
          f"{os.path.join(args.out, 'volume.npy')}")
    if args.expect_depth is not None:
        err = d - args.expect_depth
        ok = abs(err) <= args.tolerance
        print(f"error     {err * 100:+.2f} cm against {args.expect_depth} m: {'within' if ok else 'OVER'} "
              f"{args.tolerance * 100:.1f} cm")
        return 0 if ok else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
