"""The Python module `tprf` (docs/python.md) as a user calls it: renders equal the
command line's files bit for bit, arrays have the documented shapes (docs/outputs.md) and dtypes and share the result's memory,
bad input raises ValueError with the command line's message, progress arrives in order on the calling
thread, and a render can be cancelled (from the callback and by Ctrl-C) and the next one still runs.

Run by CTest (Python.Module) with the build's python/ folder on PYTHONPATH and TPRF_BINARY set.
"""

import copy
import json
import os
import pathlib
import signal
import subprocess
import threading
import time

import pytest

np = pytest.importorskip("numpy", reason="numpy is missing (Debian: apt-get install python3-numpy)")
tprf = pytest.importorskip("tprf", reason="the tprf module is not built (Debian: pybind11-dev python3-dev)")

SOURCE = pathlib.Path(__file__).resolve().parents[2]
TPRF = os.environ.get("TPRF_BINARY")
needs_tprf = pytest.mark.skipif(not TPRF, reason="TPRF_BINARY is not set (CTest sets it)")

# A small two-plane corner under a point light and a laser: 24 x 16 pixels, 300 bins, 5 cm patches.
CORNER = {
    "time": {"bins": 300, "bin_width": 0.01, "start": 0.0, "unit": "m"},
    "camera": {"position": [0.5, -1.1, 0.9], "look_at": [0.5, 0.55, 0.25], "up": [0, 0, 1],
               "fov": 45, "width": 24, "height": 16, "spp": 4},
    "lights": [{"type": "point", "position": [0.3, 0.45, 0.35], "intensity": 1.0},
               {"type": "laser", "origin": [0.9, -0.5, 0.6], "target": [0.6, 0.6, 0.0], "power": [1, 0.5, 0.25]}],
    "objects": [
        {"type": "rectangle", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "albedo": 0.6},
        {"type": "rectangle", "origin": [0, 1, 0], "u": [1, 0, 0], "v": [0, 0, 1], "albedo": [0.5, 0.4, 0.3]},
    ],
    "patches": {"max_edge": 0.05},
}

GATES = {"pulse": {"shape": "gaussian", "fwhm": 0.03},
         "exposure": {"type": "gates", "start": 0.0, "width": 0.1, "step": 0.1, "count": 20},
         "noise": {"sigma": 0.001, "seed": 7}}


def cli(*args, check=True):
    return subprocess.run([TPRF, *map(str, args)], capture_output=True, text=True, check=check)


def write_scene(tmp_path, scene, name="scene.json"):
    path = tmp_path / name
    path.write_text(json.dumps(scene))
    return path


@needs_tprf
def test_a_python_render_equals_the_command_lines_files_bit_for_bit(tmp_path):
    scene = copy.deepcopy(CORNER)
    scene["solver"] = {"bounces": True, "max_bounces": 2}
    path = write_scene(tmp_path, scene)
    cli("render", path, "-o", tmp_path / "out", "--patch-profiles", "--quiet")
    result = tprf.render(tprf.load_scene(path), patch_profiles=True)
    names = ["transient", "steady", "patch_transient", "patch_steady"] + [f"transient_bounce_{k}" for k in range(3)]
    assert sorted(result.arrays) == sorted(names)
    for name in names:
        on_disk = np.load(tmp_path / "out" / f"{name}.npy")
        in_memory = result.arrays[name]
        assert in_memory.dtype == on_disk.dtype and in_memory.shape == on_disk.shape, name
        assert np.array_equal(in_memory, on_disk), name
    assert json.loads(result.record)["patches"] == json.loads((tmp_path / "out" / "render.json").read_text())["patches"]


def test_arrays_have_the_spec_shapes_and_share_the_results_memory():
    result = tprf.render(tprf.load_scene(CORNER), patch_profiles=True)
    H, W, T = 16, 24, 300
    assert result.transient.shape == (H, W, T, 3) and result.transient.dtype == np.float32
    assert result.steady.shape == (H, W, 3) and result.steady.dtype == np.float32
    assert result.patch_transient.shape[1:] == (T, 3) and result.patch_steady.shape[1:] == (3,)
    assert result.capture is None and result.measurements is None
    assert "transient (16, 24, 300, 3)" in repr(result) and "800 patches" in repr(result)
    for a in (result.transient, result.steady, result.patch_transient):
        assert not a.flags.owndata and a.flags.c_contiguous
        assert not a.flags.writeable  # what the render computed, for every later access
    with pytest.raises(ValueError):
        result.steady[0, 0, 0] = 7.0
    # Every access is a view of the same memory, not a copy.
    first, second = result.transient, result.transient
    assert np.shares_memory(first, second)
    assert first.__array_interface__["data"][0] == second.__array_interface__["data"][0]
    # The arrays keep the result alive after the Result object is gone.
    steady = result.steady
    expected = steady.copy()
    del result, first, second
    assert np.array_equal(steady, expected)
    # With a window of 12 m that holds all the light, the cube summed over time is the steady image
    # (at 3 m, 17% of it is still on its way).
    long = copy.deepcopy(CORNER)
    long["time"]["bins"] = 1200
    again = tprf.render(tprf.load_scene(long))
    assert np.abs(again.transient.sum(axis=2) - again.steady).max() <= 1e-5 * again.steady.max()
    assert np.array_equal(tprf.times(again)[:3], np.array([0.0, 0.01, 0.02]))


@needs_tprf
def test_bad_input_raises_valueerror_with_the_command_lines_message(tmp_path):
    scene = copy.deepcopy(CORNER)
    scene["objects"][1]["albedo"] = 1.5
    path = write_scene(tmp_path, scene)
    with pytest.raises(ValueError) as caught:
        tprf.load_scene(path)
    assert isinstance(caught.value, tprf.Error)
    message = str(caught.value)
    assert "objects[1].albedo" in message and str(path) in message
    run = cli("render", path, "-o", tmp_path / "out", check=False)
    assert run.returncode == 2
    assert message in run.stderr
    # The same scene as a dict names the JSON path too.
    with pytest.raises(ValueError, match=r"objects\[1\]\.albedo"):
        tprf.load_scene(scene)
    with pytest.raises(ValueError, match="max_edge"):
        tprf.load_scene(CORNER, max_edge=-1.0)
    with pytest.raises(ValueError, match="pulse"):
        tprf.apply_sensor(tprf.render(tprf.load_scene(CORNER)), {"pulse": {"shape": "triangle"}})


def test_bad_options_and_nested_calls_raise():
    scene = tprf.load_scene(CORNER)
    for kwargs in ({"threads": -1}, {"threads": 100000}, {"max_memory_gb": float("nan")}, {"max_memory_gb": -1}):
        with pytest.raises(ValueError, match=next(iter(kwargs))):
            tprf.render(scene, **kwargs)

    def nested(phase, fraction):
        tprf.info(scene)

    with pytest.raises(RuntimeError, match="cannot nest"):
        tprf.render(scene, progress=nested)
    assert tprf.render(scene).steady.shape == (16, 24, 3)


def test_dict_scenes_read_meshes_relative_to_base():
    scene = copy.deepcopy(CORNER)
    scene["objects"].append({"type": "mesh", "file": "tetra.obj", "albedo": 0.5,
                             "transform": {"scale": 0.2, "translate": [0.5, 0.5, 0.1]}})
    with pytest.raises(ValueError, match="tetra.obj"):
        tprf.load_scene(scene, base=SOURCE / "tests")
    loaded = tprf.load_scene(scene, base=SOURCE / "meshes")
    assert loaded.objects == 3 and loaded.camera["width"] == 24


def test_progress_is_called_in_order_on_the_calling_thread():
    events = []
    caller = threading.get_ident()

    def progress(phase, fraction):
        assert threading.get_ident() == caller
        events.append((phase, fraction))

    tprf.render(tprf.load_scene(CORNER), progress=progress)
    phases = []
    for phase, fraction in events:
        assert 0.0 <= fraction <= 1.0
        if not phases or phases[-1][0] != phase:
            phases.append((phase, fraction))
        else:
            assert fraction >= phases[-1][1], (phase, fraction)
            phases[-1] = (phase, fraction)
    names = [p for p, _ in phases]
    assert len(names) == len(set(names)), names  # each phase once, in one run
    assert names.index("links") < names.index("solve") < names.index("write")
    assert events[-1] == ("write", 1.0)


def test_info_gives_the_estimate_and_the_counts():
    info = tprf.info(tprf.load_scene(CORNER))
    assert info["patches"] == info["estimate"]["patches"] == 2 * 20 * 20
    assert info["links"] > 0 and info["estimate"]["peak_bytes"] > 0
    assert info["time"]["bins"] == 300
    assert "links" not in tprf.info(tprf.load_scene(CORNER), links=False)


def test_a_mirror_from_a_dict_scene_adds_links_and_light():
    # The corner with a mirror at x = 0 facing +x: light reaches the floor and the wall through it too.
    mirrored = copy.deepcopy(CORNER)
    mirrored["objects"].append({"type": "rectangle", "origin": [0, 0, 0], "u": [0, 1, 0], "v": [0, 0, 1],
                                "material": {"type": "mirror", "reflectance": 0.9}})
    info = tprf.info(tprf.load_scene(mirrored))
    assert info["mirror_links"] > 0 and info["mirror_links"] < info["links"]
    assert tprf.info(tprf.load_scene(CORNER))["mirror_links"] == 0
    plain = tprf.render(tprf.load_scene(CORNER)).steady.sum()
    assert tprf.render(tprf.load_scene(mirrored)).steady.sum() > plain
    bad = copy.deepcopy(mirrored)
    bad["objects"][-1]["material"]["reflectance"] = 1.5
    with pytest.raises(ValueError, match=r"objects\[2\]\.material\.reflectance: must be in \[0, 1\]"):
        tprf.load_scene(bad)


# A render long enough to interrupt: 1 cm patches, flat links.
SLOW = copy.deepcopy(CORNER)
SLOW["patches"]["max_edge"] = 0.012
SLOW["time"]["bins"] = 2000
SLOW["links"] = {"method": "flat"}


def test_an_exception_in_the_callback_cancels_the_render_and_the_next_render_runs():
    def progress(phase, fraction):
        if phase == "links" and fraction > 0.0:
            raise RuntimeError("stop here")

    start = time.monotonic()
    with pytest.raises(RuntimeError, match="stop here"):
        tprf.render(tprf.load_scene(SLOW), progress=progress)
    assert time.monotonic() - start < 20.0
    # The cancel request was withdrawn: the next render completes.
    assert tprf.render(tprf.load_scene(CORNER)).steady.shape == (16, 24, 3)


def test_ctrl_c_cancels_a_render_within_a_second():
    scene = tprf.load_scene(SLOW)
    sent = []

    def interrupt_in_the_solve(phase, fraction):
        if phase in ("solve", "links") and not sent:
            sent.append(time.monotonic())
            threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()

    with pytest.raises(KeyboardInterrupt):
        tprf.render(scene, progress=interrupt_in_the_solve)
    assert sent and time.monotonic() - sent[0] < 1.5
    assert tprf.render(tprf.load_scene(CORNER)).transient.shape == (16, 24, 300, 3)


@needs_tprf
def test_apply_sensor_equals_tprf_sensor(tmp_path):
    path = write_scene(tmp_path, CORNER)
    cli("render", path, "-o", tmp_path / "out", "--quiet")
    sensor_file = tmp_path / "sensor.json"
    sensor_file.write_text(json.dumps(GATES))
    cli("sensor", tmp_path / "out", sensor_file, "--quiet")
    result = tprf.render(tprf.load_scene(path))
    for given in (GATES, sensor_file):
        measured = tprf.apply_sensor(result, given)
        assert measured["measurements"].shape == (16, 24, 20, 3)
        assert np.array_equal(measured["measurements"], np.load(tmp_path / "out" / "sensor-sensor" / "measurements.npy"))


@needs_tprf
def test_a_capture_equals_the_command_lines_capture(tmp_path):
    scene = json.loads((SOURCE / "examples" / "nlos" / "letter.json").read_text())
    scene["capture"]["grid"]["nu"] = scene["capture"]["grid"]["nv"] = 6
    scene["time"]["bins"] = 300
    scene["sensor"] = GATES
    path = write_scene(tmp_path, scene)
    cli("render", path, "-o", tmp_path / "out", "--quiet")
    result = tprf.render(tprf.load_scene(path))
    assert result.transient is None
    assert result.capture.shape == (300, 6, 6)
    assert np.array_equal(result.capture, np.load(tmp_path / "out" / "capture.npy"))
    # The sensor block on the capture's points, in the render and applied afterwards.
    on_disk = np.load(tmp_path / "out" / "measurements.npy")
    assert on_disk.shape == (6, 6, 20, 3)
    assert np.array_equal(result.measurements, on_disk)
    assert np.array_equal(tprf.apply_sensor(result, GATES)["measurements"], on_disk)


def test_numpy_values_in_a_dict_scene_and_any_scalar_in_defines():
    # numpy scalars and arrays read as the numbers and lists they hold: the same scene as plain Python.
    scene = copy.deepcopy(CORNER)
    scene["time"]["bins"] = np.int64(300)
    scene["camera"]["fov"] = np.float32(45.0)
    scene["objects"][0]["origin"] = np.zeros(3)
    scene["objects"][1]["albedo"] = np.array([0.5, 0.4, 0.3])
    loaded, plain = tprf.load_scene(scene), tprf.load_scene(CORNER)
    assert loaded.time == plain.time and loaded.objects == plain.objects
    assert loaded.camera["fov"] == pytest.approx(45.0)
    with pytest.raises(TypeError, match="not JSON serializable"):
        tprf.load_scene({**CORNER, "patches": {"max_edge": object()}})
    # defines: each value as its text, as -D name=value gives it.
    xml = str(SOURCE / "meshes" / "cornell-box.xml")
    as_text = tprf.load_scene(xml, defines={"res": "8", "bins": "32"})
    as_ints = tprf.load_scene(xml, defines={"res": 8, "bins": np.int32(32)})
    assert as_ints.camera["width"] == as_text.camera["width"] == 8
    assert as_ints.time == as_text.time


@needs_tprf
def test_aov_maps_equal_the_command_lines_files_and_have_their_dtypes(tmp_path):
    scene = copy.deepcopy(CORNER)
    del scene["camera"]["fov"]
    scene["camera"]["intrinsics"] = {"fx": np.float64(20.0), "fy": 20.0, "cx": 11.5, "cy": 7.5}
    scene["camera"]["distortion"] = {"k1": -0.05}
    loaded = tprf.load_scene(scene)
    assert loaded.camera["intrinsics"] == {"fx": 20.0, "fy": 20.0, "cx": 11.5, "cy": 7.5}
    assert loaded.camera["distortion"]["k1"] == -0.05 and "fov" not in loaded.camera
    path = write_scene(tmp_path, scene)
    cli("render", path, "-o", tmp_path / "out", "--aov", "depth,object,albedo", "--quiet")
    result = tprf.render(loaded, aov=["depth", "object", "albedo"])
    assert sorted(result.aov) == ["albedo", "depth", "object"]
    assert result.aov["object"].dtype == np.int32 and result.aov["depth"].dtype == np.float32
    for name, array in result.aov.items():
        on_disk = np.load(tmp_path / "out" / f"aov_{name}.npy")
        assert array.dtype == on_disk.dtype and np.array_equal(array, on_disk), name
        assert result.arrays[f"aov_{name}"] is not None
    # Both rectangles are seen, and the albedo map is each one's own.
    objects = result.aov["object"]
    assert set(np.unique(objects)) <= {-1, 0, 1} and {0, 1} <= set(np.unique(objects))
    assert np.allclose(result.aov["albedo"][objects == 1], [0.5, 0.4, 0.3])
    assert np.all(np.isinf(result.aov["depth"][objects == -1]))
    assert tprf.render(loaded).aov == {}
    with pytest.raises(ValueError, match='aov: unknown map "colour"'):
        tprf.render(loaded, aov="depth,colour")


def test_apply_sensor_on_numpy_arrays_equals_it_on_the_result():
    scene = copy.deepcopy(CORNER)
    scene["solver"] = {"bounces": True, "max_bounces": 2}
    result = tprf.render(tprf.load_scene(scene))
    amcw = {"exposure": {"type": "amcw", "frequencies": [20e6, 50e6], "phases": 4}}
    on_result = tprf.apply_sensor(result, amcw)
    on_array = tprf.apply_sensor(np.array(result.transient), amcw, time=result.time)
    assert sorted(on_array) == ["depth", "measurements", "raw"] and on_array["raw"].shape == (16, 24, 2, 4)
    for name in on_result:
        assert np.array_equal(on_result[name], on_array[name]), name
    # Any cube with its time axis: a bounce order, in picoseconds (3.3356 ps per cm of path).
    bounce = result.arrays["transient_bounce_1"]
    gates = {"exposure": {"type": "gates", "start": 0.0, "width": 0.5, "step": 0.5, "count": 6}}
    in_metres = tprf.apply_sensor(bounce, gates, time=result.time)["measurements"]
    assert in_metres.shape == (16, 24, 6, 3) and in_metres.max() > 0
    ps = {"bin_width": 0.01 / 299792458.0 * 1e12, "unit": "ps"}
    gates_ps = {"exposure": {"type": "gates", "start": 0.0, "width": 0.5 / 299792458.0 * 1e12,
                             "step": 0.5 / 299792458.0 * 1e12, "count": 6}}
    in_ps = tprf.apply_sensor(bounce, gates_ps, time=ps)["measurements"]
    assert np.allclose(in_ps, in_metres, rtol=1e-5, atol=1e-7 * in_metres.max())
    with pytest.raises(ValueError, match="needs its time axis"):
        tprf.apply_sensor(bounce, gates)
    with pytest.raises(ValueError, match="camera cube"):
        tprf.apply_sensor(np.zeros((4, 4)), gates, time=result.time)
    with pytest.raises(ValueError, match="bins"):
        tprf.apply_sensor(bounce, gates, time={"bins": 7, "bin_width": 0.01})
    with pytest.raises(ValueError, match="no elements along axis 2"):
        tprf.apply_sensor(np.zeros((300, 4, 0), dtype=np.float32), gates, time=result.time)
