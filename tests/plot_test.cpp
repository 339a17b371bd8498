#include "tprf/core/error.h"
#include "tprf/io/plot.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>
#include <unistd.h>

namespace {

using tprf::AxisScale;
using tprf::PlotPanel;
using tprf::PlotSeries;
using tprf::SeriesStyle;
using Rgb = std::array<std::uint8_t, 3>;

constexpr int kWidth = 900, kHeight = 320;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr Rgb kRed{200, 30, 30}, kBlue{30, 30, 200};

struct Image {
    std::vector<std::uint8_t> rgb;
    int width;
    Rgb at(int x, int y) const {
        const std::size_t i = (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + x) * 3;
        return {rgb[i], rgb[i + 1], rgb[i + 2]};
    }
    /// Whether `c` appears anywhere in the inclusive rectangle.
    bool has(Rgb c, int x0, int y0, int x1, int y1) const {
        for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x)
                if (at(x, y) == c) return true;
        return false;
    }
};

Image render(const PlotPanel& panel) { return {tprf::render_plot({panel}, kWidth, kHeight), kWidth}; }

PlotSeries series(std::vector<double> x, std::vector<double> y, Rgb color, SeriesStyle style = SeriesStyle::Line,
                  std::string label = "") {
    return {std::move(label), std::move(x), std::move(y), color, style};
}

std::vector<double> iota(int n) {
    std::vector<double> v(n);
    for (int i = 0; i < n; ++i) v[i] = i;
    return v;
}

TEST(Plot, ConstantSeriesDrawsOnItsRow) {
    PlotPanel panel;
    panel.series.push_back(series(iota(11), std::vector<double>(11, 3.0), kRed));
    const tprf::PlotFrame f = tprf::plot_frame(panel, kWidth, kHeight);
    // All-equal data: a band of 10% of the value on either side, so y = 3 sits mid-height.
    EXPECT_NEAR(f.y0, 2.7, 1e-12);
    EXPECT_NEAR(f.y1, 3.3, 1e-12);
    EXPECT_NEAR(f.py(3.0), (f.top + f.bottom) / 2.0, 1.0);
    const Image img = render(panel);
    const int row = f.py(3.0);
    for (double x = 0.5; x < 10.0; x += 1.0) {
        const int col = f.px(x);
        EXPECT_EQ(img.at(col, row), kRed) << "x = " << x;
        // The pen is 2 pixels wide at this size: the colour covers rows py and py + 1, nothing else.
        for (int y = f.top + 1; y < f.bottom; ++y) {
            if (std::abs(y - row) > 1) {
                EXPECT_NE(img.at(col, y), kRed) << "x = " << x << ", row " << y;
            }
        }
    }
}

TEST(Plot, LogAxisSpacesDecadesEvenly) {
    PlotPanel panel;
    panel.x_scale = panel.y_scale = AxisScale::Log;
    panel.series.push_back(series({1.0, 10.0, 100.0}, {1.0, 10.0, 100.0}, kRed));
    const tprf::PlotFrame f = tprf::plot_frame(panel, kWidth, kHeight);
    // Data 1..100 spans exactly two whole decades: the axis ends on them.
    EXPECT_DOUBLE_EQ(f.y0, 1.0);
    EXPECT_DOUBLE_EQ(f.y1, 100.0);
    EXPECT_EQ(f.py(1.0), f.bottom);
    EXPECT_EQ(f.py(100.0), f.top);
    // Each decade is half the axis; rounding to whole pixels moves a row by at most half a pixel.
    EXPECT_LE(std::abs((f.py(1.0) - f.py(10.0)) - (f.py(10.0) - f.py(100.0))), 1);
    EXPECT_LE(std::abs((f.px(10.0) - f.px(1.0)) - (f.px(100.0) - f.px(10.0))), 1);
    // Ranges that are not whole decades widen to them; non-positive values are left out.
    panel.series = {series({3.0, -2.0, 450.0, 450.0}, {0.02, 5.0, 0.0, 0.09}, kRed)};
    const tprf::PlotFrame g = tprf::plot_frame(panel, kWidth, kHeight);
    EXPECT_DOUBLE_EQ(g.x0, 1.0);
    EXPECT_DOUBLE_EQ(g.x1, 1000.0);
    EXPECT_DOUBLE_EQ(g.y0, 0.01);
    EXPECT_DOUBLE_EQ(g.y1, 0.1);
    EXPECT_EQ(g.py(-1.0), -1);
}

TEST(Plot, LinearRangeHasFivePercentMarginUnlessGiven) {
    PlotPanel panel;
    panel.series.push_back(series({0.0, 10.0}, {-2.0, 2.0}, kRed));
    const tprf::PlotFrame f = tprf::plot_frame(panel, kWidth, kHeight);
    EXPECT_NEAR(f.x0, -0.25, 1e-12);
    EXPECT_NEAR(f.x1, 10.25, 1e-12);
    EXPECT_NEAR(f.y0, -2.1, 1e-12);
    EXPECT_NEAR(f.y1, 2.1, 1e-12);
    panel.x_range = {{4.0, 1.0}};  // reversed: taken in order
    panel.y_range = {{kNaN, 1.0}};  // unusable: from the data
    const tprf::PlotFrame g = tprf::plot_frame(panel, kWidth, kHeight);
    EXPECT_EQ(g.x0, 1.0);
    EXPECT_EQ(g.x1, 4.0);
    EXPECT_NEAR(g.y0, -2.1, 1e-12);
    EXPECT_EQ(g.px(1.0), g.left);
    EXPECT_EQ(g.px(4.0), g.right);
}

TEST(Plot, NaNPointsBreakTheLineAndDrawNothing) {
    PlotPanel panel;
    std::vector<double> x = iota(11), y = iota(11);
    y[5] = kNaN;
    x[6] = kNaN;
    panel.series.push_back(series(x, y, kRed));
    panel.series.push_back(series(x, y, kBlue, SeriesStyle::Markers));
    panel.series.back().y[3] = std::numeric_limits<double>::infinity();
    const tprf::PlotFrame f = tprf::plot_frame(panel, kWidth, kHeight);
    const Image img = render(panel);
    const auto column_has = [&](Rgb c, double at) { return img.has(c, f.px(at), f.top, f.px(at), f.bottom); };
    // The line runs 0..4 and 7..10; nothing of it lies over x in (4, 7).
    EXPECT_TRUE(column_has(kRed, 2.5));
    EXPECT_TRUE(column_has(kRed, 8.5));
    EXPECT_FALSE(column_has(kRed, 5.5));
    // Markers: on the good points, none at the infinite, NaN and NaN-x points (3, 5, 6).
    for (const int i : {2, 4, 7})
        EXPECT_EQ(img.at(f.px(i), f.py(i)), kBlue) << i;
    for (const double at : {3.0, 5.0, 6.0})
        EXPECT_FALSE(column_has(kBlue, at)) << at;
}

TEST(Plot, StepsHoldEachValueUntilTheNextPoint) {
    PlotPanel panel;
    panel.series.push_back(series({0.0, 1.0, 2.0}, {0.0, 1.0, 1.0}, kRed, SeriesStyle::Steps));
    const tprf::PlotFrame f = tprf::plot_frame(panel, kWidth, kHeight);
    const Image img = render(panel);
    EXPECT_EQ(img.at(f.px(0.5), f.py(0.0)), kRed);  // the tread at y = 0 ...
    EXPECT_EQ(img.at(f.px(1.0), f.py(0.5)), kRed);  // ... the riser at x = 1 ...
    EXPECT_EQ(img.at(f.px(1.5), f.py(1.0)), kRed);  // ... the tread at y = 1
    EXPECT_FALSE(img.has(kRed, f.px(0.5) - 3, f.py(0.5) - 3, f.px(0.5) + 3, f.py(0.5) + 3));  // no diagonal
}

TEST(Plot, LegendShowsLabelledSeriesAwayFromTheData) {
    PlotPanel panel;
    // A diagonal through the top-right and bottom-left corners: the legend must take another corner.
    panel.series.push_back(series({0.0, 10.0}, {0.0, 10.0}, kRed, SeriesStyle::Line, "a rising line"));
    panel.series.push_back(series({1.0}, {kNaN}, kBlue, SeriesStyle::Line, "no data"));
    panel.series.push_back(series({1.0}, {kNaN}, {10, 150, 10}));  // no label: not in the legend
    const tprf::PlotFrame f = tprf::plot_frame(panel, kWidth, kHeight);
    const Image img = render(panel);
    for (const double v : {0.5, 9.5}) EXPECT_EQ(img.at(f.px(v), f.py(v)), kRed) << v;
    EXPECT_TRUE(img.has(kBlue, 0, 0, kWidth - 1, kHeight - 1));
    EXPECT_FALSE(img.has({10, 150, 10}, 0, 0, kWidth - 1, kHeight - 1));
}

TEST(Plot, DegenerateInputsKeepTheStatedSize) {
    std::vector<PlotPanel> panels(8);
    panels[1].series.push_back(series({}, {}, kRed));
    panels[2].series.push_back(series({2.0}, {5.0}, kRed));
    panels[3].series.push_back(series(iota(5), std::vector<double>(5, 0.0), kRed, SeriesStyle::Steps));
    panels[4].series.push_back(series({kNaN, kNaN}, {kNaN, 1.0}, kRed, SeriesStyle::Markers));
    panels[5].y_scale = AxisScale::Log;
    panels[5].y_range = {{-1.0, 10.0}};
    panels[5].series.push_back(series({1.0, 2.0}, {-1.0, 0.0}, kRed));
    panels[6].series.push_back(series(iota(5), {1.0, 2.0}, kRed));  // lengths differ: the shorter rules
    panels[7].series.push_back(series({1e308, -1e308, 1e-320}, {1e308, 1.0, -1e308}, kRed));
    panels[7].x_scale = AxisScale::Log;
    for (const auto [w, h] : {std::array{kWidth, kHeight}, std::array{7, 5}, std::array{1, 1}}) {
        const std::vector<std::uint8_t> rgb = tprf::render_plot(panels, w, h);
        EXPECT_EQ(rgb.size(), panels.size() * static_cast<std::size_t>(w) * h * 3) << w << " x " << h;
    }
    for (const PlotPanel& p : panels) {
        const tprf::PlotFrame f = tprf::plot_frame(p, kWidth, kHeight);
        EXPECT_TRUE(std::isfinite(f.x0) && std::isfinite(f.x1) && f.x0 < f.x1);
        EXPECT_TRUE(std::isfinite(f.y0) && std::isfinite(f.y1) && f.y0 < f.y1);
        EXPECT_LT(f.left, f.right);
        EXPECT_LT(f.top, f.bottom);
    }
    // Fallbacks fixed by the interface: no data [0, 1]; a log axis without positive data [1, 10];
    // a single point a band of 10% of its value around it.
    EXPECT_EQ(tprf::plot_frame(panels[0], kWidth, kHeight).x1, 1.0);
    EXPECT_EQ(tprf::plot_frame(panels[5], kWidth, kHeight).y0, 1.0);
    EXPECT_EQ(tprf::plot_frame(panels[5], kWidth, kHeight).y1, 10.0);
    EXPECT_NEAR(tprf::plot_frame(panels[2], kWidth, kHeight).y1, 5.5, 1e-12);
    EXPECT_EQ(tprf::render_plot({}, kWidth, kHeight).size(), 0u);
}

TEST(Plot, WritesPngAndRejectsBadSizes) {
    const auto path = std::filesystem::temp_directory_path() /
                      ("tprf_plot_test_" + std::to_string(::getpid()) + ".png");
    PlotPanel panel;
    panel.title = "t";
    panel.series.push_back(series({0.0, 1.0}, {0.0, 1.0}, kRed));
    tprf::write_plot_png(path, {panel, panel}, 200, 100);
    std::ifstream in(path, std::ios::binary);
    const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    std::filesystem::remove(path);
    ASSERT_GE(bytes.size(), 24u);
    EXPECT_EQ(bytes.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    // IHDR: width and height, big-endian, at bytes 16..23.
    const auto be32 = [&](std::size_t i) {
        return (static_cast<unsigned char>(bytes[i]) << 24) | (static_cast<unsigned char>(bytes[i + 1]) << 16) |
               (static_cast<unsigned char>(bytes[i + 2]) << 8) | static_cast<unsigned char>(bytes[i + 3]);
    };
    EXPECT_EQ(be32(16), 200);
    EXPECT_EQ(be32(20), 200);
    EXPECT_THROW(tprf::write_plot_png(path, {panel}, 0, 100), tprf::Error);
    EXPECT_THROW(tprf::write_plot_png(path, {panel}, 100, -3), tprf::Error);
    EXPECT_THROW(tprf::write_plot_png(path, {}, 100, 100), tprf::Error);
    EXPECT_THROW(tprf::render_plot({panel}, 100000, 100000), tprf::Error);
    EXPECT_FALSE(std::filesystem::exists(path));
}

}  // namespace
