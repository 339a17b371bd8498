#pragma once
/// A sensor block as plain data (SPEC.md, "Sensor block"): what the TPRF sensor model of
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

/// The name of an exposure type as the scene file writes it ("gates", "amcw", ...).
const char* exposure_name(ExposureType type);

/// The 3 x 3 normal matrix of the least-squares fit M(phi) = a + b cos(phi) + c sin(phi) over the AMCW
/// phases (degrees): singular when the phases cannot determine a phase (fewer than 3 distinct).
Eigen::Matrix3d phase_normal_matrix(const std::vector<double>& phases_deg);

/// The pulse as a kernel fine enough for bins of `bin_width` (step at most 1/16 of a bin and of the
/// pulse's own width).
TimeKernel pulse_kernel(const SensorPulse& pulse, double bin_width);

}  // namespace tprf
