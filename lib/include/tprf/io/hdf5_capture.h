#pragma once
/// capture.hdf5: an NLOS capture in the layout of the `tal` toolkit's NLOSCaptureData (every
/// field, unit and axis order in docs/capture.md), through the HDF5 C++ library.

#include "tprf/core/types.h"

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace tprf {

/// A grid of points on the relay wall as tal stores it (grid format X_Y_3): point (a, b) at index
/// a * nv + b of `xyz` and `normals`.
struct CaptureGridData {
    int nu = 0;
    int nv = 0;
    std::vector<Vec3> xyz;      ///< nu * nv points, metres
    std::vector<Vec3> normals;  ///< nu * nv unit normals of the wall at the points
};

/// Everything capture.hdf5 holds.
struct CaptureFile {
    bool confocal = true;        ///< H_format 1 (T_Sx_Sy); false: 2 (T_Lx_Ly_Sx_Sy)
    /// H, float32 in C order, time first: (T, nu, nv) for confocal (the sensor grid's nu, nv), else
    /// (T, nu_l, nv_l, nu_s, nv_s). Radiance times seconds per bin, one channel.
    std::vector<std::size_t> shape;
    const float* H = nullptr;    ///< product(shape) values, owned by the caller
    CaptureGridData sensor_grid;
    CaptureGridData laser_grid;  ///< confocal: the same points as sensor_grid
    Vec3 sensor_xyz = Vec3::Zero();  ///< the sensor device, metres
    Vec3 laser_xyz = Vec3::Zero();   ///< the laser device, metres
    double delta_t = 0.0;        ///< bin width, metres of optical path
    double t_start = 0.0;        ///< path of bin 0's start, metres
    bool t_accounts_first_and_last_bounces = false;
    std::string scene_info;      ///< YAML text: the scene and the tprf version
};

/// Writes `capture` to `path` (the caller stages it; this writes that name directly). Throws
/// tprf::Error naming the file when the HDF5 library fails (a full disk, a missing folder).
void write_capture_hdf5(const std::filesystem::path& path, const CaptureFile& capture);

/// Writes `to` as a copy of the capture file `from` whose H is replaced by `H` (float32, C order, of
/// `from`'s H's shape, which must equal `shape`): a sensor's measurement of a capture (a SPAD's noisy
/// histograms) that tal reads as it reads the render's own. Throws tprf::Error naming the file when
/// `from` cannot be read, its H has another shape, or the library fails.
void copy_capture_with_h(const std::filesystem::path& from, const std::filesystem::path& to, const float* H,
                         const std::vector<std::size_t>& shape);

}  // namespace tprf
