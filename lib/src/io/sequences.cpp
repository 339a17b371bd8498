#include "tprf/io/sequences.h"

#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/io/atomic_file.h"
#include "tprf/io/image_io.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace tprf {
namespace {

std::string numbered(const char* prefix, int k, int digits, const char* ext) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s%0*d%s", prefix, digits, k, ext);
    return buf;
}

// Frame t of the cube as a height x width x 3 image.
void frame(const float* cube, int height, int width, int bins, int t, std::vector<float>& out) {
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
    out.resize(pixels * 3);
    for (std::size_t px = 0; px < pixels; ++px)
        for (int c = 0; c < 3; ++c)
            out[px * 3 + std::size_t(c)] = cube[(px * std::size_t(bins) + std::size_t(t)) * 3 + std::size_t(c)];
}

std::string quoted(const std::filesystem::path& p) {
    std::string s = "'";
    for (char ch : p.string()) s += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
    return s + "'";
}

}  // namespace

void write_frames(const std::filesystem::path& dir, const float* cube, int height, int width, int bins) {
    create_output_dir(dir);
    std::vector<float> image;
    for (int t = 0; t < bins; ++t) {
        check_cancelled();  // thousands of files: stop between two of them
        frame(cube, height, width, bins, t, image);
        write_exr(dir / numbered("frame_", t, 5, ".exr"), width, height, image.data());
    }
}

void write_streaks(const std::filesystem::path& dir, const float* cube, int height, int width, int bins) {
    create_output_dir(dir);
    std::vector<float> image(std::size_t(width) * std::size_t(bins) * 3);
    for (int r = 0; r < height; ++r) {
        check_cancelled();
        for (int c = 0; c < width; ++c) {
            const float* profile = cube + (std::size_t(r) * std::size_t(width) + std::size_t(c)) * std::size_t(bins) * 3;
            for (int t = 0; t < bins; ++t)
                for (int k = 0; k < 3; ++k)
                    image[(std::size_t(t) * std::size_t(width) + std::size_t(c)) * 3 + std::size_t(k)] =
                        profile[std::size_t(t) * 3 + std::size_t(k)];
        }
        write_exr(dir / numbered("row_", r, 4, ".exr"), width, bins, image.data());
    }
}

bool have_ffmpeg() { return std::system("command -v ffmpeg >/dev/null 2>&1") == 0; }

void write_video(const std::filesystem::path& mp4, const float* cube, int height, int width, int bins, int fps) {
    const std::filesystem::path scratch = mp4.parent_path() / ".video-frames";
    // One exposure for the whole sequence, from a strided sample of the cube's luminance.
    const std::size_t values = std::size_t(height) * std::size_t(width) * std::size_t(bins);
    const std::size_t step = std::max<std::size_t>(1, values / 2000000);
    std::vector<float> lum;
    for (std::size_t v = 0; v < values; v += step) {
        const float* p = cube + v * 3;
        const float l = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
        if (l > 0 && std::isfinite(l)) lum.push_back(l);
    }
    double scale = 1.0;
    if (!lum.empty()) {
        const std::size_t k = std::min(lum.size() - 1, std::size_t(0.995 * double(lum.size())));
        std::nth_element(lum.begin(), lum.begin() + std::ptrdiff_t(k), lum.end());
        scale = 1.0 / double(lum[k]);
    }
    create_output_dir(scratch);
    std::vector<float> image;
    for (int t = 0; t < bins; ++t) {
        check_cancelled();
        frame(cube, height, width, bins, t, image);
        const std::vector<std::uint8_t> rgb8 = tonemap(width, height, image.data(), scale);
        write_png(scratch / numbered("frame_", t, 5, ".png"), width, height, rgb8.data());
    }
    // Even sizes for yuv420p: pad by one pixel where needed.
    const std::string command = "ffmpeg -loglevel error -y -framerate " + std::to_string(fps) + " -i " +
                                quoted(scratch / "frame_%05d.png") +
                                " -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' -c:v libx264 -pix_fmt yuv420p " + quoted(mp4);
    if (std::system(command.c_str()) != 0) throw Error(mp4.string() + ": ffmpeg failed to encode the video");
    std::filesystem::remove_all(scratch);
}

}  // namespace tprf
