"""A render's .npy files as a NumPy user reads them (docs/outputs.md): each
loads with numpy.load, also memory-mapped (mmap_mode='r'), as float32 in C order with the shape the spec
gives, and the cube summed over time is the steady image when the window holds all the light.

The tprf command is $TPRF_BINARY, or the build's bin/tprf beside the directory CTest runs this from
(BUILD/tests), or build/bin/tprf in the source tree; the tests skip, saying so, where there is none, or
where this Python lacks numpy (Debian: python3-numpy, which scripts/setup.sh installs).
"""

import csv
import json
import os
import pathlib
import shutil
import subprocess

import pytest

np = pytest.importorskip("numpy", reason="numpy is missing (Debian: apt-get install python3-numpy)")

SOURCE = pathlib.Path(__file__).resolve().parents[2]


def find_tprf():
    candidates = []
    if os.environ.get("TPRF_BINARY"):
        candidates.append(pathlib.Path(os.environ["TPRF_BINARY"]))
    cwd = pathlib.Path.cwd()
    candidates += [cwd.parent / "bin" / "tprf", cwd / "bin" / "tprf", SOURCE / "build" / "bin" / "tprf"]
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    return None


TPRF = find_tprf()
needs_tprf = pytest.mark.skipif(TPRF is None, reason="no tprf binary: set TPRF_BINARY or run from the build's tests/")

# The two-plane corner of tests/render_test.cpp (floor z = 0 and wall x = 0, 1 x 1 m, albedos 0.6 and 0.5)
# under a point light, 24 x 20 pixels. 500 bins of 2 cm: after 10 m of path what is left of the light in
# this open corner is below 1e-6 of it (tests/render_test.cpp, TimeIntegralOfTheCubeIsTheSteadyImage).
H, W, T, GATES = 20, 24, 500, 6
SCENE = {
    "time": {"bins": T, "bin_width": 0.02},
    "camera": {"position": [1.6, 0.5, 0.6], "look_at": [0.3, 0.5, 0.3], "up": [0, 0, 1], "fov": 60,
               "width": W, "height": H},
    "lights": [{"type": "point", "position": [0.6, 0.3, 0.7], "intensity": 1.0}],
    "objects": [{"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "albedo": 0.6},
                {"type": "rectangle", "origin": [0, 0, 0], "u": [0, 1, 0], "v": [0, 0, 1], "albedo": 0.5}],
    "patches": {"max_edge": 0.1},
    "solver": {"bounces": True},
    "sensor": {"exposure": {"type": "gates", "start": 1.5, "width": 0.5, "step": 0.5, "count": GATES}},
}


def tprf(*args):
    r = subprocess.run([str(TPRF), *map(str, args), "-q"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return r


@pytest.fixture(scope="module")
def render(tmp_path_factory):
    d = tmp_path_factory.mktemp("outputs")
    (d / "scene.json").write_text(json.dumps(SCENE))
    tprf("render", d / "scene.json", "-o", d / "out", "--patch-profiles", "--threads", 2)
    return d / "out"


def patch_count(out):
    with open(out / "patches.csv", newline="") as f:
        return sum(1 for _ in csv.DictReader(f))


def check_npy(path, shape):
    """Loads `path` both ways; returns the array. float32 little-endian, C order, the given shape, and the
    data aligned to 64 bytes for memory mapping (lib/include/tprf/io/npy.h)."""
    a = np.load(path)
    assert a.dtype == np.dtype("<f4"), path
    assert a.shape == shape, path
    assert a.flags.c_contiguous, path
    with open(path, "rb") as f:
        major, _ = np.lib.format.read_magic(f)
        header = np.lib.format.read_array_header_1_0(f) if major == 1 else np.lib.format.read_array_header_2_0(f)
        assert header == (shape, False, np.dtype("<f4")), path
        assert f.tell() % 64 == 0, f"{path}: data starts at byte {f.tell()}"
    m = np.load(path, mmap_mode="r")
    assert isinstance(m, np.memmap), path
    assert m.shape == shape, path
    assert np.array_equal(m, a), path
    assert np.all(np.isfinite(a)), path
    return a


@needs_tprf
def test_every_npy_loads_with_the_spec_shape(render):
    n = patch_count(render)
    assert n == 200  # two 1 m squares cut at 0.1 m
    expected = {
        "transient.npy": (H, W, T, 3),
        "steady.npy": (H, W, 3),
        "patch_transient.npy": (n, T, 3),
        "patch_steady.npy": (n, 3),
        "measurements.npy": (H, W, GATES, 3),
        # solver.bounces without max_bounces: orders 0..3 and every order >= 4 (docs/scene.md)
        **{f"transient_bounce_{k}.npy": (H, W, T, 3) for k in range(5)},
    }
    assert {p.name for p in render.glob("*.npy")} == set(expected)
    for name, shape in expected.items():
        check_npy(render / name, shape)


@needs_tprf
def test_time_sums_are_the_steady_state(render):
    # docs/scene.md: with the window holding all the light, the bins sum to the steady value. The cube is summed
    # in float64 here; what is left is the film's float accumulation and the steady solve's 1e-8:
    # 1e-5 of each value plus 1e-6 of the peak.
    cube = np.load(render / "transient.npy", mmap_mode="r")
    steady = np.load(render / "steady.npy")
    total = cube.sum(axis=2, dtype=np.float64)
    assert steady.max() > 0
    assert np.all(np.abs(total - steady) <= 1e-5 * steady + 1e-6 * steady.max())
    # The same for every patch's radiosity profile.
    profiles = np.load(render / "patch_transient.npy", mmap_mode="r")
    patch_steady = np.load(render / "patch_steady.npy")
    total = profiles.sum(axis=1, dtype=np.float64)
    assert np.all(np.abs(total - patch_steady) <= 1e-5 * patch_steady + 1e-6 * patch_steady.max())
    # The bounce orders add up to the cube (five float parts against the float whole: 1e-6 of the peak).
    orders = sum(np.load(render / f"transient_bounce_{k}.npy").astype(np.float64) for k in range(5))
    assert np.max(np.abs(orders - cube)) <= 1e-6 * cube.max()


@needs_tprf
def test_gates_hold_the_bins_inside_them(render):
    # A delta pulse: gate k, [1.5 + 0.5 k, 2 + 0.5 k) m, is bins 75 + 25 k to 100 + 25 k of 2 cm
    # (docs/sensor.md), to float rounding. The first light arrives at 1.68 m, inside gate 0.
    cube = np.load(render / "transient.npy", mmap_mode="r")
    m = np.load(render / "measurements.npy")
    for k in range(GATES):
        inside = cube[:, :, 75 + 25 * k:100 + 25 * k].sum(axis=2, dtype=np.float64)
        assert np.all(np.abs(m[:, :, k] - inside) <= 1e-5 * inside + 1e-7 * cube.max()), k
    assert m[:, :, 0].max() > 0


@needs_tprf
def test_amcw_depth_and_measurements_load(render, tmp_path):
    # `tprf sensor` on the same render: four phases (the default) and the depth image (H, W), metres in
    # [0, c / (2 f)) = [0, 7.49 m) at 20 MHz.
    # A copy, so that the other tests see the render's own measurements whatever the order.
    out = tmp_path / "out"
    shutil.copytree(render, out)
    (tmp_path / "amcw.json").write_text(json.dumps({"exposure": {"type": "amcw", "frequency_mhz": 20}}))
    tprf("sensor", out, tmp_path / "amcw.json")
    check_npy(out / "sensor-amcw" / "measurements.npy", (H, W, 4, 3))
    check_npy(out / "sensor-amcw" / "raw.npy", (H, W, 1, 4))
    depth = check_npy(out / "sensor-amcw" / "depth.npy", (H, W))
    c = 299792458.0
    assert np.all((depth >= 0) & (depth < c / (2 * 20e6)))
