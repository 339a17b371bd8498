#include "arrays.h"

#include "tprf/imaging/sensor_model.h"

#include <algorithm>
#include <functional>
#include <numeric>

namespace tprf {
namespace {

std::size_t elements(const std::vector<std::size_t>& shape) {
    return std::accumulate(shape.begin(), shape.end(), std::size_t(1), std::multiplies<>());
}

}  // namespace

float* Arrays::open(const std::string& name, const std::vector<std::size_t>& shape) {
    if (m_staging) {
        m_maps.push_back(std::make_unique<NpyMap>(m_staging->path(name + ".npy"), shape));
        return m_maps.back()->data();
    }
    FloatArray& a = m_result->arrays[name];
    a.shape = shape;
    a.data.assign(elements(shape), 0.0f);
    return a.data.data();
}

const FloatArray& Arrays::put(const std::string& name, FloatArray&& array) {
    if (m_staging) {
        write_npy(m_staging->path(name + ".npy"), array.shape, array.data.data());
        m_kept.push_back(std::make_unique<FloatArray>(std::move(array)));
        return *m_kept.back();
    }
    FloatArray& kept = m_result->arrays[name];
    kept = std::move(array);
    return kept;
}

void Arrays::put(const std::string& name, Int32Array&& array) {
    if (m_staging) write_npy(m_staging->path(name + ".npy"), array.shape, array.data.data());
    else m_result->labels[name] = std::move(array);
}

void Arrays::commit() {
    for (auto& map : m_maps) map->commit();
    m_maps.clear();
}

Measured measure_cube(const SensorSettings& sensor, const CubeView& cube, int threads, Arrays& out) {
    const int K = measurement_count(sensor, cube.time);
    const std::size_t H = std::size_t(cube.height), W = std::size_t(cube.width);
    float* measurements = out.open("measurements", {H, W, std::size_t(K), 3});
    const bool amcw = sensor.exposure.type == ExposureType::Amcw;
    float* depth = amcw ? out.open("depth", {H, W}) : nullptr;
    float* raw = amcw ? out.open("raw", {H, W, sensor.exposure.amcw_frequencies_hz().size(),
                                         sensor.exposure.phases_deg.size()})
                      : nullptr;
    SensorOptions options;
    options.threads = threads;
    apply_sensor(sensor, cube, measurements, depth, options, raw);
    return {K, measurements};
}

CaptureCube capture_cube(const std::vector<std::size_t>& shape, const float* data) {
    const std::size_t T = shape[0];
    const std::size_t pairs = T ? elements(shape) / T : 0;
    CaptureCube c;
    c.width = int(shape.back());
    c.height = int(pairs / shape.back());
    c.cube.resize(pairs * T * 3);
    for (std::size_t pair = 0; pair < pairs; ++pair)
        for (std::size_t t = 0; t < T; ++t)
            for (std::size_t ch = 0; ch < 3; ++ch) c.cube[(pair * T + t) * 3 + ch] = data[t * pairs + pair];
    return c;
}

}  // namespace tprf
