#include "test_process.h"
#include "tprf/io/atomic_file.h"
#include "tprf/core/error.h"
#include "tprf/io/image_io.h"
#include "tprf/io/npy.h"

#include <gtest/gtest.h>
// OpenEXR's C RGBA interface: its header needs no Imath include path, which the test target lacks.
#include <OpenEXR/ImfCRgbaFile.h>
#include <png.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using tprf::test::read_bytes;

// Each test writes into a directory of its own, so that tests may run in parallel.
class Io : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        m_dir = fs::temp_directory_path() /
                ("tprf_io_test_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }

    std::vector<std::string> listing() const {
        std::vector<std::string> names;
        for (const auto& entry : fs::directory_iterator(m_dir)) names.push_back(entry.path().filename().string());
        return names;
    }

    fs::path m_dir;
};

void write_bytes(const fs::path& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary) << bytes;
}

// A .npy file with a hand-written header (version 1.0 or 2.0) and `payload` raw bytes.
std::string npy_bytes(int major, const std::string& dict, const std::string& payload) {
    std::string header = "\x93NUMPY";
    header += static_cast<char>(major);
    header += '\0';
    const std::size_t length = dict.size();
    const int length_bytes = major == 1 ? 2 : 4;
    for (int i = 0; i < length_bytes; ++i) header += static_cast<char>((length >> (8 * i)) & 0xff);
    return header + dict + payload;
}

std::string float_bytes(const std::vector<float>& values) {
    return std::string(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(float));
}

double srgb(double linear) {
    return linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

TEST_F(Io, NpyRoundTripsExactlyWithTheHeaderNumpyWrites) {
    const std::vector<std::size_t> shape = {2, 3, 4};
    std::vector<float> values(24);
    for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i) * 0.37f - 5.0f;
    values[1] = -0.0f;
    values[2] = std::numeric_limits<float>::denorm_min();
    values[3] = std::numeric_limits<float>::max();
    const fs::path file = m_dir / "a.npy";
    tprf::write_npy(file, shape, values.data());

    const std::string bytes = read_bytes(file);
    ASSERT_GE(bytes.size(), 10u);
    EXPECT_EQ(bytes.substr(0, 6), "\x93NUMPY");
    EXPECT_EQ(bytes[6], 1);  // format version 1.0
    EXPECT_EQ(bytes[7], 0);
    const std::size_t header_len =
        static_cast<unsigned char>(bytes[8]) | static_cast<std::size_t>(static_cast<unsigned char>(bytes[9])) << 8;
    const std::size_t offset = 10 + header_len;
    EXPECT_EQ(offset % 64, 0u);
    const std::string dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }";
    EXPECT_EQ(bytes.substr(10, dict.size()), dict);
    EXPECT_EQ(bytes[offset - 1], '\n');
    EXPECT_EQ(bytes.substr(10 + dict.size(), header_len - dict.size() - 1),
              std::string(header_len - dict.size() - 1, ' '));
    EXPECT_EQ(bytes.size(), offset + 24 * sizeof(float));

    const tprf::NpyArray back = tprf::read_npy(file);
    EXPECT_EQ(back.shape, shape);
    ASSERT_EQ(back.data.size(), values.size());
    EXPECT_EQ(std::memcmp(back.data.data(), values.data(), values.size() * sizeof(float)), 0);
}

TEST_F(Io, NpyWritesOneAndZeroDimensionalShapesAsPythonTuples) {
    const std::vector<float> values = {1.0f, 2.0f, 3.0f, 4.0f, 5.0f};
    tprf::write_npy(m_dir / "v.npy", {5}, values.data());
    EXPECT_NE(read_bytes(m_dir / "v.npy").find("'shape': (5,), }"), std::string::npos);
    tprf::write_npy(m_dir / "s.npy", {}, values.data());
    EXPECT_NE(read_bytes(m_dir / "s.npy").find("'shape': (), }"), std::string::npos);
    const tprf::NpyArray scalar = tprf::read_npy(m_dir / "s.npy");
    EXPECT_TRUE(scalar.shape.empty());
    EXPECT_EQ(scalar.data, std::vector<float>{1.0f});
}

TEST_F(Io, ReadNpyAcceptsVersionTwoHeaders) {
    const std::vector<float> values = {0.5f, -1.5f, 2.25f, 8.0f, 1e30f, -3.0f};
    const fs::path file = m_dir / "v2.npy";
    write_bytes(file, npy_bytes(2, "{\"shape\": (3, 2), \"fortran_order\": False, \"descr\": \"<f4\"}\n",
                                float_bytes(values)));
    const tprf::NpyArray back = tprf::read_npy(file);
    EXPECT_EQ(back.shape, (std::vector<std::size_t>{3, 2}));
    EXPECT_EQ(back.data, values);
}

TEST_F(Io, ReadNpyRejectsWhatItCannotRead) {
    const auto expect_error = [&](const std::string& name, const std::string& bytes, const std::string& what) {
        const fs::path file = m_dir / name;
        write_bytes(file, bytes);
        try {
            tprf::read_npy(file);
            ADD_FAILURE() << name << ": no error";
        } catch (const tprf::Error& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(file.string()), std::string::npos) << message;
            EXPECT_NE(message.find(what), std::string::npos) << message;
        }
    };
    const std::string eight(8, '\0');
    expect_error("f8.npy", npy_bytes(1, "{'descr': '<f8', 'fortran_order': False, 'shape': (1,), }\n", eight),
                 "'<f8'");
    expect_error("big.npy", npy_bytes(1, "{'descr': '>f4', 'fortran_order': False, 'shape': (2,), }\n", eight),
                 "'>f4'");
    expect_error("fortran.npy", npy_bytes(1, "{'descr': '<f4', 'fortran_order': True, 'shape': (2,), }\n", eight),
                 "Fortran");
    expect_error("short.npy", npy_bytes(1, "{'descr': '<f4', 'fortran_order': False, 'shape': (3,), }\n", eight),
                 "size");
    expect_error("v3.npy", npy_bytes(3, "{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }\n", eight),
                 "version 3.0");
    expect_error("text.npy", "hello, world", "not a .npy file");
}

TEST(IoFullDisk, NpyMapOnAFullDiskIsAnErrorNotASignal) {
    // A 1 MiB file system and an 8 MiB array: without reserving the blocks up front, the first write
    // through the mapping beyond 1 MiB would kill the process with SIGBUS.
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("tprf_fulldisk_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    const std::string mount = "mount -t tmpfs -o size=1M tmpfs " + dir.string() + " 2>/dev/null";
    if (std::system(mount.c_str()) != 0) {
        std::filesystem::remove(dir);
        GTEST_SKIP() << "cannot mount a small tmpfs here (needs root)";
    }
    try {
        tprf::NpyMap map(dir / "big.npy", {2, 1024, 1024});
        ADD_FAILURE() << "an 8 MiB map on a 1 MiB file system was accepted";
    } catch (const tprf::OutputError& e) {  // not an Error: the input was fine (exit 1, not 2)
        EXPECT_NE(std::string(e.what()).find("No space left on device (free some space"), std::string::npos)
            << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "big.npy"));
    EXPECT_EQ(std::system(("umount " + dir.string()).c_str()), 0);
    std::filesystem::remove(dir);
}

TEST_F(Io, NpyMapWritesThroughTheMappingAndCommits) {
    const fs::path file = m_dir / "transient.npy";
    const std::vector<std::size_t> shape = {4, 5, 1000, 3};
    {
        tprf::NpyMap map(file, shape);
        ASSERT_EQ(map.size(), 4u * 5u * 1000u * 3u);
        EXPECT_EQ(map.shape(), shape);
        // The payload starts at a multiple of 64 bytes of a page-aligned mapping.
        EXPECT_EQ(reinterpret_cast<std::uintptr_t>(map.data()) % 64, 0u);
        EXPECT_FALSE(fs::exists(file));
        // Leave every 7th element untouched: the sparse file must read back as zero there.
        for (std::size_t i = 0; i < map.size(); ++i)
            if (i % 7 != 0) map.data()[i] = static_cast<float>(i) * 0.25f;
        tprf::NpyMap moved(std::move(map));
        EXPECT_EQ(map.data(), nullptr);
        moved.commit();
        EXPECT_EQ(moved.data(), nullptr);
    }
    EXPECT_EQ(listing(), std::vector<std::string>{"transient.npy"});
    const tprf::NpyArray back = tprf::read_npy(file);
    EXPECT_EQ(back.shape, shape);
    ASSERT_EQ(back.data.size(), 60000u);
    for (std::size_t i = 0; i < back.data.size(); ++i)
        ASSERT_EQ(back.data[i], i % 7 == 0 ? 0.0f : static_cast<float>(i) * 0.25f) << "element " << i;
    // Same header as write_npy, so numpy sees the same file either way.
    const std::vector<float> copy = back.data;
    tprf::write_npy(m_dir / "copy.npy", shape, copy.data());
    EXPECT_EQ(read_bytes(m_dir / "copy.npy"), read_bytes(file));
}

TEST_F(Io, UncommittedFilesLeaveNothingBehind) {
    {
        tprf::AtomicFile file(m_dir / "a.bin");
        EXPECT_EQ(file.temp_path().parent_path(), m_dir);
        EXPECT_EQ(file.temp_path().filename().string().front(), '.');
        EXPECT_TRUE(fs::exists(file.temp_path()));
        write_bytes(file.temp_path(), "partial");
    }
    {
        tprf::NpyMap map(m_dir / "b.npy", {3, 4});
        map.data()[5] = 1.0f;
    }
    {
        tprf::NpyMap map(m_dir / "c.npy", {2});
        tprf::NpyMap other(m_dir / "d.npy", {2});
        other = std::move(map);  // d's temporary is abandoned now, c's when `other` goes
    }
    EXPECT_TRUE(listing().empty());
}

TEST_F(Io, AtomicFileCommitReplacesTheFinalFile) {
    const fs::path target = m_dir / "out.txt";
    write_bytes(target, "old");
    tprf::AtomicFile file(target);
    EXPECT_NE(file.temp_path(), tprf::AtomicFile(target).temp_path());
    write_bytes(file.temp_path(), "new");
    EXPECT_EQ(read_bytes(target), "old");
    file.commit();
    EXPECT_TRUE(file.committed());
    EXPECT_EQ(read_bytes(target), "new");
    EXPECT_EQ(listing(), std::vector<std::string>{"out.txt"});
}

TEST_F(Io, CheckOutputDirCreatesDirectoriesAndRejectsUnwritablePaths) {
    const fs::path nested = m_dir / "x" / "y";
    tprf::check_output_dir(nested);
    EXPECT_TRUE(fs::is_directory(nested));
    EXPECT_TRUE(fs::is_empty(nested));  // the probe file is gone

    const fs::path regular = m_dir / "file";
    write_bytes(regular, "x");
    for (const fs::path& bad : {regular / "sub", regular}) {
        try {
            tprf::check_output_dir(bad);
            ADD_FAILURE() << bad << ": no error";
        } catch (const tprf::Error& e) {
            EXPECT_EQ(std::string(e.what()).rfind(bad.string() + ": cannot write: ", 0), 0u) << e.what();
        }
    }
}

// The chlist attribute of an EXR header: channel name -> pixel type (0 UINT, 1 HALF, 2 FLOAT).
std::vector<std::pair<std::string, int>> exr_channels(const std::string& bytes) {
    const std::string key("channels\0chlist\0", 16);
    std::size_t pos = bytes.find(key);
    if (pos == std::string::npos) return {};
    pos += key.size() + 4;  // the attribute's size
    std::vector<std::pair<std::string, int>> channels;
    while (pos < bytes.size() && bytes[pos] != '\0') {
        const std::size_t end = bytes.find('\0', pos);
        std::int32_t type = 0;
        std::memcpy(&type, bytes.data() + end + 1, sizeof type);
        channels.emplace_back(bytes.substr(pos, end - pos), type);
        pos = end + 1 + 16;  // type, pLinear + 3 reserved, x and y sampling
    }
    return channels;
}

TEST_F(Io, ExrStoresFloatChannelsTopRowFirst) {
    const int width = 5;
    const int height = 3;
    // Multiples of 1/4 below 2048 are exact in half as well, so the RGBA (half) reader returns them
    // exactly; each value encodes its row, column and channel.
    std::vector<float> rgb(static_cast<std::size_t>(width * height * 3));
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c)
                rgb[static_cast<std::size_t>((y * width + x) * 3 + c)] = static_cast<float>(y * 100 + x * 10 + c) * 0.25f;
    const fs::path file = m_dir / "steady.exr";
    tprf::write_exr(file, width, height, rgb.data());
    EXPECT_EQ(listing(), std::vector<std::string>{"steady.exr"});

    const std::vector<std::pair<std::string, int>> float_rgb = {{"B", 2}, {"G", 2}, {"R", 2}};
    EXPECT_EQ(exr_channels(read_bytes(file)), float_rgb);

    ImfInputFile* in = ImfOpenInputFile(file.c_str());
    ASSERT_NE(in, nullptr) << ImfErrorMessage();
    int x_min = -1, y_min = -1, x_max = -1, y_max = -1;
    ImfHeaderDataWindow(ImfInputHeader(in), &x_min, &y_min, &x_max, &y_max);
    EXPECT_EQ(x_min, 0);
    EXPECT_EQ(y_min, 0);
    ASSERT_EQ(x_max, width - 1);
    ASSERT_EQ(y_max, height - 1);
    std::vector<ImfRgba> pixels(static_cast<std::size_t>(width * height));
    ASSERT_NE(ImfInputSetFrameBuffer(in, pixels.data(), 1, static_cast<std::size_t>(width)), 0) << ImfErrorMessage();
    ASSERT_NE(ImfInputReadPixels(in, 0, height - 1), 0) << ImfErrorMessage();
    ImfCloseInputFile(in);
    for (int i = 0; i < width * height; ++i) {
        const ImfRgba& p = pixels[static_cast<std::size_t>(i)];
        const float* expected = rgb.data() + 3 * i;
        EXPECT_EQ(ImfHalfToFloat(p.r), expected[0]) << "pixel " << i;
        EXPECT_EQ(ImfHalfToFloat(p.g), expected[1]) << "pixel " << i;
        EXPECT_EQ(ImfHalfToFloat(p.b), expected[2]) << "pixel " << i;
    }
}

TEST_F(Io, PngReadsBackTheSamePixels) {
    const int width = 7;
    const int height = 4;
    std::vector<std::uint8_t> rgb8(static_cast<std::size_t>(width * height * 3));
    for (std::size_t i = 0; i < rgb8.size(); ++i) rgb8[i] = static_cast<std::uint8_t>((i * 37 + 11) % 256);
    const fs::path file = m_dir / "preview.png";
    tprf::write_png(file, width, height, rgb8.data());
    EXPECT_EQ(listing(), std::vector<std::string>{"preview.png"});

    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    ASSERT_NE(png_image_begin_read_from_file(&image, file.c_str()), 0) << image.message;
    EXPECT_EQ(image.width, static_cast<png_uint_32>(width));
    EXPECT_EQ(image.height, static_cast<png_uint_32>(height));
    EXPECT_EQ(image.format, static_cast<png_uint_32>(PNG_FORMAT_RGB));
    image.format = PNG_FORMAT_RGB;
    std::vector<std::uint8_t> back(PNG_IMAGE_SIZE(image));
    ASSERT_NE(png_image_finish_read(&image, nullptr, back.data(), 0, nullptr), 0) << image.message;
    EXPECT_EQ(back, rgb8);
}

TEST_F(Io, WritersRejectEmptyImages) {
    const float rgb[3] = {};
    EXPECT_THROW(tprf::write_exr(m_dir / "e.exr", 0, 1, rgb), tprf::Error);
    EXPECT_THROW(tprf::write_png(m_dir / "e.png", 1, 0, nullptr), tprf::Error);
    EXPECT_TRUE(listing().empty());
}

TEST_F(Io, TonemapMapsTheHighPercentileToWhite) {
    // 194 grey pixels 0.01, 0.02, ..., 1.94 and six outliers of 100 (200 pixels in all): the nearest
    // rank of the 97th percentile is ceil(0.97 * 200) = 194, the value 1.94, so 1.94 is white (255)
    // and 1.93 just below (1.93 / 1.94 encodes to 254.4); the outliers saturate.
    std::vector<float> rgb;
    for (int i = 1; i < 195; ++i) rgb.insert(rgb.end(), 3, static_cast<float>(i) * 0.01f);
    for (int i = 0; i < 6; ++i) rgb.insert(rgb.end(), 3, 100.0f);
    const std::vector<std::uint8_t> out = tprf::tonemap(200, 1, rgb.data());
    ASSERT_EQ(out.size(), 600u);
    EXPECT_EQ(out[3 * 193], 255);
    EXPECT_EQ(out[3 * 192], 254);
    EXPECT_EQ(out[3 * 199], 255);
    EXPECT_EQ(out[0], std::lround(255.0 * srgb(0.01 / 1.94)));
}

TEST_F(Io, TonemapWeighsLuminanceAndHonoursAFixedExposure) {
    // Pure red has luminance 0.2126: it is the brightest pixel and sets the scale, so the grey
    // 0.1 becomes 0.1 / 0.2126 before encoding.
    const std::vector<float> rgb = {1.0f, 0.0f, 0.0f, 0.1f, 0.1f, 0.1f};
    const std::vector<std::uint8_t> out = tprf::tonemap(2, 1, rgb.data());
    EXPECT_EQ(out[0], 255);
    EXPECT_EQ(out[1], 0);
    EXPECT_EQ(out[3], std::lround(255.0 * srgb(0.1 / 0.2126)));
    // Linear 0.5 is sRGB 188 (0.7354 * 255).
    const std::vector<float> grey = {0.25f, 0.25f, 0.25f};
    EXPECT_EQ(tprf::tonemap(1, 1, grey.data(), 2.0), (std::vector<std::uint8_t>{188, 188, 188}));
}

TEST_F(Io, TonemapKeepsZeroAndBadPixelsBlack) {
    const std::vector<float> zero(4 * 3 * 3, 0.0f);
    EXPECT_EQ(tprf::tonemap(4, 3, zero.data()), std::vector<std::uint8_t>(36, 0));

    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    const std::vector<float> rgb = {nan, 1.0f, 1.0f, 2.0f, 2.0f, 2.0f, 1.0f, inf, 1.0f, 0.0f, -1.0f, 0.0f};
    const std::vector<std::uint8_t> out = tprf::tonemap(4, 1, rgb.data());
    EXPECT_EQ(out, (std::vector<std::uint8_t>{0, 0, 0, 255, 255, 255, 0, 0, 0, 0, 0, 0}));
}

}  // namespace
