// libFuzzer target: Mitsuba 3 XML through parse_mitsuba_scene (the XML subset, $name parameters, then
// validate()). Only tprf::Error may come out; InternalError, bad_alloc, a crash or a sanitizer report
// is a finding.
#include "tprf/core/error.h"
#include "tprf/scene/parse_mitsuba.h"

#include <cstddef>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        // Beside the sample meshes, so that seeds naming them ("block.obj") find them. The define
        // gives `$fuzz` a value whatever the input's defaults say.
        const tprf::Scene scene =
            tprf::parse_mitsuba_scene(text, TPRF_SOURCE_DIR "/meshes/fuzz.xml", {{"fuzz", "1"}});
        if (scene.objects.empty()) __builtin_trap();  // validate() refuses a scene without objects
    } catch (const tprf::Error&) {
        // Bad input, reported as the user sees it.
    }
    return 0;
}
