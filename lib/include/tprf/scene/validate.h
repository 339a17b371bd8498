#pragma once
/// Checks of a Scene however it was built (a JSON file today; Mitsuba XML and Python next), with the
/// messages the JSON parser gives: "FILE: JSON.PATH: what is wrong", thrown as tprf::Error.

#include "tprf/core/time_axis.h"
#include "tprf/scene/scene.h"
#include "tprf/scene/sensor_settings.h"

namespace tprf {

/// Checks a sensor block against a render's time axis: the pulse (and a SPAD's jitter) must reach no
/// more than 64 windows from t = 0, and at least one gate or window must be able to receive light of
/// the window (a sensor that can measure nothing is a mistake). Throws tprf::Error naming the block's
/// file and JSON path. The sensor model assumes a checked block.
void validate_sensor(const SensorSettings& sensor, const TimeAxis& time);

}  // namespace tprf
