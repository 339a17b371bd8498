// libFuzzer target: a sensor block (docs/scene.md, "Sensor") through its parser and its checks on
// their own (parse_sensor_block), then against a time axis. Only tprf::Error may come out.
#include "tprf/core/error.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/validate.h"

#include <cstddef>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const tprf::SensorSettings sensor = tprf::parse_sensor_block(text, TPRF_SOURCE_DIR "/meshes/fuzz.json");
        tprf::TimeAxis time;
        time.bins = 1024;
        time.bin_width = 0.005;
        tprf::validate_sensor(sensor, time);
    } catch (const tprf::Error&) {
        // Bad input, reported as the user sees it.
    }
    return 0;
}
