#include "tprf/core/error.h"
#include "tprf/io/hdf5_capture.h"

#include <gtest/gtest.h>
#include <H5Cpp.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>
#include <utility>
#include <vector>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using tprf::CaptureFile;
using tprf::CaptureGridData;
using tprf::Vec3;

// tal's NLOSCaptureData fields, all 15 of them: its reader rejects any other top-level key.
const std::set<std::string> kTalKeys = {"H",
                                        "H_format",
                                        "sensor_xyz",
                                        "sensor_grid_xyz",
                                        "sensor_grid_normals",
                                        "sensor_grid_format",
                                        "laser_xyz",
                                        "laser_grid_xyz",
                                        "laser_grid_normals",
                                        "laser_grid_format",
                                        "volume_format",
                                        "delta_t",
                                        "t_start",
                                        "t_accounts_first_and_last_bounces",
                                        "scene_info"};
using Members = std::vector<std::pair<std::string, std::int64_t>>;
const Members kHFormat = {{"UNKNOWN", 0}, {"T_Sx_Sy", 1}, {"T_Lx_Ly_Sx_Sy", 2}, {"T_Si", 3}, {"T_Li_Si", 4},
                          {"F_Sx_Sy", 10}, {"F_Lx_Ly_Sx_Sy", 11}, {"F_Si", 12}, {"F_Li_Si", 13}};
const Members kGridFormat = {{"UNKNOWN", 0}, {"N_3", 1}, {"X_Y_3", 2}};
const Members kVolumeFormat = {{"UNKNOWN", 0}, {"N_3", 1}, {"X_Y_Z_3", 2}, {"X_Y_3", 3}};

// A directory of the test's own, so that tests may run in parallel.
class TempDir {
public:
    TempDir() {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        m_path = fs::temp_directory_path() /
                 ("tprf_hdf5_test_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
        fs::remove_all(m_path);
        fs::create_directories(m_path);
    }
    ~TempDir() { fs::remove_all(m_path); }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    const fs::path& path() const { return m_path; }

private:
    fs::path m_path;
};

// Grid point (a, b) at a * nv + b, each coordinate distinct per grid, point and axis.
CaptureGridData make_grid(int nu, int nv, double offset) {
    CaptureGridData grid;
    grid.nu = nu;
    grid.nv = nv;
    for (int a = 0; a < nu; ++a)
        for (int b = 0; b < nv; ++b) {
            grid.xyz.push_back(Vec3(offset + a, offset + 0.25 * b, offset + 0.5));
            grid.normals.push_back(Vec3(0.0, 0.125 * a, 1.0 + 0.0625 * b));
        }
    return grid;
}

// H[i] = i + 0.5: distinct and exact in float32 for these sizes.
std::vector<float> ramp(std::size_t n) {
    std::vector<float> values(n);
    for (std::size_t i = 0; i < n; ++i) values[i] = static_cast<float>(i) + 0.5f;
    return values;
}

std::vector<hsize_t> dims_of(const H5::DataSet& ds) {
    const H5::DataSpace space = ds.getSpace();
    std::vector<hsize_t> dims(static_cast<std::size_t>(space.getSimpleExtentNdims()));
    space.getSimpleExtentDims(dims.data());
    return dims;
}

std::set<std::string> root_names(const H5::H5File& file) {
    std::set<std::string> names;
    for (hsize_t i = 0; i < file.getNumObjs(); ++i) {
        EXPECT_EQ(file.getObjTypeByIdx(i), H5G_DATASET) << file.getObjnameByIdx(i);
        names.insert(file.getObjnameByIdx(i));
    }
    return names;
}

// A float32 dataset's values, after checking its class, width and shape.
std::vector<float> read_floats(const H5::H5File& file, const std::string& name, const std::vector<hsize_t>& dims) {
    const H5::DataSet ds = file.openDataSet(name);
    EXPECT_EQ(ds.getTypeClass(), H5T_FLOAT) << name;
    EXPECT_EQ(ds.getFloatType().getSize(), 4u) << name;
    EXPECT_EQ(dims_of(ds), dims) << name;
    std::size_t n = 1;
    for (const hsize_t d : dims) n *= d;
    std::vector<float> values(n);
    ds.read(values.data(), H5::PredType::NATIVE_FLOAT);
    return values;
}

double read_scalar_double(const H5::H5File& file, const std::string& name) {
    const H5::DataSet ds = file.openDataSet(name);
    EXPECT_EQ(ds.getTypeClass(), H5T_FLOAT) << name;
    EXPECT_EQ(ds.getFloatType().getSize(), 8u) << name;
    EXPECT_EQ(dims_of(ds), std::vector<hsize_t>{}) << name;
    double value = 0.0;
    ds.read(&value, H5::PredType::NATIVE_DOUBLE);
    return value;
}

// An enum dataset: its base type, its members (names and values, in order) and its one value.
std::int64_t read_enum(const H5::H5File& file, const std::string& name, const H5::PredType& base,
                       const Members& members, const std::vector<hsize_t>& dims) {
    const H5::DataSet ds = file.openDataSet(name);
    EXPECT_EQ(ds.getTypeClass(), H5T_ENUM) << name;
    EXPECT_EQ(dims_of(ds), dims) << name;
    const H5::EnumType type = ds.getEnumType();
    EXPECT_TRUE(type.getSuper() == base) << name;
    Members found;
    for (int i = 0; i < type.getNmembers(); ++i) {
        std::int64_t value = 0;  // the base's width, little-endian: the low bytes of an int64
        type.getMemberValue(static_cast<unsigned>(i), &value);
        const std::string member = type.nameOf(&value, 64);
        found.emplace_back(member, base.getSize() == 1 ? static_cast<std::int8_t>(value) : value);
    }
    EXPECT_EQ(found, members) << name;
    std::int64_t value = 0;
    ds.read(&value, type);
    return base.getSize() == 1 ? static_cast<std::int8_t>(value) : static_cast<std::int32_t>(value);
}

std::string read_text(const H5::H5File& file, const std::string& name) {
    const H5::DataSet ds = file.openDataSet(name);
    EXPECT_EQ(ds.getTypeClass(), H5T_STRING) << name;
    EXPECT_EQ(dims_of(ds), std::vector<hsize_t>{}) << name;
    const H5::StrType type = ds.getStrType();
    EXPECT_TRUE(type.isVariableStr()) << name;
    EXPECT_EQ(type.getCset(), H5T_CSET_UTF8) << name;
    std::string value;
    ds.read(value, type);
    return value;
}

// The grid as written: float32 (nu, nv, 3), point (a, b) at a * nv + b.
void expect_grid(const H5::H5File& file, const std::string& prefix, const CaptureGridData& grid) {
    const std::vector<hsize_t> dims = {hsize_t(grid.nu), hsize_t(grid.nv), 3};
    const auto xyz = read_floats(file, prefix + "_grid_xyz", dims);
    const auto normals = read_floats(file, prefix + "_grid_normals", dims);
    for (int a = 0; a < grid.nu; ++a)
        for (int b = 0; b < grid.nv; ++b)
            for (int k = 0; k < 3; ++k) {
                const std::size_t i = static_cast<std::size_t>(a * grid.nv + b);
                EXPECT_EQ(xyz[i * 3 + std::size_t(k)], static_cast<float>(grid.xyz[i][k])) << prefix;
                EXPECT_EQ(normals[i * 3 + std::size_t(k)], static_cast<float>(grid.normals[i][k])) << prefix;
            }
    EXPECT_EQ(read_enum(file, prefix + "_grid_format", H5::PredType::NATIVE_INT32, kGridFormat, {1}), 2);
}

// Everything but H and H_format, which depend on the layout.
void expect_common(const H5::H5File& file, const CaptureFile& capture) {
    EXPECT_EQ(root_names(file), kTalKeys);
    expect_grid(file, "sensor", capture.sensor_grid);
    expect_grid(file, "laser", capture.laser_grid);
    const auto sensor = read_floats(file, "sensor_xyz", {3});
    const auto laser = read_floats(file, "laser_xyz", {3});
    for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(sensor[std::size_t(k)], static_cast<float>(capture.sensor_xyz[k]));
        EXPECT_EQ(laser[std::size_t(k)], static_cast<float>(capture.laser_xyz[k]));
    }
    EXPECT_EQ(read_enum(file, "volume_format", H5::PredType::NATIVE_INT32, kVolumeFormat, {1}), 0);
    EXPECT_EQ(read_scalar_double(file, "delta_t"), capture.delta_t);
    EXPECT_EQ(read_scalar_double(file, "t_start"), capture.t_start);
    EXPECT_EQ(read_enum(file, "t_accounts_first_and_last_bounces", H5::PredType::NATIVE_INT8,
                        {{"FALSE", 0}, {"TRUE", 1}}, {}),
              capture.t_accounts_first_and_last_bounces ? 1 : 0);
    EXPECT_EQ(read_text(file, "scene_info"), capture.scene_info);
}

CaptureFile make_capture(bool confocal, std::vector<std::size_t> shape, const std::vector<float>& h) {
    CaptureFile capture;
    capture.confocal = confocal;
    capture.shape = std::move(shape);
    capture.H = h.data();
    capture.sensor_xyz = Vec3(-0.5, 0.25, 1.5);
    capture.laser_xyz = Vec3(0.75, -0.125, 1.25);
    capture.delta_t = 0.0012345678901;  // a double that float32 would round
    capture.t_start = 1.5e-3;
    capture.scene_info = "tprf_version: 0.1.0\nscene: {file: \"m\u00e9sh.json\", bins: 5}\n";
    return capture;
}

// A confocal capture of H `h` (T, nu, nv) over one grid.
CaptureFile confocal_capture(std::size_t T, std::size_t nu, std::size_t nv, const std::vector<float>& h) {
    CaptureFile capture = make_capture(true, {T, nu, nv}, h);
    capture.sensor_grid = make_grid(int(nu), int(nv), 10.0);
    capture.laser_grid = capture.sensor_grid;
    return capture;
}

TEST(Hdf5Capture, ConfocalRoundTripsEveryDataset) {
    const TempDir dir;
    const std::size_t T = 5, nu = 3, nv = 2;
    const auto h = ramp(T * nu * nv);
    CaptureFile capture = confocal_capture(T, nu, nv, h);
    capture.t_accounts_first_and_last_bounces = true;
    const fs::path path = dir.path() / "capture.hdf5";
    tprf::write_capture_hdf5(path, capture);

    const H5::H5File file(path.string(), H5F_ACC_RDONLY);
    expect_common(file, capture);
    EXPECT_EQ(read_enum(file, "H_format", H5::PredType::NATIVE_INT32, kHFormat, {1}), 1);
    const auto H = read_floats(file, "H", {T, nu, nv});
    for (std::size_t t = 0; t < T; ++t)
        for (std::size_t a = 0; a < nu; ++a)
            for (std::size_t b = 0; b < nv; ++b)
                EXPECT_EQ(H[(t * nu + a) * nv + b], h[(t * nu + a) * nv + b]) << t << " " << a << " " << b;
}

// A sensor's measurement of a capture: the same file with another H (tal reads both alike).
TEST(Hdf5Capture, ACopyWithANewHKeepsEveryOtherDataset) {
    const TempDir dir;
    const std::size_t T = 5, nu = 3, nv = 2;
    const auto h = ramp(T * nu * nv);
    const CaptureFile capture = confocal_capture(T, nu, nv, h);
    const fs::path from = dir.path() / "capture.hdf5", to = dir.path() / "noisy.hdf5";
    tprf::write_capture_hdf5(from, capture);
    std::vector<float> counts(h.size());
    for (std::size_t k = 0; k < counts.size(); ++k) counts[k] = float(7 * k % 11);
    tprf::copy_capture_with_h(from, to, counts.data(), {T, nu, nv});
    {
        const H5::H5File file(to.string(), H5F_ACC_RDONLY);
        expect_common(file, capture);
        EXPECT_EQ(read_floats(file, "H", {T, nu, nv}), counts);
        const H5::H5File original(from.string(), H5F_ACC_RDONLY);
        EXPECT_EQ(read_floats(original, "H", {T, nu, nv}), h);  // the render's own file is left alone
    }
    try {
        tprf::copy_capture_with_h(from, to, counts.data(), {T, nv, nu});
        FAIL() << "a shape other than the file's H was written";
    } catch (const tprf::Error& e) {
        EXPECT_NE(std::string(e.what()).find("does not have the shape"), std::string::npos) << e.what();
    }
}

TEST(Hdf5Capture, ExhaustiveRoundTripsEveryDataset) {
    const TempDir dir;
    const std::size_t T = 4, nul = 2, nvl = 1, nus = 2, nvs = 3;
    const auto h = ramp(T * nul * nvl * nus * nvs);
    CaptureFile capture = make_capture(false, {T, nul, nvl, nus, nvs}, h);
    capture.laser_grid = make_grid(int(nul), int(nvl), -3.0);
    capture.sensor_grid = make_grid(int(nus), int(nvs), 7.0);
    const fs::path path = dir.path() / "capture.hdf5";
    tprf::write_capture_hdf5(path, capture);

    const H5::H5File file(path.string(), H5F_ACC_RDONLY);
    expect_common(file, capture);
    EXPECT_EQ(read_enum(file, "H_format", H5::PredType::NATIVE_INT32, kHFormat, {1}), 2);
    const auto H = read_floats(file, "H", {T, nul, nvl, nus, nvs});
    for (std::size_t t = 0; t < T; ++t)
        for (std::size_t la = 0; la < nul; ++la)
            for (std::size_t lb = 0; lb < nvl; ++lb)
                for (std::size_t sa = 0; sa < nus; ++sa)
                    for (std::size_t sb = 0; sb < nvs; ++sb) {
                        const std::size_t i = (((t * nul + la) * nvl + lb) * nus + sa) * nvs + sb;
                        EXPECT_EQ(H[i], h[i]) << t << " " << la << " " << lb << " " << sa << " " << sb;
                    }
}

TEST(Hdf5Capture, MissingFolderIsAnErrorNamingTheFile) {
    const TempDir dir;
    const std::size_t T = 2;
    const auto h = ramp(T);
    CaptureFile capture = make_capture(true, {T, 1, 1}, h);
    capture.sensor_grid = make_grid(1, 1, 0.0);
    capture.laser_grid = capture.sensor_grid;
    const fs::path path = dir.path() / "no-such-folder" / "capture.hdf5";
    ::testing::internal::CaptureStderr();
    try {
        tprf::write_capture_hdf5(path, capture);
        ADD_FAILURE() << "no error";
    } catch (const tprf::OutputError& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind(path.string() + ": cannot create the file (", 0), 0u) << what;
        EXPECT_NE(what.find("No such file or directory"), std::string::npos) << what;
    }
    // HDF5's own error report is silenced: the message above is the only one.
    EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
    EXPECT_FALSE(fs::exists(path.parent_path()));
}

TEST(Hdf5Capture, FullDiskIsAnErrorNamingTheFile) {
    // An 8 MiB cube on a 1 MiB file system: HDF5 fails writing H (or at the latest when closing).
    const fs::path dir = fs::temp_directory_path() / ("tprf_hdf5_fulldisk_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const std::string mount = "mount -t tmpfs -o size=1M tmpfs " + dir.string() + " 2>/dev/null";
    if (std::system(mount.c_str()) != 0) {
        fs::remove(dir);
        GTEST_SKIP() << "cannot mount a small tmpfs here (needs root)";
    }
    const std::size_t T = 512, nu = 64, nv = 64;
    const auto h = ramp(T * nu * nv);
    CaptureFile capture = make_capture(true, {T, nu, nv}, h);
    capture.sensor_grid = make_grid(int(nu), int(nv), 0.0);
    capture.laser_grid = capture.sensor_grid;
    const fs::path path = dir / "capture.hdf5";
    ::testing::internal::CaptureStderr();
    try {
        tprf::write_capture_hdf5(path, capture);
        ADD_FAILURE() << "an 8 MiB capture on a 1 MiB file system was accepted";
    } catch (const tprf::OutputError& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind(path.string() + ": cannot ", 0), 0u) << what;
        EXPECT_NE(what.find("No space left on device"), std::string::npos) << what;
        EXPECT_EQ(what.find('\n'), std::string::npos) << what;  // one line
    }
    EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
    EXPECT_EQ(std::system(("umount " + dir.string()).c_str()), 0);
    fs::remove(dir);
}

TEST(Hdf5Capture, ShapeThatDisagreesWithTheGridIsABrokenInvariant) {
    const TempDir dir;
    const auto h = ramp(5 * 3 * 2);
    CaptureFile capture = make_capture(true, {5, 3, 2}, h);
    capture.sensor_grid = make_grid(2, 3, 0.0);  // transposed
    capture.laser_grid = capture.sensor_grid;
    const fs::path path = dir.path() / "capture.hdf5";
    EXPECT_THROW(tprf::write_capture_hdf5(path, capture), tprf::InternalError);
    capture.shape = {5, 3, 2, 1, 1};  // five axes, yet confocal
    EXPECT_THROW(tprf::write_capture_hdf5(path, capture), tprf::InternalError);
    EXPECT_FALSE(fs::exists(path));  // checked before the file is created
}

}  // namespace
