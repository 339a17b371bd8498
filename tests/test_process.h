#pragma once
// Running the `tprf` command (or any command line) from a test, and reading files back whole: shared by
// the command-line and end-to-end tests.

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

namespace tprf::test {

/// A command's exit status (-1 when it did not exit normally) and what it wrote to stderr.
struct Outcome {
    int status = -1;
    std::string err;
};

/// A file's bytes ("" when it cannot be read).
inline std::string read_bytes(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Runs a shell command line with its stderr captured (its stdout goes wherever the line sends it).
inline Outcome shell(const std::string& command) {
    const std::filesystem::path err =
        std::filesystem::temp_directory_path() / ("tprf_test_err_" + std::to_string(std::random_device{}()));
    const int raw = std::system((command + " 2>" + err.string()).c_str());
    Outcome r;
    r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
    r.err = read_bytes(err);
    std::filesystem::remove(err);
    return r;
}

/// Runs `tprf ARGS -q` with stdout discarded.
inline Outcome run_tprf(const std::string& args) {
    return shell(std::string(TPRF_BINARY) + " " + args + " -q >/dev/null");
}

}  // namespace tprf::test
