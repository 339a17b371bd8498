#pragma once
// Private to the pipeline: where the arrays of a render go. render_file writes them as .npy files in
// its staging folder (the cubes memory-mapped, so that a cube larger than memory never needs a copy);
// render_scene keeps them in its RenderResult, for the Python module. The stages fill both alike, so
// the numbers of the two are the same bit for bit.

#include "staging.h"
#include "tprf/io/npy.h"
#include "tprf/pipeline/render.h"

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

namespace tprf {

class Arrays {
public:
    /// Files in the staging folder: `name` "transient" is staging.path("transient.npy").
    explicit Arrays(Staging& staging) : m_staging(&staging) {}
    /// Arrays of `result` (RenderResult::arrays), by name.
    explicit Arrays(RenderResult& result) : m_result(&result) {}

    /// A zeroed array of `shape` (float32, C order) for the caller to fill; it stays valid until
    /// commit() (files) or as long as the result (memory).
    float* open(const std::string& name, const std::vector<std::size_t>& shape);
    /// A finished array handed over: written and kept here (files) or moved into the result (memory).
    /// The returned array lives as long as this Arrays (files) or the result (memory).
    const FloatArray& put(const std::string& name, FloatArray&& array);
    /// An int32 array handed over: written (files) or moved into the result's labels (memory).
    void put(const std::string& name, Int32Array&& array);
    /// Files: every open() array flushed and moved to its staging name. Memory: nothing to do.
    void commit();

    /// The staging folder, for the outputs that exist only as files (images, frames, HDF5, JSON);
    /// null when the arrays stay in memory.
    Staging* staging() const { return m_staging; }

private:
    Staging* m_staging = nullptr;
    RenderResult* m_result = nullptr;
    std::vector<std::unique_ptr<NpyMap>> m_maps;
    std::vector<std::unique_ptr<FloatArray>> m_kept;
};

struct CubeView;

/// A sensor block applied to a cube (height, width, T, 3): "measurements" (height, width, K, 3) and,
/// for amcw, "depth" (height, width) opened in `out` and filled. Returns K and the measurements.
struct Measured {
    int K = 0;
    const float* measurements = nullptr;
};
Measured measure_cube(const SensorSettings& sensor, const CubeView& cube, int threads, Arrays& out);

/// A capture's H as a cube that a sensor block measures: one row of pixels per laser point and sensor
/// row (a confocal capture: per sensor row), one pixel per sensor column, the value in every colour.
struct CaptureCube {
    std::vector<float> cube;  ///< (height, width, T, 3)
    int height = 0;
    int width = 0;
};
/// `data` of `shape`: H time first, (T, nu, nv) or (T, nu_l, nv_l, nu_s, nv_s) (capture.npy's layout).
CaptureCube capture_cube(const std::vector<std::size_t>& shape, const float* data);

}  // namespace tprf
