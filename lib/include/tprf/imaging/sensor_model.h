#pragma once
/// The TPRF sensor model (transient rendering paper, section 6; docs/scene.md, "Sensor"):
///
///     M_k = max(0, noise + integral of (TPRF * pulse)(t) exposure_k(t) dt)
///
/// The cube's bin i holds the energy e_i that arrives in [t_i, t_i + bin_width), taken as spread
/// evenly over the bin. Everything before the noise is linear in e, so each measurement is a weighted
/// sum M_k = sum_i w_k[i] e_i whose weights fold the pulse (and a SPAD's timing jitter) into the
/// exposure once per render, not once per pixel. All times are in the scene's time unit.

#include "tprf/core/time_axis.h"
#include "tprf/core/time_kernel.h"
#include "tprf/scene/sensor_settings.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tprf {

/// Measurements per pixel and channel, K: one per gate, window or phase; T for a SPAD histogram.
int measurement_count(const SensorSettings& sensor, const TimeAxis& time);

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

/// A transient cube as the sensor model reads it: `data` is (height, width, T, 3), T the bins of `time`.
struct CubeView {
    const TimeAxis& time;
    const float* data = nullptr;
    int height = 0;
    int width = 0;
};

/// Applies the sensor to a cube: writes `measurements` (H, W, K, 3) and, for amcw, `depth` (H, W),
/// metres, and `raw` (H, W, F, P): the camera's raw correlation samples, F frequencies by P phases
/// (docs/sensor.md, "AMCW"); each may be null. Noise and photon counts are drawn per pixel from the
/// seed, so that the result does not depend on the thread count. A SPAD's dead pixel outside the image
/// is an Error (its JSON path and the image's size), raised before anything is written.
void apply_sensor(const SensorSettings& sensor, const CubeView& cube, float* measurements, float* depth,
                  const SensorOptions& options = {}, float* raw = nullptr);

/// A SPAD pixel's expected counts per bin and channel (K x 3, bin by bin), the means that apply_sensor
/// draws its Poisson counts from: photons x signal, dark and ambient counts, crosstalk from the 4-neighbours,
/// dead time and afterpulses (docs/sensor.md, "SPAD"); all 0 for a dead pixel. (row, column) is the
/// pixel. A dead pixel outside the image is an Error, as in apply_sensor.
std::vector<double> spad_expected_counts(const SensorSettings& sensor, const CubeView& cube, int row, int column);

/// The depth a CW-ToF camera infers from one pixel's raw samples (F frequencies x P phases, frequency
/// by frequency): at each frequency f the phase theta_f of the fitted M(phi) = a + b cos(phi) + c sin(phi),
/// the distance c theta_f / (4 pi f) (emitter beside the camera), in [0, c / (2 f)). One frequency: that
/// distance (it wraps). Several: the distance up to `max_distance` (metres; at least the longest
/// frequency's wrap) whose phases agree best with all of them (wrapped phase errors, squared and
/// summed), refined as the mean of each frequency's unwrapped distance weighted by f^2. 0 when no
/// frequency carries any modulation.
double amcw_depth(const SensorSettings& sensor, const double* raw, double max_distance);

/// What sensor_plot.png shows for one pixel, like the paper's figures 5 to 7 (channel means): its TPRF,
/// the TPRF convolved with the pulse, and its measurements. Times in the scene's time unit.
struct SensorPlot {
    int x = 0, y = 0;                       ///< the pixel: column, row
    std::string exposure;                   ///< gates, windows, amcw or spad
    std::string time_unit;                  ///< m or ps
    double start = 0.0, end = 0.0;          ///< the render's time window
    std::vector<double> tprf_edges;         ///< T + 1 bin edges
    std::vector<double> tprf;               ///< T: the TPRF as energy per unit time (radiance s per time unit)
    std::vector<double> convolved_time;     ///< bin centres of the TPRF convolved with the pulse (beyond the
                                            ///< window where the pulse reaches)
    std::vector<double> convolved;          ///< its energy per unit time, as tprf
    std::vector<double> measurement_at;     ///< K: a gate's or window's centre, a phase (degrees), a SPAD bin's start
    std::vector<double> measurements;       ///< K: the measurements (for a SPAD, photon counts per bin)
};

/// The data of sensor_plot.png for pixel (x, y): its profile (T x 3) and its measurements (K x 3).
SensorPlot sensor_plot(const SensorSettings& sensor, const TimeAxis& time, const float* profile /* T x 3 */,
                       const float* measurements /* K x 3 */, int x, int y);

}  // namespace tprf
