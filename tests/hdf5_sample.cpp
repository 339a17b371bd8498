// Writes sample capture.hdf5 files for python/tests/test_capture_hdf5.py, which reads them the way the
// NLOS toolkit tal does (the CTest test Io.PythonCaptureHdf5 runs both).
//
//     tprf_hdf5_sample CONFOCAL.hdf5 [EXHAUSTIVE.hdf5]
//
// Confocal: T = 6 bins over a 4 x 3 grid. Exhaustive: T = 5 over a 2 x 2 laser grid and a 3 x 2 sensor
// grid. Every value follows from its indices (the formulas below, repeated in the Python test):
//   H[i] = 0.25 * i (i the C-order index), grid point (a, b) = (a / 10, b / 10, 0), normal (0, 0, 1).
#include "tprf/core/error.h"
#include "tprf/io/hdf5_capture.h"

#include <cstddef>
#include <exception>
#include <iostream>
#include <vector>

namespace {

tprf::CaptureGridData make_grid(int nu, int nv) {
    tprf::CaptureGridData grid;
    grid.nu = nu;
    grid.nv = nv;
    for (int a = 0; a < nu; ++a)
        for (int b = 0; b < nv; ++b) {
            grid.xyz.push_back(tprf::Vec3(0.1 * a, 0.1 * b, 0.0));
            grid.normals.push_back(tprf::Vec3(0.0, 0.0, 1.0));
        }
    return grid;
}

void write_sample(const char* path, bool confocal) {
    tprf::CaptureFile capture;
    capture.confocal = confocal;
    capture.shape = confocal ? std::vector<std::size_t>{6, 4, 3} : std::vector<std::size_t>{5, 2, 2, 3, 2};
    std::size_t count = 1;
    for (const std::size_t n : capture.shape) count *= n;
    std::vector<float> h(count);
    for (std::size_t i = 0; i < count; ++i) h[i] = 0.25f * static_cast<float>(i);
    capture.H = h.data();
    capture.sensor_grid = confocal ? make_grid(4, 3) : make_grid(3, 2);
    capture.laser_grid = confocal ? capture.sensor_grid : make_grid(2, 2);
    capture.sensor_xyz = tprf::Vec3(-0.5, 0.0, 1.0);
    capture.laser_xyz = tprf::Vec3(0.5, 0.0, 1.0);
    capture.delta_t = 0.003;
    capture.t_start = 0.0;
    capture.t_accounts_first_and_last_bounces = false;
    capture.scene_info = "generator: tprf_hdf5_sample\ntprf_version: 0.1.0\nscene:\n  file: sample.json\n";
    tprf::write_capture_hdf5(path, capture);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2 || argc > 3) {
        std::cerr << "usage: tprf_hdf5_sample CONFOCAL.hdf5 [EXHAUSTIVE.hdf5]\n";
        return 2;
    }
    try {
        write_sample(argv[1], true);
        if (argc == 3) write_sample(argv[2], false);
    } catch (const std::exception& e) {
        std::cerr << "tprf_hdf5_sample: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
