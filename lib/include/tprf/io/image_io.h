#pragma once
/// Images of the output directory: the linear steady image as OpenEXR (steady.exr) and its
/// tone-mapped 8-bit sRGB preview (preview.png). Both appear atomically under their final name.
///
/// Pixel buffers are height x width x 3 (RGB), row-major, row 0 the top of the image.

#include <cstdint>
#include <filesystem>
#include <vector>

namespace tprf {

/// Writes a scanline OpenEXR file with 32-bit FLOAT channels R, G, B (ZIP compressed, lossless), so
/// that the radiance keeps its full range and precision. `rgb`: height x width x 3 floats, linear
/// radiance (W / (m^2 sr)), row 0 the top. OpenEXR's errors are rethrown as tprf::Error.
void write_exr(const std::filesystem::path& path, int width, int height, const float* rgb);

/// Writes an 8-bit RGB PNG (libpng). `rgb8`: height x width x 3 bytes, sRGB-encoded, row 0 the top.
void write_png(const std::filesystem::path& path, int width, int height, const std::uint8_t* rgb8);

/// Maps linear radiance to 8-bit sRGB for a preview. Returns height x width x 3 bytes.
///
/// Each channel is multiplied by a scale, clamped to [0, 1], encoded with the sRGB transfer curve
/// (IEC 61966-2-1) and rounded to 0..255. With `exposure_scale` > 0 that is the scale. Otherwise the
/// scale is automatic: 1 / L, where L is the 97th percentile (nearest rank) of the luminance
/// 0.2126 R + 0.7152 G + 0.0722 B over the pixels whose luminance is positive, so that the bright
/// pixels of a light source or a laser spot (a few percent of a view into a lit room) saturate
/// rather than darken the whole image; an
/// image without any positive luminance stays black. A pixel with a NaN or infinite channel becomes
/// black and is left out of the percentile, so that one bad sample never blanks or crashes a preview.
std::vector<std::uint8_t> tonemap(int width, int height, const float* rgb, double exposure_scale = 0.0);

}  // namespace tprf
