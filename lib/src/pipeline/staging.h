#pragma once
// Private to the pipeline: the staging folder that makes a run's outputs appear all at once, and the
// steps that `tprf render` and `tprf sensor` share.

#include "tprf/core/time_axis.h"
#include "tprf/pipeline/options.h"
#include "tprf/scene/sensor_settings.h"

#include <array>
#include <chrono>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tprf {

/// An exclusive lock (flock) on a directory while it lives, as a Staging holds on its own: `tprf sensor`
/// holds its render's directory, so that no render replaces the cube (or removes the sensor's folder)
/// while it is measured. Throws tprf::Error when another run holds it.
class DirectoryLock {
public:
    explicit DirectoryLock(const std::filesystem::path& dir);
    ~DirectoryLock();
    DirectoryLock(const DirectoryLock&) = delete;
    DirectoryLock& operator=(const DirectoryLock&) = delete;

private:
    int m_fd = -1;
};

/// Outputs are written into a hidden staging folder inside the output directory, then moved into
/// place one by one once every one of them is complete; on failure or cancellation the folder is
/// removed. The output directory is locked (flock) from construction to destruction, so two runs
/// never write into one directory at once: the second is refused (tprf::Error) before it renders.
class Staging {
public:
    /// Locks `out` (which must exist), removes staging folders that killed runs left there, and
    /// creates this run's. `marker`: the file whose presence says an earlier run of the same kind
    /// wrote `out` (render.json; a sensor folder's sensor.json), whose outputs publish() may replace.
    explicit Staging(const std::filesystem::path& out, const std::string& marker = "render.json");
    ~Staging();
    Staging(const Staging&) = delete;
    Staging& operator=(const Staging&) = delete;

    /// The staging path of output `name` (a file or a folder), recorded as written.
    std::filesystem::path path(const std::string& name);

    /// Drops output `name` (not written after all).
    void forget(const std::string& name);
    /// Where output `name` will be once published.
    std::filesystem::path final_path(const std::string& name) const { return m_out / name; }

    /// Moves every staged output into place (unless the run was cancelled: then Cancelled), then, when the directory held an earlier render, removes
    /// that run's outputs that this one did not write (`owned`: names, or prefixes ending in '*'), so
    /// that the directory never mixes two runs (a depth.npy of an earlier AMCW sensor beside gated
    /// measurements, say).
    void publish(const std::vector<std::string>& owned);
    /// `message` with the staging folder's paths replaced by the final ones: what a user looks for.
    std::string public_message(const std::string& message) const;
    /// The outputs written, relative to the output directory.
    const std::vector<std::string>& names() const { return m_names; }

private:
    std::filesystem::path m_out, m_dir;
    int m_lock = -1;  ///< the output directory, open and flock()ed
    std::vector<std::string> m_names;
    bool m_earlier_run = false;
};

/// What a sensor run writes (docs/sensor.md).
const std::vector<std::string>& sensor_outputs();

/// The plot pixel: the image centre by default; one outside the image is a bad flag.
std::array<int, 2> plot_pixel(const std::optional<std::array<int, 2>>& asked, int width, int height);

struct CubeView;

/// A capture that a cube's rows are (capture_cube): its capture.hdf5 and the shape of its H (T, ...).
struct CaptureSource {
    std::filesystem::path file;
    std::vector<std::size_t> shape;
};

/// What a sensor measures: a cube (H, W, T, 3), the pixel its plot shows and, when the cube's rows are
/// a capture's sensor points, that capture.
struct SensorSubject {
    const CubeView& cube;
    std::array<int, 2> pixel;
    const CaptureSource* capture = nullptr;
};

/// measurements.npy, depth.npy and raw.npy (amcw), sensor.json, sensor_plot.json and sensor_plot.png:
/// what a sensor block turns the subject's cube into; with a SPAD on the rows of its capture (when the
/// capture's file exists), also capture.hdf5: that file with H the first channel's counts. Returns K.
/// When no Python with matplotlib can draw the plot, the data is still written and `warnings` gets a
/// line saying how to draw it; with draw_plots off, only the data is written.
int write_sensor_outputs(Staging& staging, const SensorSettings& sensor, const SensorSubject& subject,
                         const PipelineOptions& options, std::vector<std::string>& warnings);

/// Seconds from `start` to now.
double seconds_since(std::chrono::steady_clock::time_point start);

}  // namespace tprf
