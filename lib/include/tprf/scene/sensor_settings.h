#pragma once
/// A sensor block as plain data (docs/scene.md, "Sensor"): what the TPRF sensor model of
/// imaging/sensor_model.h applies. Parsed by scene/parse_json.h, checked by scene/validate.h.

#include "tprf/core/time_kernel.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tprf {

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

/// `sensor.exposure.jitter_tail`: the exponential diffusion tail of a SPAD's timing response. The
/// jitter kernel becomes (1 - fraction) G + fraction (G * E), G the Gaussian of `jitter_fwhm` and E the
/// exponential of `time_constant` that starts at 0: unit area, mean delay fraction * time_constant.
struct JitterTail {
    double time_constant = 0.0;        ///< 1/e time of the tail, time unit; > 0 where fraction > 0
    double fraction = 0.0;             ///< share of the counts in the tail, [0, 1]; 0: no tail
};

/// `sensor.exposure.afterpulsing`: each detection adds `probability` expected counts, delayed by the
/// dead time plus an exponential delay of `time_constant`.
struct Afterpulsing {
    double probability = 0.0;          ///< expected afterpulses per detection, [0, 1]; 0: none
    double time_constant = 0.0;        ///< 1/e delay after the dead time, time unit; > 0 where probability > 0
};

/// `sensor.exposure`.
struct Exposure {
    ExposureType type = ExposureType::Gates;
    /// gates and windows: one [start, width] per measurement, time unit (gates are expanded here).
    std::vector<std::array<double, 2>> windows;
    double frequency_mhz = 0.0;        ///< amcw `frequency_mhz`: one modulation frequency, MHz, > 0; 0 with `frequencies`
    std::vector<double> phases_deg;    ///< amcw: the phases measured at each frequency, degrees; >= 3 distinct
    double photons = 1.0;              ///< spad: expected photons per unit of signal, > 0
    double jitter_fwhm = 0.0;          ///< spad: gaussian timing jitter, time unit, >= 0
    double dark_rate = 0.0;            ///< spad: dark counts per second of bin time, >= 0
    std::uint64_t seed = 0;            ///< spad: seed of the photon counts (and of the dead pixels' choice); amcw: of the shot noise
    // The SPAD's detector effects (docs/sensor.md, "SPAD"); every default leaves the counts Poisson.
    JitterTail jitter_tail{};          ///< spad: none by default
    double dead_time = 0.0;            ///< spad: blind time after a detection, time unit, >= 0; 0: none
    double cycles = 1e7;               ///< spad: laser repetitions over the acquisition, [1, 1e15]
    Afterpulsing afterpulsing{};       ///< spad: none by default
    double ambient = 0.0;              ///< spad: ambient counts per second on the pixel, [0, 1e30]
    double crosstalk = 0.0;            ///< spad: probability that a detection fires each 4-neighbour, [0, 1]
    double dead_fraction = 0.0;        ///< spad: share of the pixels that count nothing, chosen from `seed`, [0, 1]
    std::vector<std::array<int, 2>> dead_pixels{};  ///< spad: [row, column] of pixels that count nothing, >= 0
    // The AMCW camera's frequencies and raw samples (docs/sensor.md, "AMCW").
    std::vector<double> frequencies_hz{};  ///< amcw `frequencies`: measured in turn, Hz, > 0; empty: frequency_mhz
    double amcw_photons = 0.0;         ///< amcw `photons`: photo-electrons per unit of signal; 0: no shot noise
    double amcw_ambient = 0.0;         ///< amcw `ambient`: electrons of ambient light per raw sample, >= 0 (with photons)
    int adc_bits = 0;                  ///< amcw: raw samples quantised to this many bits, [1, 24]; 0: not quantised

    /// amcw: the modulation frequencies in Hz, in the order measured (from either key).
    std::vector<double> amcw_frequencies_hz() const {
        return frequencies_hz.empty() ? std::vector<double>{frequency_mhz * 1e6} : frequencies_hz;
    }
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

/// The name of an exposure type as the scene file writes it ("gates", "amcw", ...).
const char* exposure_name(ExposureType type);

/// The 3 x 3 normal matrix of the least-squares fit M(phi) = a + b cos(phi) + c sin(phi) over the AMCW
/// phases (degrees): singular when the phases cannot determine a phase (fewer than 3 distinct).
Eigen::Matrix3d phase_normal_matrix(const std::vector<double>& phases_deg);

/// The pulse as a kernel fine enough for bins of `bin_width` (step at most 1/16 of a bin and of the
/// pulse's own width).
TimeKernel pulse_kernel(const SensorPulse& pulse, double bin_width);

/// An exponential tail is cut at this many time constants; the mass beyond (e^-20, 2e-9, as a Gaussian's
/// beyond 6 sigma) is put at its own mean, so that the kernel keeps unit area and the mean exactly.
inline constexpr double kTailReach = 20.0;

/// The exponential distribution of 1/e time `time_constant` (> 0), starting at 0, as a kernel fine enough
/// for bins of `bin_width`: unit area, mean `time_constant`.
TimeKernel exponential_kernel(double time_constant, double bin_width);

/// A SPAD's timing jitter: the Gaussian of `jitter_fwhm` (a delta for 0) mixed with its exponential tail
/// (`jitter_tail`). Unit area; mean jitter_tail.fraction * jitter_tail.time_constant.
TimeKernel jitter_kernel(const Exposure& exposure, double bin_width);

/// How far a SPAD's jitter reaches from t = 0: 6 sigma of the Gaussian plus the tail's cut and its
/// remainder's place (time unit).
double jitter_reach(const Exposure& exposure);

}  // namespace tprf
