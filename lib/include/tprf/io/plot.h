#pragma once
/// Line plots drawn straight into an RGB8 image (and a PNG), with an embedded 5 x 9 bitmap font, so that
/// figures of profiles and benchmarks need no plotting library.
///
/// Images are height x width x 3 bytes, row-major, row 0 the top, as in image_io.h.

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace tprf {

/// How an axis maps data to pixels. Log: base 10, only positive values can be placed.
enum class AxisScale { Linear, Log };

/// How a series is drawn. Line: straight segments between consecutive points. Steps: a staircase in
/// which y[i] holds from x[i] to x[i+1] (for a histogram pass the bin edges as x and repeat the last
/// value at the right edge). Markers: a small filled square on each point.
enum class SeriesStyle { Line, Steps, Markers };

/// One curve of a panel.
struct PlotSeries {
    std::string label;                           ///< legend text; empty: not in the legend
    std::vector<double> x, y;                    ///< same length (extra values of the longer one are ignored);
                                                 ///< non-finite points (and <= 0 on a log axis) are skipped
                                                 ///< (a Line or Steps breaks there)
    std::array<std::uint8_t, 3> color{0, 0, 0};  ///< sRGB; all zero: a palette colour by series index
    SeriesStyle style = SeriesStyle::Line;
};

/// One plot: axes, curves and their legend.
struct PlotPanel {
    std::string title, x_label, y_label;
    AxisScale x_scale = AxisScale::Linear, y_scale = AxisScale::Linear;
    std::vector<PlotSeries> series;
    /// Axis ranges in data units, in either order. Default (or unusable: not finite, empty, <= 0 on a log
    /// axis): from the data, with 5% margin on linear axes and whole decades on log axes; all-equal data:
    /// +-10% of the value (+-1 around 0); no data: [0, 1] or [1, 10].
    std::optional<std::pair<double, double>> x_range, y_range;
};

/// Renders panels stacked top to bottom, each width x panel_height pixels: white background, axes with
/// ticks and numeric tick labels (linear: 1/2/5 steps; log: decades labelled like 1e3), the title, the
/// axis labels (the y label written vertically) and a legend in the corner of the plot area with the
/// least ink under it. Characters are 12 x 18 pixels (6 x 9 where width < 600 or panel_height < 200).
/// Returns (panels.size() * panel_height) x width x 3 bytes, row 0 at top.
/// Throws tprf::Error when width or panel_height is not positive or the image would be too large.
std::vector<std::uint8_t> render_plot(const std::vector<PlotPanel>& panels, int width = 900, int panel_height = 320);

/// render_plot + write_png (atomic). Throws tprf::Error on bad sizes or no panels.
void write_plot_png(const std::filesystem::path& path, const std::vector<PlotPanel>& panels, int width = 900,
                    int panel_height = 320);

/// Where a panel's data lands: the axis ranges and the plot area in pixels.
struct PlotFrame {
    double x0, x1, y0, y1;         ///< axis ranges, data units (x0 at `left`, y0 at `bottom`)
    AxisScale xs, ys;              ///< axis scales
    int left, right, top, bottom;  ///< plot area, pixel columns and rows inclusive, rows from the panel's top
    /// Pixel column of x (rounded); values outside the range land outside [left, right]. A value that
    /// cannot be placed (not finite, or <= 0 on a log axis) gives -1.
    int px(double x) const;
    /// Pixel row of y, as px (rows grow downwards: y0 is at `bottom`).
    int py(double y) const;
};

/// The frame of `panel` drawn as the first panel of a width x panel_height image (panel k lies
/// k * panel_height rows lower).
PlotFrame plot_frame(const PlotPanel& panel, int width, int panel_height);

}  // namespace tprf
