"""capture.hdf5 as the NLOS toolkit tal reads it (tal.io.read_capture, its NLOSCaptureData class).

read_tal() below follows tal's reader (tal/io/capture_data.py, read_hdf5 and NLOSCaptureData.__init__):
every top-level dataset read whole with [()], arrays of one element squeezed to a scalar, the Enum
fields turned into tal's Enum classes (their values copied from tal/enums.py), scene_info parsed as
YAML, and a key that NLOSCaptureData does not declare rejected.

The files are written by tests/hdf5_sample.cpp (tprf_hdf5_sample) to the paths in $TPRF_HDF5_SAMPLE
(confocal) and $TPRF_HDF5_SAMPLE_EXHAUSTIVE; the CTest test Io.PythonCaptureHdf5 runs both. Without those
variables, or without h5py (Debian: python3-h5py) or PyYAML (python3-yaml), the tests skip, saying why.
"""

import enum
import os
import pathlib

import pytest

np = pytest.importorskip("numpy", reason="numpy is missing (Debian: apt-get install python3-numpy)")
h5py = pytest.importorskip("h5py", reason="h5py is missing (Debian: apt-get install python3-h5py)")
yaml = pytest.importorskip("yaml", reason="PyYAML is missing (Debian: apt-get install python3-yaml)")


class HFormat(enum.Enum):
    UNKNOWN = 0
    T_Sx_Sy = 1
    T_Lx_Ly_Sx_Sy = 2
    T_Si = 3
    T_Li_Si = 4
    F_Sx_Sy = 10
    F_Lx_Ly_Sx_Sy = 11
    F_Si = 12
    F_Li_Si = 13


class GridFormat(enum.Enum):
    UNKNOWN = 0
    N_3 = 1
    X_Y_3 = 2


class VolumeFormat(enum.Enum):
    UNKNOWN = 0
    N_3 = 1
    X_Y_Z_3 = 2
    X_Y_3 = 3


# NLOSCaptureData's fields, with the Enum class of those that have one.
TAL_FIELDS = {
    "H": None, "H_format": HFormat,
    "sensor_xyz": None, "sensor_grid_xyz": None, "sensor_grid_normals": None, "sensor_grid_format": GridFormat,
    "laser_xyz": None, "laser_grid_xyz": None, "laser_grid_normals": None, "laser_grid_format": GridFormat,
    "volume_format": VolumeFormat, "delta_t": None, "t_start": None,
    "t_accounts_first_and_last_bounces": None, "scene_info": None,
}


def read_raw(path):
    """Each top-level dataset as tal's read_hdf5 leaves it, before the Enum classes."""
    out = {}
    with h5py.File(path, "r") as f:
        for key in f.keys():
            assert isinstance(f[key], h5py.Dataset), f"{key} is not a dataset"
            value = f[key][()]
            if isinstance(value, np.ndarray) and value.size == 1:
                value = np.squeeze(value)[()]
            out[key] = value
    return out


def read_tal(path):
    data = {}
    for key, value in read_raw(path).items():
        assert key in TAL_FIELDS, f"raw_data contains unknown key: {key}"
        if TAL_FIELDS[key] is not None:
            value = TAL_FIELDS[key](value)
        elif key == "scene_info":
            value = yaml.safe_load(value)
        data[key] = value
    return data


def sample(variable):
    path = os.environ.get(variable)
    if not path:
        pytest.skip(f"${variable} is not set: run through CTest (Io.PythonCaptureHdf5), which writes the sample")
    path = pathlib.Path(path)
    assert path.is_file(), f"{path} does not exist"
    return path


def expected_grid(nu, nv):
    """tests/hdf5_sample.cpp's grid: point (a, b) = (a / 10, b / 10, 0), normal (0, 0, 1)."""
    a, b = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    xyz = np.stack([0.1 * a, 0.1 * b, np.zeros_like(a, dtype=float)], axis=-1).astype(np.float32)
    normals = np.broadcast_to(np.array([0, 0, 1], dtype=np.float32), (nu, nv, 3))
    return xyz, normals


def check_common(data, shape, sensor_grid, laser_grid):
    assert set(data) == set(TAL_FIELDS)
    assert data["H"].dtype == np.float32 and data["H"].shape == shape
    # H[i] = i / 4 over the C-order index, so H[t, a, b] is its index in time-first order.
    assert np.array_equal(data["H"], (0.25 * np.arange(np.prod(shape))).astype(np.float32).reshape(shape))
    for prefix, (nu, nv) in (("sensor", sensor_grid), ("laser", laser_grid)):
        xyz, normals = expected_grid(nu, nv)
        for key, want in ((f"{prefix}_grid_xyz", xyz), (f"{prefix}_grid_normals", normals)):
            assert data[key].dtype == np.float32 and data[key].shape == (nu, nv, 3), key
            assert np.array_equal(data[key], want), key
        assert data[f"{prefix}_grid_format"] == GridFormat.X_Y_3
    for key, want in (("sensor_xyz", [-0.5, 0, 1]), ("laser_xyz", [0.5, 0, 1])):
        assert data[key].dtype == np.float32 and data[key].shape == (3,), key
        assert np.array_equal(data[key], np.array(want, dtype=np.float32)), key
    assert data["volume_format"] == VolumeFormat.UNKNOWN
    assert isinstance(data["delta_t"], float) and data["delta_t"] == 0.003
    assert isinstance(data["t_start"], float) and data["t_start"] == 0.0
    assert isinstance(data["t_accounts_first_and_last_bounces"], np.bool_)
    assert not data["t_accounts_first_and_last_bounces"]
    assert isinstance(data["scene_info"], dict)
    assert data["scene_info"]["generator"] == "tprf_hdf5_sample"


def test_enum_fields_are_numpy_integers_as_tal_reads_them():
    raw = read_raw(sample("TPRF_HDF5_SAMPLE"))
    for key, want in (("H_format", 1), ("sensor_grid_format", 2), ("laser_grid_format", 2), ("volume_format", 0)):
        assert isinstance(raw[key], np.integer), f"{key}: {type(raw[key])}"
        assert raw[key] == want, key
    assert isinstance(raw["scene_info"], bytes)  # a variable-length string; tal parses it as YAML


def test_confocal_sample_reads_as_tal_reads_it():
    data = read_tal(sample("TPRF_HDF5_SAMPLE"))
    assert data["H_format"] == HFormat.T_Sx_Sy
    check_common(data, (6, 4, 3), sensor_grid=(4, 3), laser_grid=(4, 3))
    # tal's is_confocal(): no laser axes in H, and the laser grid is the sensor grid.
    assert np.allclose(data["sensor_grid_xyz"], data["laser_grid_xyz"])


def test_exhaustive_sample_reads_as_tal_reads_it():
    data = read_tal(sample("TPRF_HDF5_SAMPLE_EXHAUSTIVE"))
    assert data["H_format"] == HFormat.T_Lx_Ly_Sx_Sy
    check_common(data, (5, 2, 2, 3, 2), sensor_grid=(3, 2), laser_grid=(2, 2))
