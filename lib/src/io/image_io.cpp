#include "tprf/io/image_io.h"

#include "tprf/io/atomic_file.h"
#include "tprf/core/error.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <png.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <string>

namespace tprf {

namespace fs = std::filesystem;

namespace {

void check_size(const fs::path& path, int width, int height) {
    if (width <= 0 || height <= 0)
        fail_input(path, "", "cannot write an image of " + std::to_string(width) + " x " + std::to_string(height) +
                                 " pixels");
}

double srgb_encode(double linear) {
    return linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

bool finite_pixel(const float* p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); }

double luminance(const float* p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

}  // namespace

void write_exr(const fs::path& path, int width, int height, const float* rgb) {
    check_size(path, width, height);
    AtomicFile file(path);
    try {
        Imf::Header header(width, height);
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::FrameBuffer frame;
        // OpenEXR's Slice takes a mutable pointer for both directions; an OutputFile only reads it.
        char* base = reinterpret_cast<char*>(const_cast<float*>(rgb));
        const std::size_t x_stride = 3 * sizeof(float);
        const std::size_t y_stride = x_stride * static_cast<std::size_t>(width);
        const char* names[] = {"R", "G", "B"};
        for (std::size_t c = 0; c < 3; ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
            frame.insert(names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), x_stride, y_stride));
        }
        // The data window starts at (0, 0) and lines are stored top to bottom (INCREASING_Y), so
        // row 0 of `rgb` is the top line of the file.
        Imf::OutputFile out(file.temp_path().c_str(), header);
        out.setFrameBuffer(frame);
        out.writePixels(height);
    } catch (const std::exception& e) {
        throw OutputError(path.string() + ": cannot write OpenEXR: " + e.what());
    }
    file.commit();
}

void write_png(const fs::path& path, int width, int height, const std::uint8_t* rgb8) {
    check_size(path, width, height);
    AtomicFile file(path);
    // The simplified API reports errors in image.message instead of longjmp, which would skip the
    // destructors of this C++ frame.
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    image.width = static_cast<png_uint_32>(width);
    image.height = static_cast<png_uint_32>(height);
    image.format = PNG_FORMAT_RGB;
    if (png_image_write_to_file(&image, file.temp_path().c_str(), 0, rgb8, 0, nullptr) == 0) {
        const std::string message = image.message;
        png_image_free(&image);
        throw OutputError(path.string() + ": cannot write PNG: " + message);
    }
    file.commit();
}

std::vector<std::uint8_t> tonemap(int width, int height, const float* rgb, double exposure_scale) {
    const std::size_t pixels =
        static_cast<std::size_t>(std::max(width, 0)) * static_cast<std::size_t>(std::max(height, 0));
    std::vector<std::uint8_t> out(3 * pixels, 0);
    double scale = exposure_scale;
    if (!(scale > 0.0)) {
        std::vector<double> lum;
        lum.reserve(pixels);
        for (std::size_t i = 0; i < pixels; ++i) {
            const float* p = rgb + 3 * i;
            if (finite_pixel(p) && luminance(p) > 0.0) lum.push_back(luminance(p));
        }
        if (lum.empty()) return out;
        // Nearest rank: the smallest value with at least 97% of the values at or below it.
        const std::size_t rank = (970 * lum.size() + 999) / 1000;
        const auto nth = lum.begin() + static_cast<std::ptrdiff_t>(rank - 1);
        std::nth_element(lum.begin(), nth, lum.end());
        scale = 1.0 / *nth;
    }
    for (std::size_t i = 0; i < pixels; ++i) {
        const float* p = rgb + 3 * i;
        if (!finite_pixel(p)) continue;
        for (std::size_t c = 0; c < 3; ++c) {
            double v = static_cast<double>(p[c]) * scale;
            if (!(v > 0.0)) v = 0.0;  // also a NaN from 0 * an infinite exposure_scale
            v = std::min(v, 1.0);
            out[3 * i + c] = static_cast<std::uint8_t>(std::lround(255.0 * srgb_encode(v)));
        }
    }
    return out;
}

}  // namespace tprf
