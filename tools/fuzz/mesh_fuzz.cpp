// libFuzzer target: the mesh loader (tprf::load_mesh) on arbitrary bytes. The first byte chooses the
// format (.obj, .off, .ply, .stl), the rest is the file. Bad input must end in tprf::Error; anything
// else escaping (InternalError, bad_alloc, a crash, a sanitizer report) is a finding, and a mesh that
// loads must keep load_mesh's promises.
#include "tprf/core/error.h"
#include "tprf/scene/mesh_io.h"

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;

// One folder per process, in memory where the machine has /dev/shm.
const fs::path& folder() {
    static const fs::path dir = [] {
        const fs::path base = fs::is_directory("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
        fs::path d = base / ("tprf_fuzz_mesh_" + std::to_string(::getpid()));
        fs::create_directories(d);
        return d;
    }();
    // libFuzzer ends a run with exit(); without this every run leaves a folder in /dev/shm (memory).
    [[maybe_unused]] static const int removed_at_exit = std::atexit([] {
        std::error_code ignored;
        fs::remove_all(dir, ignored);
    });
    return dir;
}

void check_promises(const tprf::PolygonMesh& mesh) {
    if (mesh.faces() == 0 || mesh.first.front() != 0 || mesh.first.back() != mesh.indices.size()) __builtin_trap();
    for (int v : mesh.indices)
        if (v < 0 || static_cast<std::size_t>(v) >= mesh.vertices.size()) __builtin_trap();
    for (const tprf::Vec3& p : mesh.vertices)
        if (!p.allFinite()) __builtin_trap();
    if (mesh.repairs.unreferenced_vertices + mesh.vertices.size() != mesh.file_vertices) __builtin_trap();
    if (mesh.repairs.dropped_faces() + mesh.faces() != mesh.file_faces) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    static const std::array<const char*, 4> kExtensions{".obj", ".off", ".ply", ".stl"};
    const fs::path file = folder() / (std::string("mesh") + kExtensions[data[0] % kExtensions.size()]);
    {
        std::ofstream out(file, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
    }
    try {
        check_promises(tprf::load_mesh(file, Eigen::Matrix4d::Identity(), "fuzz.json", "objects[0].file"));
    } catch (const tprf::Error&) {
        // Bad input, reported as the user sees it: what the target expects.
    }
    return 0;
}
