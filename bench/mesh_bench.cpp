// Loading mesh files (issue 19): a 1M-triangle height field written once per format into a temporary
// folder, then load_mesh timed on each (the file read from the page cache: what a second render of the
// same scene sees). Reports triangles per second and the peak memory of the load over what was held
// before it.
#include "bench_util.h"

#include "tprf/scene/mesh_io.h"

#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;

constexpr int kSide = 707;  // quads per side: 2 * 707^2 = 999,698 triangles, 708^2 = 501,264 vertices

struct HeightField {
    std::vector<std::array<float, 3>> vertices;
    std::vector<std::array<std::uint32_t, 3>> triangles;
};

// A wavy unit square: no two triangles coplanar by accident, as in a scan.
const HeightField& height_field() {
    static const HeightField field = [] {
        HeightField f;
        const int n = kSide + 1;
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const float x = float(i) / kSide, y = float(j) / kSide;
                f.vertices.push_back({x, y, 0.05f * std::sin(12.0f * x) * std::cos(9.0f * y)});
            }
        for (int j = 0; j < kSide; ++j)
            for (int i = 0; i < kSide; ++i) {
                const std::uint32_t a = std::uint32_t(j * n + i), b = a + 1, c = a + std::uint32_t(n), d = c + 1;
                f.triangles.push_back({a, b, d});
                f.triangles.push_back({a, d, c});
            }
        return f;
    }();
    return field;
}

fs::path folder() {
    static const fs::path dir = [] {
        const fs::path d = fs::temp_directory_path() / ("tprf_mesh_bench_" + std::to_string(::getpid()));
        fs::create_directories(d);
        return d;
    }();
    return dir;
}

template <class T>
void put(std::string& out, T value) {
    out.append(reinterpret_cast<const char*>(&value), sizeof value);  // little-endian machines only
}

std::string text_obj(const HeightField& f) {
    std::string s;
    char line[96];
    for (const auto& v : f.vertices) s.append(line, std::size_t(std::snprintf(line, sizeof line, "v %.7g %.7g %.7g\n", v[0], v[1], v[2])));
    for (const auto& t : f.triangles)
        s.append(line, std::size_t(std::snprintf(line, sizeof line, "f %u %u %u\n", t[0] + 1, t[1] + 1, t[2] + 1)));
    return s;
}

std::string text_off(const HeightField& f) {
    std::string s = "OFF\n" + std::to_string(f.vertices.size()) + " " + std::to_string(f.triangles.size()) + " 0\n";
    char line[96];
    for (const auto& v : f.vertices) s.append(line, std::size_t(std::snprintf(line, sizeof line, "%.7g %.7g %.7g\n", v[0], v[1], v[2])));
    for (const auto& t : f.triangles)
        s.append(line, std::size_t(std::snprintf(line, sizeof line, "3 %u %u %u\n", t[0], t[1], t[2])));
    return s;
}

std::string binary_ply(const HeightField& f) {
    std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(f.vertices.size()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                    std::to_string(f.triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
    for (const auto& v : f.vertices)
        for (float c : v) put(s, c);
    for (const auto& t : f.triangles) {
        put(s, std::uint8_t(3));
        for (std::uint32_t i : t) put(s, std::int32_t(i));
    }
    return s;
}

std::string binary_stl(const HeightField& f) {
    std::string s(80, ' ');
    put(s, std::uint32_t(f.triangles.size()));
    for (const auto& t : f.triangles) {
        for (int k = 0; k < 3; ++k) put(s, 0.0f);  // the normal, which readers recompute
        for (std::uint32_t i : t)
            for (float c : f.vertices[i]) put(s, c);
        put(s, std::uint16_t(0));
    }
    return s;
}

fs::path written(const std::string& name, std::string (*make)(const HeightField&)) {
    const fs::path file = folder() / name;
    if (!fs::exists(file)) std::ofstream(file, std::ios::binary) << make(height_field());
    return file;
}

void load(benchmark::State& state, const fs::path& file) {
    const double before = tprf::bench::start_peak();
    std::size_t triangles = 0;
    for (auto _ : state) {
        const tprf::PolygonMesh mesh = tprf::load_mesh(file, Eigen::Matrix4d::Identity(), "bench", "mesh");
        triangles = mesh.faces();
        benchmark::DoNotOptimize(mesh.vertices.data());
    }
    state.counters["triangles"] = double(triangles);
    state.counters["file_MB"] = double(fs::file_size(file)) / 1e6;
    const double peak = tprf::bench::proc_status_bytes("VmHWM") - before;
    state.counters["peak_MB"] = peak / 1e6;
    state.counters["bytes_per_face"] = peak / double(triangles);
    state.counters["triangles_per_s"] =
        benchmark::Counter(double(triangles), benchmark::Counter::kIsIterationInvariantRate);
    state.counters["seconds_per_face"] = benchmark::Counter(
        double(triangles), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_LoadBinaryPly(benchmark::State& state) { load(state, written("field.ply", binary_ply)); }
void BM_LoadAsciiObj(benchmark::State& state) { load(state, written("field.obj", text_obj)); }
void BM_LoadAsciiOff(benchmark::State& state) { load(state, written("field.off", text_off)); }
void BM_LoadBinaryStl(benchmark::State& state) { load(state, written("field.stl", binary_stl)); }
BENCHMARK(BM_LoadBinaryPly)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_LoadAsciiObj)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_LoadAsciiOff)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_LoadBinaryStl)->Unit(benchmark::kMillisecond)->MinTime(2.0);

// The folder goes with the process.
struct RemoveFolder {
    ~RemoveFolder() {
        std::error_code ec;
        fs::remove_all(fs::temp_directory_path() / ("tprf_mesh_bench_" + std::to_string(::getpid())), ec);
    }
} remove_folder;

}  // namespace
