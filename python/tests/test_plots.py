"""python/tprf_plots.py on small data files: the PNG appears with the documented size, bad data is
exit status 2 without a PNG, and a Python without matplotlib is exit status 3 (what tprf relies on
to try another Python, then to tell the user how to install it).

The script runs in a child process under the first Python that can import matplotlib and numpy
($TPRF_PYTHON, the python3s along the PATH, this interpreter), as tprf itself looks for one; the
tests that draw are skipped, saying so, where none can.
"""

import json
import os
import pathlib
import shutil
import struct
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "tprf_plots.py"


def candidate_pythons():
    if os.environ.get("TPRF_PYTHON"):
        return [os.environ["TPRF_PYTHON"]]
    found = []
    for d in os.environ.get("PATH", "").split(os.pathsep):
        p = shutil.which("python3", path=d or ".")
        if p and os.path.realpath(p) not in {os.path.realpath(f) for f in found}:
            found.append(p)
    return found + [sys.executable]


def find_matplotlib_python():
    for python in candidate_pythons():
        try:
            r = subprocess.run([python, "-c", "import matplotlib, numpy"], capture_output=True, timeout=120)
        except OSError:
            continue
        if r.returncode == 0:
            return python
    return None


PYTHON = find_matplotlib_python()
needs_matplotlib = pytest.mark.skipif(
    PYTHON is None, reason="no Python with matplotlib and numpy (Debian: apt-get install python3-matplotlib)")


def run(*args, python=None, options=()):
    return subprocess.run([python or PYTHON, *options, str(SCRIPT), *map(str, args)], capture_output=True,
                          text=True, timeout=300)


def png_size(path):
    """(width, height) from a PNG's IHDR chunk."""
    data = pathlib.Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def sensor_data(exposure="gates"):
    """A sensor_plot.json as tprf writes it: 8 bins of 0.1 m, a spike in bin 3 and a pulse-blurred copy."""
    edges = [round(0.1 * i, 10) for i in range(9)]
    density = [0, 0, 0, 10.0, 2.5, 0, 0, 0]
    conv_t = [round(0.05 + 0.1 * i, 10) for i in range(-1, 9)]
    conv = [0, 0, 0.5, 6.0, 4.0, 1.5, 0.5, 0, 0, 0]
    if exposure == "amcw":
        at, values, units_at, units_m = [0, 90, 180, 270], [1.2, 0.9, 0.3, 0.6], "degrees", "measurement"
    elif exposure == "spad":
        at, values, units_at, units_m = edges[:-1], [0, 1, 0, 19, 6, 1, 0, None], "m", "counts per bin"
    else:
        at, values, units_at, units_m = [0.1, 0.3, 0.5, 0.7], [0.0, 1.25, 0.25, 0.0], "m", "measurement"
    return {
        "pixel": [3, 4],
        "exposure": exposure,
        "window": [0.0, 0.8],
        "units": {"time": "m", "tprf": "radiance s per m", "measurement_at": units_at, "measurements": units_m},
        "tprf": {"bin_edges": edges, "density": density},
        "tprf_pulse": {"time": conv_t, "density": conv},
        "measurements": {"at": at, "value": values},
    }


@needs_matplotlib
@pytest.mark.parametrize("exposure", ["gates", "amcw", "spad"])
def test_sensor_plot_is_a_900_by_640_png(tmp_path, exposure):
    data = tmp_path / "sensor_plot.json"
    data.write_text(json.dumps(sensor_data(exposure)))
    out = tmp_path / "sensor_plot.png"
    r = run("sensor", data, out)
    assert r.returncode == 0, r.stderr
    # 9 x 6.4 inches at 100 dpi, fixed whatever the data.
    assert png_size(out) == (900, 640)
    # Written under a temporary name and renamed: nothing else is left beside it.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sensor_plot.json", "sensor_plot.png"]


@needs_matplotlib
def test_scaling_plot_is_a_1000_by_1320_png(tmp_path):
    phases = "load_s,patches_s,links_s,solve_s,gather_s,write_s,total_s"
    (tmp_path / "harness.csv").write_text(
        f"label,max_edge,patches,links,bins,width,height,{phases}\n"
        "patches+bins,0.2,300,1000,64,24,24,0,0,0.1,0.2,0.1,0.1,0.5\n"
        "patches,0.15,550,3000,64,24,24,0,0,0.3,0.4,0.1,0.1,0.9\n"
        "bins,0.2,300,1000,128,24,24,0,0,0.1,0.4,0.2,0.1,0.8\n"
        "bins,0.15,550,3000,64,24,24,0,0,0.3,0.4,0.1,0.1,0.9\n"
        "pixels,0.2,300,1000,64,32,32,0,0,0.1,0.2,0.2,0.1,0.6\n")
    (tmp_path / "accuracy.csv").write_text(
        "max_edge,patches,total_s,rel_l2_transient,rel_l2_transient_16bin,rel_l2_steady\n"
        "0.2,300,0.5,0.01,0.008,0.006\n0.15,550,0.9,0.007,0.005,0.004\n")
    out = tmp_path / "scaling.png"
    r = run("scaling", tmp_path / "harness.csv", tmp_path / "accuracy.csv", out, "--bin-width", "0.04",
            "--accuracy-bins", "128")
    assert r.returncode == 0, r.stderr
    assert png_size(out) == (1000, 1320)


@needs_matplotlib
def test_bad_data_exits_two_without_a_png(tmp_path):
    data = tmp_path / "bad.json"
    broken = sensor_data()
    broken["tprf"]["bin_edges"].pop()  # T edges for T bins
    data.write_text(json.dumps(broken))
    out = tmp_path / "out.png"
    r = run("sensor", data, out)
    assert r.returncode == 2
    assert "bad.json" in r.stderr and "lengths" in r.stderr
    assert not out.exists()
    r = run("sensor", tmp_path / "missing.json", out)
    assert r.returncode == 2 and "missing.json" in r.stderr


def test_without_matplotlib_exits_three_and_says_how_to_install(tmp_path):
    # -S: no site-packages, so neither matplotlib nor numpy can be imported, whatever is installed.
    data = tmp_path / "sensor_plot.json"
    data.write_text(json.dumps(sensor_data()))
    r = run("sensor", data, tmp_path / "out.png", python=sys.executable, options=["-S"])
    assert r.returncode == 3, r.stderr
    assert "apt-get install python3-matplotlib" in r.stderr
    assert not (tmp_path / "out.png").exists()


def test_auto_scale_is_log_where_the_values_span_more_than_a_thousand():
    import importlib.util
    spec = importlib.util.spec_from_file_location("tprf_plots", SCRIPT)
    plots = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(plots)
    counts = [0, 0, 3, 12000, 40, 0]  # a SPAD histogram: zeros and a peak 4000 times the smallest count
    assert plots.y_scale(counts, "auto") == ("symlog", 3)
    assert plots.y_scale([1.0, 2.0, 900.0], "auto") == ("linear", None)
    assert plots.y_scale([1.0, 2.0, 900.0], "log") == ("symlog", 1.0)
    assert plots.y_scale(counts, "linear") == ("linear", None)
    assert plots.y_scale([0.0, 0.0], "log") == ("linear", None)  # nothing positive to put on a log axis


@needs_matplotlib
@pytest.mark.parametrize("scale", ["auto", "log", "linear"])
def test_every_scale_draws_the_spad_plot(tmp_path, scale):
    data = tmp_path / "sensor_plot.json"
    spad = sensor_data("spad")
    spad["measurements"]["value"] = [0.0] * (len(spad["measurements"]["value"]) - 1) + [5000.0]
    data.write_text(json.dumps(spad))
    out = tmp_path / "sensor_plot.png"
    r = run("sensor", data, out, "--scale", scale)
    assert r.returncode == 0, r.stderr
    assert png_size(out) == (900, 640)
