// The tprf command line: parse arguments, call one library entry point, print. No physics here.
#include "tprf/error.h"
#include "tprf/scene.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <string>

int main(int argc, char** argv) {
    CLI::App app{"tprf: transient radiosity, light in flight"};
    app.require_subcommand(1);
    std::string scene_file;
    auto* info = app.add_subcommand("info", "print patch count, link count, link memory and the time window");
    info->add_option("scene", scene_file, "scene JSON file")->required();
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int rc = app.exit(e);
        return rc == 0 ? 0 : 2;
    }
    try {
        const tprf::Scene scene = tprf::load_scene(scene_file);
        std::printf("bins %d\n", scene.time.bins);
        return 0;
    } catch (const tprf::Error& e) {
        std::fprintf(stderr, "tprf: error: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "tprf: internal error: %s\n", e.what());
        return 1;
    }
}
