#pragma once
// Mesh files written by a test into a folder of its own, and loading them back: shared by the mesh
// loading and mesh format tests.

#include "tprf/core/error.h"
#include "tprf/scene/mesh_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

namespace tprf::test {

/// Each test writes its files into a directory of its own, so that tests may run in parallel.
class MeshFiles : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        m_dir = std::filesystem::temp_directory_path() /
                ("tprf_mesh_test_" + std::string(info->test_suite_name()) + "_" + std::string(info->name()) + "_" +
                 std::to_string(::getpid()));
        std::filesystem::create_directories(m_dir);
    }
    void TearDown() override { std::filesystem::remove_all(m_dir); }

    /// Writes `bytes` to the file `name` in the test's folder.
    std::filesystem::path write(const std::string& name, const std::string& bytes) const {
        const std::filesystem::path file = m_dir / name;
        std::ofstream(file, std::ios::binary) << bytes;
        return file;
    }

    /// Writes and loads a mesh file, untransformed.
    PolygonMesh load(const std::string& name, const std::string& bytes) const {
        return load_mesh(write(name, bytes), Eigen::Matrix4d::Identity(), "scene.json", "objects[0].file");
    }

    std::filesystem::path m_dir;
};

/// Expects load_mesh(file) to throw tprf::Error naming the scene file, the JSON path and the mesh file,
/// with `needle` in its message.
inline void expect_input_error(const std::filesystem::path& file, const std::string& needle) {
    try {
        load_mesh(file, Eigen::Matrix4d::Identity(), "scene.json", "objects[4].file");
        ADD_FAILURE() << "no error for " << file;
    } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("scene.json: objects[4].file: mesh file '" + file.string() + "'"), std::string::npos)
            << what;
        EXPECT_NE(what.find(needle), std::string::npos) << what;
    }
}

}  // namespace tprf::test
