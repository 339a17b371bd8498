#include "tprf/io/hdf5_capture.h"

#include "tprf/core/error.h"

#include <H5Cpp.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tprf {

namespace fs = std::filesystem;

namespace {

// tal's enums (tal/enums.py) with all their members: tal's write_hdf5 stores an Enum as an HDF5 enum
// type listing every member over a native int32 (h5py.enum_dtype(..., basetype='i')), and its reader
// turns the value back into the Python class.
using EnumMember = std::pair<const char*, std::int32_t>;
constexpr std::array<EnumMember, 9> kHFormat = {{{"UNKNOWN", 0},
                                                 {"T_Sx_Sy", 1},
                                                 {"T_Lx_Ly_Sx_Sy", 2},
                                                 {"T_Si", 3},
                                                 {"T_Li_Si", 4},
                                                 {"F_Sx_Sy", 10},
                                                 {"F_Lx_Ly_Sx_Sy", 11},
                                                 {"F_Si", 12},
                                                 {"F_Li_Si", 13}}};
constexpr std::array<EnumMember, 3> kGridFormat = {{{"UNKNOWN", 0}, {"N_3", 1}, {"X_Y_3", 2}}};
constexpr std::array<EnumMember, 4> kVolumeFormat = {{{"UNKNOWN", 0}, {"N_3", 1}, {"X_Y_Z_3", 2}, {"X_Y_3", 3}}};
// numpy.bool_ as h5py stores it.
constexpr std::array<EnumMember, 2> kNumpyBool = {{{"FALSE", 0}, {"TRUE", 1}}};
constexpr std::int32_t kHFormatConfocal = 1;    // T_Sx_Sy
constexpr std::int32_t kHFormatExhaustive = 2;  // T_Lx_Ly_Sx_Sy
constexpr std::int32_t kGridXY3 = 2;            // X_Y_3
constexpr std::int32_t kVolumeUnknown = 0;      // tprf reconstructs no volume

// HDF5 error-stack walker keeping the innermost entry: the cause ("unable to open file: name = ...,
// errno = 2, error message = 'No such file or directory'"), where the exception only names the call.
herr_t keep_innermost(unsigned n, const H5E_error2_t* entry, void* out) {
    if (n == 0 && entry->desc != nullptr) *static_cast<std::string*>(out) = entry->desc;
    return 0;
}

[[noreturn]] void fail_hdf5(const fs::path& path, std::string_view what, const H5::Exception& e) {
    std::string cause;
    try {
        H5::Exception::walkErrorStack(H5E_WALK_UPWARD, keep_innermost, &cause);
    } catch (const H5::Exception&) {
        cause.clear();
    }
    if (cause.empty()) cause = e.getFuncName() + ": " + e.getDetailMsg();
    // One line (the app prints the message as one): HDF5's write errors hold a ctime() stamp.
    for (char& c : cause)
        if (c == '\n') c = ' ';
    throw OutputError(path.string() + ": " + std::string(what) + " (" + cause + ")");
}

// An HDF5 enum type over `base` with the given members (values converted to the base's width).
template <class Int>
H5::EnumType make_enum(const H5::PredType& base, std::span<const EnumMember> members) {
    H5::EnumType type(base);
    for (const auto& [name, value] : members) {
        Int v = static_cast<Int>(value);  // not const: insert() takes a void* in HDF5 1.10
        type.insert(name, &v);
    }
    return type;
}

// One capture.hdf5 being written. Every HDF5 call goes through step(), which turns its failure into
// tprf::Error. The calls that meet the file system (create, write, close) hold no HDF5 object of their
// own, so no destructor calls into the library, clearing its error stack, before fail_hdf5 reads the
// cause there.
class CaptureWriter {
public:
    explicit CaptureWriter(const fs::path& path)
        : m_path(path), m_file(step("cannot create the file", [&] {
              return H5::H5File(path.string(), H5F_ACC_TRUNC);
          })) {}

    /// A float32 dataset of shape `dims` (C order) holding product(dims) values.
    void floats(const char* name, const std::vector<hsize_t>& dims, const float* values) {
        write(name, H5::PredType::IEEE_F32LE, make_space(name, dims), H5::PredType::NATIVE_FLOAT, values);
    }

    /// An enum dataset of shape (1,) over int32, as tal writes its Enum fields.
    void enumeration(const char* name, std::span<const EnumMember> members, std::int32_t value) {
        const auto type = step(std::string("cannot describe ") + name,
                               [&] { return make_enum<std::int32_t>(H5::PredType::NATIVE_INT32, members); });
        write(name, type, make_space(name, {1}), type, &value);
    }

    /// A scalar float64 dataset.
    void scalar(const char* name, double value) {
        write(name, H5::PredType::IEEE_F64LE, make_space(name, {}), H5::PredType::NATIVE_DOUBLE, &value);
    }

    /// A scalar boolean as h5py stores numpy.bool_: an enum over int8 with FALSE = 0 and TRUE = 1.
    void boolean(const char* name, bool value) {
        const auto type = step(std::string("cannot describe ") + name, [&] {
            return make_enum<std::int8_t>(H5::PredType::NATIVE_INT8, kNumpyBool);
        });
        const std::int8_t v = value ? 1 : 0;
        write(name, type, make_space(name, {}), type, &v);
    }

    /// A scalar variable-length UTF-8 string, as h5py stores a Python str.
    void text(const char* name, const std::string& value) {
        const auto type = step(std::string("cannot describe ") + name, [&] {
            H5::StrType t(H5::PredType::C_S1, H5T_VARIABLE);
            t.setCset(H5T_CSET_UTF8);
            return t;
        });
        const auto dataset = create(name, type, make_space(name, {}));
        step(std::string("cannot write the dataset ") + name, [&] { dataset.write(value, type); });
    }

    /// Closes the file, which flushes what the library still holds (a full disk shows here).
    void close() {
        step("cannot close the file", [&] { m_file.close(); });
    }

private:
    template <class Call>
    auto step(std::string_view what, Call&& call) -> decltype(call()) {
        try {
            return call();
        } catch (const H5::Exception& e) {
            fail_hdf5(m_path, what, e);
        }
    }

    // Shape `dims`; no dims: a scalar.
    H5::DataSpace make_space(const char* name, const std::vector<hsize_t>& dims) {
        return step(std::string("cannot describe ") + name, [&] {
            return dims.empty() ? H5::DataSpace(H5S_SCALAR)
                                : H5::DataSpace(static_cast<int>(dims.size()), dims.data());
        });
    }

    // Without modification times (HDF5 stamps every object by default): two renders of one scene give
    // the same bytes, so that captures can be compared with cmp (and a split render with one process's).
    H5::DataSet create(const char* name, const H5::DataType& type, const H5::DataSpace& space) {
        return step(std::string("cannot create the dataset ") + name, [&] {
            H5::DSetCreatPropList properties;
            if (H5Pset_obj_track_times(properties.getId(), false) < 0)
                throw H5::PropListIException("H5Pset_obj_track_times", "cannot turn time tracking off");
            return m_file.createDataSet(name, type, space, properties);
        });
    }

    void write(const char* name, const H5::DataType& file_type, const H5::DataSpace& space,
               const H5::DataType& memory_type, const void* values) {
        const auto dataset = create(name, file_type, space);
        step(std::string("cannot write the dataset ") + name, [&] { dataset.write(values, memory_type); });
    }

    const fs::path& m_path;
    H5::H5File m_file;
};

void check_grid(const CaptureGridData& grid, std::size_t nu, std::size_t nv) {
    TPRF_CHECK_EQ(static_cast<std::size_t>(grid.nu), nu);
    TPRF_CHECK_EQ(static_cast<std::size_t>(grid.nv), nv);
    TPRF_CHECK_EQ(grid.xyz.size(), nu * nv);
    TPRF_CHECK_EQ(grid.normals.size(), nu * nv);
}

void check_capture(const CaptureFile& capture) {
    const auto& shape = capture.shape;
    TPRF_CHECK_EQ(shape.size(), capture.confocal ? std::size_t{3} : std::size_t{5});
    std::size_t count = 1;
    for (const std::size_t n : shape) count *= n;
    TPRF_CHECK_LT(std::size_t{0}, count);
    TPRF_CHECK(capture.H != nullptr);
    if (capture.confocal) {
        check_grid(capture.sensor_grid, shape[1], shape[2]);
        check_grid(capture.laser_grid, shape[1], shape[2]);
    } else {
        check_grid(capture.laser_grid, shape[1], shape[2]);
        check_grid(capture.sensor_grid, shape[3], shape[4]);
    }
}

std::vector<float> to_float32(const std::vector<Vec3>& points) {
    std::vector<float> out;
    out.reserve(points.size() * 3);
    for (const Vec3& p : points)
        for (int k = 0; k < 3; ++k) out.push_back(static_cast<float>(p[k]));
    return out;
}

std::vector<float> to_float32(const Vec3& point) { return to_float32(std::vector<Vec3>{point}); }

void write_grid(CaptureWriter& writer, const std::string& prefix, const CaptureGridData& grid) {
    const std::vector<hsize_t> dims = {static_cast<hsize_t>(grid.nu), static_cast<hsize_t>(grid.nv), 3};
    writer.floats((prefix + "_grid_xyz").c_str(), dims, to_float32(grid.xyz).data());
    writer.floats((prefix + "_grid_normals").c_str(), dims, to_float32(grid.normals).data());
    writer.enumeration((prefix + "_grid_format").c_str(), kGridFormat, kGridXY3);
}

}  // namespace

void copy_capture_with_h(const fs::path& from, const fs::path& to, const float* H, const std::vector<std::size_t>& shape) {
    std::error_code ec;
    fs::copy_file(from, to, fs::copy_options::overwrite_existing, ec);
    if (ec) throw Error(from.string() + ": cannot copy to " + to.string() + ": " + ec.message());
    H5::Exception::dontPrint();
    try {
        H5::H5File file(to.string(), H5F_ACC_RDWR);
        H5::DataSet h = file.openDataSet("H");
        const H5::DataSpace space = h.getSpace();
        std::vector<hsize_t> dims(std::size_t(std::max(0, space.getSimpleExtentNdims())));
        space.getSimpleExtentDims(dims.data());
        if (!std::equal(dims.begin(), dims.end(), shape.begin(), shape.end()))
            throw Error(from.string() + ": its H does not have the shape of the measured capture");
        h.write(H, H5::PredType::NATIVE_FLOAT);
        file.close();
    } catch (const H5::Exception& e) {
        fail_hdf5(to, "cannot write H", e);
    }
}

void write_capture_hdf5(const fs::path& path, const CaptureFile& capture) {
    check_capture(capture);
    // The library's own report goes to stderr by default; here its failures become tprf::Error.
    H5::Exception::dontPrint();
    CaptureWriter writer(path);
    // H is stored contiguous: gzip (level 4, chunks of whole frames) took ~240 ms against ~10 ms for a
    // 512 x 64 x 64 cube and saved a third of its size.
    const std::vector<hsize_t> dims(capture.shape.begin(), capture.shape.end());
    writer.floats("H", dims, capture.H);
    writer.enumeration("H_format", kHFormat, capture.confocal ? kHFormatConfocal : kHFormatExhaustive);
    writer.floats("sensor_xyz", {3}, to_float32(capture.sensor_xyz).data());
    write_grid(writer, "sensor", capture.sensor_grid);
    writer.floats("laser_xyz", {3}, to_float32(capture.laser_xyz).data());
    write_grid(writer, "laser", capture.laser_grid);
    writer.enumeration("volume_format", kVolumeFormat, kVolumeUnknown);
    writer.scalar("delta_t", capture.delta_t);
    writer.scalar("t_start", capture.t_start);
    writer.boolean("t_accounts_first_and_last_bounces", capture.t_accounts_first_and_last_bounces);
    writer.text("scene_info", capture.scene_info);
    writer.close();
}

}  // namespace tprf
