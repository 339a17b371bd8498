#include "staging.h"

#include "arrays.h"
#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/imaging/sensor_model.h"
#include "tprf/io/hdf5_capture.h"
#include "tprf/io/json_records.h"
#include "tprf/io/npy.h"
#include "tprf/io/plots.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <memory>

namespace tprf {

namespace {

constexpr const char* kStagingPrefix = ".tprf-staging-";

// The output directory, open and locked for this process's run; -1 when it cannot be opened (a file
// system without directory descriptors: then runs are not kept apart).
int lock_output_dir(const std::filesystem::path& out) {
    const int fd = ::open(out.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return -1;
    while (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
        const int err = errno;
        if (err == EINTR) continue;
        ::close(fd);
        if (err == EWOULDBLOCK)
            throw Error(out.string() + ": another tprf run is writing into this output directory; wait for it to "
                                       "finish, or choose another (nothing was written)");
        return -1;  // no locks on this file system (some network file systems): nothing to keep apart with
    }
    return fd;
}

// Staging folders of runs that were killed (SIGKILL, a power cut): with the directory locked, no
// living run owns one.
void remove_stale_staging(const std::filesystem::path& out) {
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(out, ec))
        if (entry.path().filename().string().rfind(kStagingPrefix, 0) == 0) std::filesystem::remove_all(entry.path(), ec);
}

}  // namespace

DirectoryLock::DirectoryLock(const std::filesystem::path& dir) : m_fd(lock_output_dir(dir)) {}

DirectoryLock::~DirectoryLock() {
    if (m_fd >= 0) ::close(m_fd);
}

Staging::Staging(const std::filesystem::path& out, const std::string& marker)
    : m_out(out), m_lock(lock_output_dir(out)) {
    m_earlier_run = std::filesystem::exists(out / marker);
    if (m_lock >= 0) remove_stale_staging(out);
    m_dir = out / (kStagingPrefix + std::to_string(::getpid()));
    std::error_code ec;
    std::filesystem::remove_all(m_dir, ec);
    std::filesystem::create_directories(m_dir, ec);
    if (ec) {
        if (m_lock >= 0) ::close(m_lock);
        fail_output(m_dir, "cannot create the staging folder", ec.value());
    }
}

Staging::~Staging() {
    std::error_code ec;
    std::filesystem::remove_all(m_dir, ec);
    if (m_lock >= 0) ::close(m_lock);  // releases the lock
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
    check_cancelled();  // the last point where a cancelled run leaves the directory as it was
    for (const std::string& name : m_names) {
        const std::filesystem::path to = m_out / name;
        std::error_code ec;
        if (std::filesystem::is_directory(to)) std::filesystem::remove_all(to, ec);
        if (!ec) std::filesystem::rename(m_dir / name, to, ec);
        if (ec) fail_output(to, "cannot move the finished output into place", ec.value());
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

std::string Staging::public_message(const std::string& message) const {
    const std::string from = (m_dir / "").string(), to = (m_out / "").string();
    std::string out = message;
    for (std::size_t at = out.find(from); at != std::string::npos; at = out.find(from, at + to.size()))
        out.replace(at, from.size(), to);
    return out;
}

const std::vector<std::string>& sensor_outputs() {
    static const std::vector<std::string> names = {"measurements.npy", "depth.npy", "raw.npy", "sensor.json",
                                                   "sensor_plot.json", "sensor_plot.png", "capture.hdf5"};
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

int write_sensor_outputs(Staging& staging, const SensorSettings& sensor, const SensorSubject& subject,
                         const PipelineOptions& run, std::vector<std::string>& warnings) {
    const CubeView& view = subject.cube;
    const std::array<int, 2>& pixel = subject.pixel;
    const CaptureSource* capture = subject.capture;
    const TimeAxis& time = view.time;
    const float* cube = view.data;
    Arrays arrays(staging);
    const auto [K, measurements] = measure_cube(sensor, view, run.threads, arrays);
    // A SPAD's histograms of a capture are a capture: its file with H replaced by the counts (the first
    // channel's: one detector), for tal to read as it reads the noise-free one.
    if (capture && sensor.exposure.type == ExposureType::Spad && std::filesystem::exists(capture->file)) {
        const std::size_t T = std::size_t(time.bins), pairs = std::size_t(view.height) * std::size_t(view.width);
        std::vector<float> H(T * pairs);
        for (std::size_t q = 0; q < pairs; ++q)
            for (std::size_t t = 0; t < T; ++t) H[t * pairs + q] = measurements[(q * T + t) * 3];
        copy_capture_with_h(capture->file, staging.path("capture.hdf5"), H.data(), capture->shape);
    }
    const std::size_t p = std::size_t(pixel[1]) * std::size_t(view.width) + std::size_t(pixel[0]);
    const std::filesystem::path data = staging.path("sensor_plot.json");
    write_sensor_plot_json(data, sensor_plot(sensor, time, cube + p * std::size_t(time.bins) * 3,
                                             measurements + p * std::size_t(K) * 3, pixel[0], pixel[1]));
    write_sensor_json(staging.path("sensor.json"), sensor, time, K, pixel);
    arrays.commit();
    // The figure last: it is the one output that needs Python, and its absence is not an error. A
    // caller that draws nothing itself keeps sensor_plot.json.
    if (!run.draw_plots) return K;
    const std::filesystem::path png = staging.path("sensor_plot.png");
    std::string failure;
    if (!run_plot_script({"sensor", data.string(), png.string(), "--scale", run.plot_scale}, &failure)) {
        staging.forget("sensor_plot.png");
        warnings.push_back(plot_not_drawn_message(staging.final_path("sensor_plot.png"),
                                                  {"sensor", staging.final_path("sensor_plot.json").string(),
                                                   staging.final_path("sensor_plot.png").string(), "--scale",
                                                   run.plot_scale},
                                                  failure));
    }
    return K;
}

double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace tprf
