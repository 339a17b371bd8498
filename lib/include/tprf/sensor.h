#pragma once
/// The TPRF sensor model (transient rendering paper, section 6; SPEC.md, "Sensor block"):
///
///     M_k = max(0, noise + integral of (TPRF * pulse)(t) exposure_k(t) dt)
///
/// The cube's bin i holds the energy e_i that arrives in [t_i, t_i + bin_width), taken as spread
/// evenly over the bin. Everything before the noise is linear in e, so each measurement is a weighted
/// sum M_k = sum_i w_k[i] e_i whose weights fold the pulse (and a SPAD's timing jitter) into the
/// exposure once per render, not once per pixel. All times are in the scene's time unit.

#include "tprf/time_axis.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tprf {

struct JsonNode;

/// The emitted pulse's shape in time. Symmetric shapes are centred on t = 0, so that they keep the
/// mean arrival time; a table keeps the times it is given.
enum class PulseShape { Delta, Gaussian, Box, Table };

/// `sensor.pulse`.
struct SensorPulse {
    PulseShape shape = PulseShape::Delta;
    double fwhm = 0.0;                 ///< gaussian: full width at half maximum, time unit, > 0
    double width = 0.0;                ///< box: width, time unit, > 0
    std::vector<double> table_time;    ///< table: strictly increasing sample times, time unit
    std::vector<double> table_value;   ///< table: values >= 0 (linear between samples), positive area
};

/// What each measurement integrates.
enum class ExposureType { Gates, Windows, Amcw, Spad };

/// `sensor.exposure`.
struct Exposure {
    ExposureType type = ExposureType::Gates;
    /// gates and windows: one [start, width] per measurement, time unit (gates are expanded here).
    std::vector<std::array<double, 2>> windows;
    double frequency_mhz = 0.0;        ///< amcw: modulation frequency, MHz, > 0
    std::vector<double> phases_deg;    ///< amcw: one measurement per phase, degrees; >= 3 distinct
    double photons = 1.0;              ///< spad: expected photons per unit of signal, > 0
    double jitter_fwhm = 0.0;          ///< spad: gaussian timing jitter, time unit, >= 0
    double dark_rate = 0.0;            ///< spad: dark counts per second of bin time, >= 0
    std::uint64_t seed = 0;            ///< spad: seed of the photon counts
};

/// `sensor.noise`: additive Gaussian noise on every measurement.
struct SensorNoise {
    double sigma = 0.0;                ///< standard deviation, in the measurement's unit, >= 0
    std::uint64_t seed = 0;
};

/// A validated `sensor` block.
struct SensorSettings {
    SensorPulse pulse;
    Exposure exposure;
    SensorNoise noise;
    bool clamp = true;                 ///< max(0, ...), as the paper's model
    std::filesystem::path file;        ///< where the block was read, for messages
    std::string json_path;             ///< the block's JSON path ("sensor", or "" for a sensor file)
};

/// Validates a `sensor` block; errors name the node's file and JSON path. A table pulse's CSV is
/// read here, relative to the node's file.
SensorSettings parse_sensor(const JsonNode& block);

/// Reads a sensor file for `tprf sensor`: either the block itself or an object {"sensor": block}.
SensorSettings load_sensor(const std::filesystem::path& file);

/// Checks the block against a render's time axis: the pulse (and a SPAD's jitter) must reach no more
/// than 64 windows from t = 0, and at least one gate or window must be able to receive light of the
/// window (a sensor that can measure nothing is a mistake). Throws tprf::Error naming the block's file
/// and JSON path. The functions below assume a checked block.
void check_sensor(const SensorSettings& sensor, const TimeAxis& time);

/// Measurements per pixel and channel, K: one per gate, window or phase; T for a SPAD histogram.
int measurement_count(const SensorSettings& sensor, const TimeAxis& time);

/// A distribution in time as point masses mass[q] at offset (first + q) * step (time unit), summing
/// to 1. Built so that its mean is the shape's mean exactly.
struct TimeKernel {
    double step = 0.0;
    int first = 0;
    std::vector<double> mass;
};

/// The pulse as a kernel fine enough for bins of `bin_width` (step at most 1/16 of a bin and of the
/// pulse's own width).
TimeKernel pulse_kernel(const SensorPulse& pulse, double bin_width);

/// The sensor's linear part: measurement k = sum over i in [first[k], first[k] + weight[k].size())
/// of weight[k][i - first[k]] * e_i. For a SPAD, the weights give the expected signal per histogram
/// bin (before photons and dark counts).
struct SensorWeights {
    std::vector<int> first;
    std::vector<std::vector<double>> weight;
};

/// The weights of every measurement over the render's bins.
SensorWeights sensor_weights(const SensorSettings& sensor, const TimeAxis& time);

/// A time profile convolved with the pulse, per bin of the render's axis extended on both sides
/// so that nothing is cut: energy[m] arrives in bin first_bin + m (first_bin may be negative).
struct ConvolvedProfile {
    int first_bin = 0;
    std::vector<double> energy;
};

/// Convolves one profile (T values) with the pulse.
ConvolvedProfile convolve_with_pulse(const SensorPulse& pulse, const TimeAxis& time, const float* profile);

/// Options of apply_sensor.
struct SensorOptions {
    int threads = 0;                   ///< 0: all cores; results are identical for any count
};

/// Applies the sensor to a cube (H, W, T, 3): writes `measurements` (H, W, K, 3) and, for amcw,
/// `depth` (H, W), metres (may be null otherwise). Noise and photon counts are drawn per pixel from
/// the seed, so that the result does not depend on the thread count.
void apply_sensor(const SensorSettings& sensor, const TimeAxis& time, const float* cube, int height, int width,
                  float* measurements, float* depth, const SensorOptions& options = {});

/// The depth a CW-ToF camera infers from one pixel's phase measurements (channels summed): the phase
/// of the fitted M(phi) = a + b cos(phi) + c sin(phi), as distance c * phase / (4 pi f) (emitter
/// beside the camera), in [0, c / (2 f)); 0 when the measurements carry no modulation.
double amcw_depth(const SensorSettings& sensor, const float* measurements /* K x 3 */);

/// A PNG for one pixel, like the paper's figures 5 to 7: its TPRF, the TPRF convolved with the
/// pulse, and its measurements (channel mean).
void write_sensor_plot(const std::filesystem::path& path, const SensorSettings& sensor, const TimeAxis& time,
                       const float* profile /* T x 3 */, const float* measurements /* K x 3 */, int x, int y);

/// The name of an exposure type as the scene file writes it ("gates", "amcw", ...).
const char* exposure_name(ExposureType type);

}  // namespace tprf
