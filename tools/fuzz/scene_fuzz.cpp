// libFuzzer target: scene JSON through the parser and validate() (parse_scene), then, for a scene that
// is accepted, the resource estimate that `tprf info` and every render run first (it loads the meshes
// and counts the patches without building them). Only tprf::Error may come out; InternalError,
// bad_alloc, a crash or a sanitizer report is a finding.
#include "tprf/core/error.h"
#include "tprf/pipeline/info.h"
#include "tprf/scene/parse_json.h"

#include <cstddef>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        // Beside the sample meshes, so that seeds naming them ("block.obj") find them.
        const tprf::Scene scene = tprf::parse_scene(text, TPRF_SOURCE_DIR "/meshes/fuzz.json");
        tprf::PipelineOptions options;
        options.threads = 1;
        const tprf::ResourceEstimate e = tprf::estimate_resources(scene, options);
        if (e.patches > 0 && !(e.peak_bytes > 0)) __builtin_trap();
    } catch (const tprf::Error&) {
        // Bad input, reported as the user sees it.
    }
    return 0;
}
