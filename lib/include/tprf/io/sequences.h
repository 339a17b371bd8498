#pragma once
/// Views of a rendered cube for people: frames (one EXR per bin), streak images (one x-t EXR per
/// image row, as a streak camera records) and an MP4 of light in flight.

#include <filesystem>

namespace tprf {

/// Writes dir/frame_NNNNN.exr for every bin of a (height, width, bins, 3) cube.
void write_frames(const std::filesystem::path& dir, const float* cube, int height, int width, int bins);

/// Writes dir/row_NNNN.exr for every image row: width columns by `bins` rows (time runs downward).
void write_streaks(const std::filesystem::path& dir, const float* cube, int height, int width, int bins);

/// True when `ffmpeg` is on the PATH.
bool have_ffmpeg();

/// Encodes the cube as an H.264 MP4 at `fps` frames per second through ffmpeg, one frame per bin,
/// all frames tone-mapped with one exposure (the 99.5th percentile over the whole cube), so that
/// brightness changes over time stay visible. The PNG frames go to a scratch directory beside the MP4,
/// `.video-frames`, removed once the video is encoded.
void write_video(const std::filesystem::path& mp4, const float* cube, int height, int width, int bins, int fps = 30);

}  // namespace tprf
