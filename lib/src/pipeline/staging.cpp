#include "staging.h"

#include "tprf/core/error.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/io/json_records.h"
#include "tprf/io/npy.h"
#include "tprf/io/plots.h"

#include <unistd.h>

#include <algorithm>
#include <memory>

namespace tprf {

Staging::Staging(const std::filesystem::path& out) : m_out(out) {
    m_earlier_run = std::filesystem::exists(out / "render.json");
    m_dir = out / (".tprf-staging-" + std::to_string(::getpid()));
    std::filesystem::remove_all(m_dir);
    std::filesystem::create_directories(m_dir);
}

Staging::~Staging() {
    std::error_code ec;
    std::filesystem::remove_all(m_dir, ec);
}

std::filesystem::path Staging::path(const std::string& name) {
    m_names.push_back(name);
    return m_dir / name;
}

void Staging::forget(const std::string& name) {
    m_names.erase(std::remove(m_names.begin(), m_names.end(), name), m_names.end());
    std::error_code ec;
    std::filesystem::remove_all(m_dir / name, ec);
}

void Staging::publish(const std::vector<std::string>& owned) {
    for (const std::string& name : m_names) {
        const std::filesystem::path to = m_out / name;
        if (std::filesystem::is_directory(to)) std::filesystem::remove_all(to);
        std::filesystem::rename(m_dir / name, to);
    }
    // Only in a directory that an earlier run wrote: a folder of the user's own named "frames" in
    // some other directory is not ours to remove.
    if (!m_earlier_run) return;
    for (const auto& entry : std::filesystem::directory_iterator(m_out)) {
        const std::string name = entry.path().filename().string();
        if (std::find(m_names.begin(), m_names.end(), name) != m_names.end()) continue;
        for (const std::string& o : owned) {
            const bool prefix = !o.empty() && o.back() == '*';
            if (prefix ? name.rfind(o.substr(0, o.size() - 1), 0) == 0 : name == o) {
                std::filesystem::remove_all(entry.path());
                break;
            }
        }
    }
}

const std::vector<std::string>& sensor_outputs() {
    static const std::vector<std::string> names = {"measurements.npy", "depth.npy", "sensor.json", "sensor_plot.json",
                                                   "sensor_plot.png"};
    return names;
}

std::array<int, 2> plot_pixel(const std::optional<std::array<int, 2>>& asked, int width, int height) {
    if (!asked) return {width / 2, height / 2};
    const auto [x, y] = *asked;
    if (x < 0 || y < 0 || x >= width || y >= height)
        throw Error("--plot-pixel " + std::to_string(x) + "," + std::to_string(y) + " is outside the " +
                    std::to_string(width) + " x " + std::to_string(height) + " image (x is the column, y the row)");
    return *asked;
}

int write_sensor_outputs(Staging& staging, const SensorSettings& sensor, const TimeAxis& time, const float* cube,
                         int height, int width, std::array<int, 2> pixel, const PipelineOptions& run,
                         std::vector<std::string>& warnings) {
    const int K = measurement_count(sensor, time);
    const std::size_t H = std::size_t(height), W = std::size_t(width);
    NpyMap measurements(staging.path("measurements.npy"), {H, W, std::size_t(K), 3});
    std::unique_ptr<NpyMap> depth;
    if (sensor.exposure.type == ExposureType::Amcw)
        depth = std::make_unique<NpyMap>(staging.path("depth.npy"), std::vector<std::size_t>{H, W});
    SensorOptions options;
    options.threads = run.threads;
    apply_sensor(sensor, time, cube, height, width, measurements.data(), depth ? depth->data() : nullptr, options);
    const std::size_t p = std::size_t(pixel[1]) * W + std::size_t(pixel[0]);
    const std::filesystem::path data = staging.path("sensor_plot.json");
    write_sensor_plot_json(data, sensor_plot(sensor, time, cube + p * std::size_t(time.bins) * 3,
                                             measurements.data() + p * std::size_t(K) * 3, pixel[0], pixel[1]));
    write_sensor_json(staging.path("sensor.json"), sensor, time, K, pixel);
    measurements.commit();
    if (depth) depth->commit();
    // The figure last: it is the one output that needs Python, and its absence is not an error. A
    // caller that draws nothing itself keeps sensor_plot.json.
    if (!run.draw_plots) return K;
    const std::filesystem::path png = staging.path("sensor_plot.png");
    std::string failure;
    if (!run_plot_script({"sensor", data.string(), png.string()}, &failure)) {
        staging.forget("sensor_plot.png");
        warnings.push_back(plot_not_drawn_message(staging.final_path("sensor_plot.png"),
                                                  {"sensor", staging.final_path("sensor_plot.json").string(),
                                                   staging.final_path("sensor_plot.png").string()},
                                                  failure));
    }
    return K;
}

double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace tprf
