#include "tprf/io/plot.h"

#include "tprf/core/error.h"
#include "tprf/io/image_io.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <string_view>

namespace tprf {

namespace {

using Rgb = std::array<std::uint8_t, 3>;

constexpr Rgb kWhite{255, 255, 255}, kInk{25, 25, 25}, kGrid{228, 228, 228}, kLegendEdge{160, 160, 160};

/// Default series colours, by series index.
constexpr std::array<Rgb, 10> kPalette{{{31, 119, 180}, {255, 127, 14}, {44, 160, 44}, {214, 39, 40},
                                        {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {127, 127, 127},
                                        {188, 189, 34}, {23, 190, 207}}};

/// Bitmap font for ASCII 32..126, drawn for tprf: 5 columns x 9 rows per glyph, one byte per row from the
/// top, bit 4 the leftmost column. Rows 0..6 are the cap height (the baseline is under row 6), rows 7..8
/// hold descenders. Characters advance by 6 columns.
constexpr std::uint8_t kFont[95][9] = {
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00},  // space
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04, 0x00, 0x00},  // !
    {0x0a, 0x0a, 0x0a, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00},  // "
    {0x0a, 0x0a, 0x1f, 0x0a, 0x1f, 0x0a, 0x0a, 0x00, 0x00},  // #
    {0x04, 0x0f, 0x14, 0x0e, 0x05, 0x1e, 0x04, 0x00, 0x00},  // $
    {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03, 0x00, 0x00},  // %
    {0x0c, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0d, 0x00, 0x00},  // &
    {0x04, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00},  // quote
    {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02, 0x00, 0x00},  // (
    {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08, 0x00, 0x00},  // )
    {0x00, 0x04, 0x15, 0x0e, 0x15, 0x04, 0x00, 0x00, 0x00},  // *
    {0x00, 0x04, 0x04, 0x1f, 0x04, 0x04, 0x00, 0x00, 0x00},  // +
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x04, 0x08, 0x00},  // ,
    {0x00, 0x00, 0x00, 0x1f, 0x00, 0x00, 0x00, 0x00, 0x00},  // -
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c, 0x00, 0x00},  // .
    {0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10, 0x00, 0x00},  // /
    {0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e, 0x00, 0x00},  // 0
    {0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e, 0x00, 0x00},  // 1
    {0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f, 0x00, 0x00},  // 2
    {0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e, 0x00, 0x00},  // 3
    {0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02, 0x00, 0x00},  // 4
    {0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e, 0x00, 0x00},  // 5
    {0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e, 0x00, 0x00},  // 6
    {0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08, 0x00, 0x00},  // 7
    {0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e, 0x00, 0x00},  // 8
    {0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c, 0x00, 0x00},  // 9
    {0x00, 0x0c, 0x0c, 0x00, 0x0c, 0x0c, 0x00, 0x00, 0x00},  // :
    {0x00, 0x0c, 0x0c, 0x00, 0x0c, 0x04, 0x08, 0x00, 0x00},  // ;
    {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02, 0x00, 0x00},  // <
    {0x00, 0x00, 0x1f, 0x00, 0x1f, 0x00, 0x00, 0x00, 0x00},  // =
    {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08, 0x00, 0x00},  // >
    {0x0e, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04, 0x00, 0x00},  // ?
    {0x0e, 0x11, 0x17, 0x15, 0x17, 0x10, 0x0f, 0x00, 0x00},  // @
    {0x0e, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11, 0x00, 0x00},  // A
    {0x1e, 0x11, 0x11, 0x1e, 0x11, 0x11, 0x1e, 0x00, 0x00},  // B
    {0x0e, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0e, 0x00, 0x00},  // C
    {0x1c, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1c, 0x00, 0x00},  // D
    {0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x1f, 0x00, 0x00},  // E
    {0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x10, 0x00, 0x00},  // F
    {0x0e, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0f, 0x00, 0x00},  // G
    {0x11, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11, 0x00, 0x00},  // H
    {0x0e, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e, 0x00, 0x00},  // I
    {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0c, 0x00, 0x00},  // J
    {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11, 0x00, 0x00},  // K
    {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f, 0x00, 0x00},  // L
    {0x11, 0x1b, 0x15, 0x15, 0x11, 0x11, 0x11, 0x00, 0x00},  // M
    {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11, 0x00, 0x00},  // N
    {0x0e, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e, 0x00, 0x00},  // O
    {0x1e, 0x11, 0x11, 0x1e, 0x10, 0x10, 0x10, 0x00, 0x00},  // P
    {0x0e, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0d, 0x00, 0x00},  // Q
    {0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11, 0x00, 0x00},  // R
    {0x0f, 0x10, 0x10, 0x0e, 0x01, 0x01, 0x1e, 0x00, 0x00},  // S
    {0x1f, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x00},  // T
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e, 0x00, 0x00},  // U
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x0a, 0x04, 0x00, 0x00},  // V
    {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0a, 0x00, 0x00},  // W
    {0x11, 0x11, 0x0a, 0x04, 0x0a, 0x11, 0x11, 0x00, 0x00},  // X
    {0x11, 0x11, 0x0a, 0x04, 0x04, 0x04, 0x04, 0x00, 0x00},  // Y
    {0x1f, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1f, 0x00, 0x00},  // Z
    {0x0e, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0e, 0x00, 0x00},  // [
    {0x10, 0x10, 0x08, 0x04, 0x02, 0x01, 0x01, 0x00, 0x00},  // backslash
    {0x0e, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0e, 0x00, 0x00},  // ]
    {0x04, 0x0a, 0x11, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00},  // ^
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1f, 0x00},  // _
    {0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00},  // `
    {0x00, 0x00, 0x0e, 0x01, 0x0f, 0x11, 0x0f, 0x00, 0x00},  // a
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1e, 0x00, 0x00},  // b
    {0x00, 0x00, 0x0e, 0x10, 0x10, 0x11, 0x0e, 0x00, 0x00},  // c
    {0x01, 0x01, 0x0d, 0x13, 0x11, 0x11, 0x0f, 0x00, 0x00},  // d
    {0x00, 0x00, 0x0e, 0x11, 0x1f, 0x10, 0x0e, 0x00, 0x00},  // e
    {0x06, 0x09, 0x08, 0x1c, 0x08, 0x08, 0x08, 0x00, 0x00},  // f
    {0x00, 0x00, 0x0f, 0x11, 0x11, 0x11, 0x0f, 0x01, 0x0e},  // g
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11, 0x00, 0x00},  // h
    {0x04, 0x00, 0x0c, 0x04, 0x04, 0x04, 0x0e, 0x00, 0x00},  // i
    {0x02, 0x00, 0x06, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0c},  // j
    {0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12, 0x00, 0x00},  // k
    {0x0c, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e, 0x00, 0x00},  // l
    {0x00, 0x00, 0x1a, 0x15, 0x15, 0x15, 0x15, 0x00, 0x00},  // m
    {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11, 0x00, 0x00},  // n
    {0x00, 0x00, 0x0e, 0x11, 0x11, 0x11, 0x0e, 0x00, 0x00},  // o
    {0x00, 0x00, 0x1e, 0x11, 0x11, 0x11, 0x1e, 0x10, 0x10},  // p
    {0x00, 0x00, 0x0f, 0x11, 0x11, 0x11, 0x0f, 0x01, 0x01},  // q
    {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10, 0x00, 0x00},  // r
    {0x00, 0x00, 0x0f, 0x10, 0x0e, 0x01, 0x1e, 0x00, 0x00},  // s
    {0x08, 0x08, 0x1c, 0x08, 0x08, 0x09, 0x06, 0x00, 0x00},  // t
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0d, 0x00, 0x00},  // u
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x0a, 0x04, 0x00, 0x00},  // v
    {0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0a, 0x00, 0x00},  // w
    {0x00, 0x00, 0x11, 0x0a, 0x04, 0x0a, 0x11, 0x00, 0x00},  // x
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x11, 0x0f, 0x01, 0x0e},  // y
    {0x00, 0x00, 0x1f, 0x02, 0x04, 0x08, 0x1f, 0x00, 0x00},  // z
    {0x03, 0x04, 0x04, 0x08, 0x04, 0x04, 0x03, 0x00, 0x00},  // {
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x00},  // |
    {0x18, 0x04, 0x04, 0x02, 0x04, 0x04, 0x18, 0x00, 0x00},  // }
    {0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00, 0x00, 0x00},  // ~
};

constexpr int kGlyphRows = 9, kAdvance = 6, kCap = 7;

int text_width(std::string_view text, int scale) {
    if (text.empty()) return 0;
    return static_cast<int>(std::min<std::size_t>(text.size(), 100000)) * kAdvance * scale - scale;
}

/// An RGB8 image with a clip rectangle that every drawing call respects.
struct Canvas {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;
    int cx0 = 0, cy0 = 0, cx1 = -1, cy1 = -1;  ///< clip rectangle, inclusive

    void clip(int x0, int y0, int x1, int y1) {
        cx0 = std::max(x0, 0);
        cy0 = std::max(y0, 0);
        cx1 = std::min(x1, width - 1);
        cy1 = std::min(y1, height - 1);
    }
    void fill(int x0, int y0, int x1, int y1, Rgb c) {
        for (int y = std::max(y0, cy0); y <= std::min(y1, cy1); ++y)
            for (int x = std::max(x0, cx0); x <= std::min(x1, cx1); ++x) {
                std::uint8_t* p = &rgb[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + x) * 3];
                p[0] = c[0];
                p[1] = c[1];
                p[2] = c[2];
            }
    }
    /// Pixels inside the rectangle (clipped to the image) that are neither background nor grid.
    int ink(int x0, int y0, int x1, int y1) const {
        int n = 0;
        for (int y = std::max(y0, 0); y <= std::min(y1, height - 1); ++y)
            for (int x = std::max(x0, 0); x <= std::min(x1, width - 1); ++x) {
                const std::uint8_t* p = &rgb[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + x) * 3];
                const Rgb c{p[0], p[1], p[2]};
                n += c != kWhite && c != kGrid;
            }
        return n;
    }
};

int to_pixel(double v) { return static_cast<int>(std::lround(std::clamp(v, -1e8, 1e8))); }

/// A square pen of `pen` pixels centred (to the pixel) on (x, y).
void dot(Canvas& c, int x, int y, int pen, Rgb col) {
    c.fill(x - (pen - 1) / 2, y - (pen - 1) / 2, x + pen / 2, y + pen / 2, col);
}

/// A segment between pixel-centre coordinates, clipped (Liang-Barsky) before it is rasterised (Bresenham),
/// so that far-off points cost nothing.
void line(Canvas& c, double x0, double y0, double x1, double y1, int pen, Rgb col) {
    x0 = std::clamp(x0, -1e9, 1e9), y0 = std::clamp(y0, -1e9, 1e9);
    x1 = std::clamp(x1, -1e9, 1e9), y1 = std::clamp(y1, -1e9, 1e9);
    const double dx = x1 - x0, dy = y1 - y0;
    const double p[4] = {-dx, dx, -dy, dy};
    const double q[4] = {x0 - (c.cx0 - 0.5), (c.cx1 + 0.5) - x0, y0 - (c.cy0 - 0.5), (c.cy1 + 0.5) - y0};
    double t0 = 0.0, t1 = 1.0;
    for (int i = 0; i < 4; ++i) {
        if (p[i] == 0.0) {
            if (q[i] < 0.0) return;
        } else if (p[i] < 0.0) {
            t0 = std::max(t0, q[i] / p[i]);
        } else {
            t1 = std::min(t1, q[i] / p[i]);
        }
    }
    if (t0 > t1) return;
    int ax = to_pixel(x0 + t0 * dx), ay = to_pixel(y0 + t0 * dy);
    const int bx = to_pixel(x0 + t1 * dx), by = to_pixel(y0 + t1 * dy);
    const int ex = std::abs(bx - ax), ey = -std::abs(by - ay), sx = ax < bx ? 1 : -1, sy = ay < by ? 1 : -1;
    for (int err = ex + ey;;) {
        dot(c, ax, ay, pen, col);
        if (ax == bx && ay == by) break;
        const int e2 = 2 * err;
        if (e2 >= ey) err += ey, ax += sx;
        if (e2 <= ex) err += ex, ay += sy;
    }
}

/// Text with its top-left corner at (x, y), glyphs scaled by `scale`; `vertical`: turned a quarter turn
/// anticlockwise (read bottom to top), (x, y) then being its bottom-left corner.
void text(Canvas& c, int x, int y, std::string_view t, int scale, Rgb col, bool vertical = false) {
    for (std::size_t i = 0; i < t.size() && i < 100000; ++i) {
        const unsigned code = static_cast<unsigned char>(t[i]);
        const std::uint8_t* glyph = kFont[(code < 32 || code > 126 ? '?' : code) - 32];
        for (int gy = 0; gy < kGlyphRows; ++gy)
            for (int gx = 0; gx < 5; ++gx) {
                if (!((glyph[gy] >> (4 - gx)) & 1)) continue;
                const int u = (static_cast<int>(i) * kAdvance + gx) * scale, v = gy * scale;
                if (vertical)
                    c.fill(x + v, y - u - scale + 1, x + v + scale - 1, y - u, col);
                else
                    c.fill(x + u, y + v, x + u + scale - 1, y + v + scale - 1, col);
            }
    }
}

bool placeable(double v, AxisScale scale) { return std::isfinite(v) && (scale == AxisScale::Linear || v > 0.0); }

/// Where v lies along [lo, hi]: 0 at lo, 1 at hi; NaN when v cannot be placed.
double fraction(double v, double lo, double hi, AxisScale scale) {
    if (!placeable(v, scale)) return std::numeric_limits<double>::quiet_NaN();
    if (scale == AxisScale::Log) return (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo));
    return (v - lo) / (hi - lo);
}

double fx(const PlotFrame& f, double x) { return f.left + fraction(x, f.x0, f.x1, f.xs) * (f.right - f.left); }
double fy(const PlotFrame& f, double y) { return f.bottom - fraction(y, f.y0, f.y1, f.ys) * (f.bottom - f.top); }

/// Whether [a, b] can be an axis: placeable, ordered, and wide enough for distinct tick labels.
bool usable(double a, double b, AxisScale scale) {
    if (!placeable(a, scale) || !placeable(b, scale) || !(a < b)) return false;
    if (scale == AxisScale::Log) return std::log10(b) - std::log10(a) > 1e-6;
    const double magnitude = std::max(std::fabs(a), std::fabs(b));
    return magnitude <= 1e300 && b - a > 1e-9 * magnitude && b - a > 1e-290;
}

struct Extent {
    double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
};

std::pair<double, double> axis_range(const Extent& e, AxisScale scale,
                                     const std::optional<std::pair<double, double>>& user) {
    if (user) {
        const auto [a, b] = std::minmax(user->first, user->second);
        if (usable(a, b, scale)) return {a, b};
    }
    if (e.lo > e.hi) return scale == AxisScale::Log ? std::pair{1.0, 10.0} : std::pair{0.0, 1.0};
    if (scale == AxisScale::Log) {
        // Decades whose powers of ten stay normal doubles.
        const double d0 = std::clamp(std::floor(std::log10(e.lo)), -307.0, 307.0);
        const double d1 = std::clamp(std::ceil(std::log10(e.hi)), d0 + 1.0, 308.0);
        return {std::pow(10.0, d0), std::pow(10.0, d1)};
    }
    // Halves, so that neither the middle nor the span can overflow.
    const double lo = std::clamp(e.lo, -1e300, 1e300), hi = std::clamp(e.hi, -1e300, 1e300);
    const double mid = 0.5 * lo + 0.5 * hi;
    double half = 0.5 * hi - 0.5 * lo;
    if (usable(lo, hi, scale))
        half *= 1.05;
    else  // all equal (or nearly): a band of 10% of the value around it
        half = mid == 0.0 ? 1.0 : std::max(0.1 * std::fabs(mid), 1e-280);
    return {mid - half, mid + half};
}

struct Tick {
    double value;
    std::string label;  ///< empty: a minor tick
};

/// Smallest 1, 2 or 5 times a power of ten that is at least `raw`.
double nice_step(double raw) {
    const double p = std::pow(10.0, std::floor(std::log10(raw)));
    for (const double m : {1.0, 2.0, 5.0})
        if (m * p >= raw * (1.0 - 1e-9)) return m * p;
    return 10.0 * p;
}

/// A multiple of `step`: fixed point for moderate axes, else like 2.5e6 (digits as many as the step needs).
std::string linear_label(double v, double step, double magnitude) {
    const int step_exp = static_cast<int>(std::floor(std::log10(step) + 1e-9));
    if (std::fabs(v) < 1e-6 * step) v = 0.0;  // not "-2.8e-17" for a zero that rounding missed
    char buf[64];
    if (magnitude >= 1e-2 && magnitude < 1e6) {
        std::snprintf(buf, sizeof buf, "%.*f", std::clamp(-step_exp, 0, 20), v);
        return buf;
    }
    if (v == 0.0) return "0";
    const int e = static_cast<int>(std::floor(std::log10(std::fabs(v)) + 1e-9));
    std::snprintf(buf, sizeof buf, "%.*f", std::clamp(e - step_exp, 0, 15), v / std::pow(10.0, e));
    std::string mantissa = buf;
    if (mantissa.find('.') != std::string::npos) {  // 1.50 -> 1.5, 1.0 -> 1
        mantissa.erase(mantissa.find_last_not_of('0') + 1);
        if (mantissa.back() == '.') mantissa.pop_back();
    }
    return mantissa + "e" + std::to_string(e);
}

/// Labelled multiples of the finest 1/2/5 step whose labels keep clear of each other along `pixels`.
std::vector<Tick> linear_ticks(double lo, double hi, double pixels, bool horizontal, int scale) {
    const double magnitude = std::max(std::fabs(lo), std::fabs(hi));
    std::vector<Tick> best;
    double step = nice_step((hi - lo) / std::max(2.0, pixels / (8.0 * scale)));  // fine, then coarser
    for (int attempt = 0; attempt < 40 && std::isfinite(step); ++attempt, step = nice_step(1.5 * step)) {
        const double first = std::ceil(lo / step - 1e-9), last = std::floor(hi / step + 1e-9);
        if (!(last - first <= 50.0)) continue;
        std::vector<Tick> ticks;
        int widest = 0;
        for (int i = 0; i <= static_cast<int>(last - first); ++i) {
            const double v = (first + i) * step;
            ticks.push_back({v, linear_label(v, step, magnitude)});
            widest = std::max(widest, text_width(ticks.back().label, scale));
        }
        if (ticks.size() < 2 && !best.empty()) break;  // coarser steps would leave the axis bare
        best = std::move(ticks);
        const double gap = pixels * step / (hi - lo);
        if (gap >= (horizontal ? widest + 3 * kAdvance * scale : 2 * kCap * scale)) break;
    }
    return best;
}

/// Decades labelled 1eN (every k-th where they would crowd), minor ticks at 2..9 when there is room.
std::vector<Tick> log_ticks(double lo, double hi, double pixels, bool horizontal, int scale) {
    const double a = std::log10(lo), b = std::log10(hi);
    const int d0 = static_cast<int>(std::ceil(a - 1e-9)), d1 = static_cast<int>(std::floor(b + 1e-9));
    if (d1 - d0 < 1) {  // under two decades in view: linear steps, placed on the log axis
        std::vector<Tick> ticks = linear_ticks(lo, hi, pixels, horizontal, scale);
        std::erase_if(ticks, [](const Tick& t) { return t.value <= 0.0; });
        return ticks;
    }
    const auto label = [](int d) { return "1e" + std::to_string(d); };
    const double decade_px = pixels / (b - a);
    const int widest = std::max(text_width(label(d0), scale), text_width(label(d1), scale));
    const double need = horizontal ? widest + 3 * kAdvance * scale : 2 * kCap * scale;
    const int stride = static_cast<int>(std::clamp(std::ceil(need / std::max(decade_px, 1e-3)), 1.0, 1000.0));
    std::vector<Tick> ticks;
    for (int d = d0; d <= d1; d += stride) ticks.push_back({std::pow(10.0, d), label(d)});
    if (stride == 1 && decade_px >= 12.0 * scale)
        for (int d = d0 - 1; d <= d1; ++d)
            for (int m = 2; m <= 9; ++m) {
                const double v = m * std::pow(10.0, d);
                if (v >= lo && v <= hi) ticks.push_back({v, ""});
            }
    return ticks;
}

std::vector<Tick> axis_ticks(double lo, double hi, AxisScale scale, int pixels, bool horizontal, int font) {
    return scale == AxisScale::Log ? log_ticks(lo, hi, pixels, horizontal, font)
                                   : linear_ticks(lo, hi, pixels, horizontal, font);
}

/// Text twice as large on figures big enough to hold it.
int font_scale(int width, int panel_height) { return width >= 600 && panel_height >= 200 ? 2 : 1; }

int tick_length(int scale) { return 3 * scale + 2; }

struct Layout {
    PlotFrame frame;
    std::vector<Tick> x_ticks, y_ticks;
};

Layout make_layout(const PlotPanel& panel, int width, int panel_height) {
    Extent ex, ey;
    for (const PlotSeries& s : panel.series)
        for (std::size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i)
            if (placeable(s.x[i], panel.x_scale) && placeable(s.y[i], panel.y_scale)) {
                ex.lo = std::min(ex.lo, s.x[i]), ex.hi = std::max(ex.hi, s.x[i]);
                ey.lo = std::min(ey.lo, s.y[i]), ey.hi = std::max(ey.hi, s.y[i]);
            }
    const auto [x0, x1] = axis_range(ex, panel.x_scale, panel.x_range);
    const auto [y0, y1] = axis_range(ey, panel.y_scale, panel.y_range);
    const int font = font_scale(width, panel_height), rows = kGlyphRows * font, tick = tick_length(font);
    Layout l{{x0, x1, y0, y1, panel.x_scale, panel.y_scale, 0, width - 1, 0, panel_height - 1}, {}, {}};
    PlotFrame& f = l.frame;
    f.top = (panel.title.empty() ? 8 : 8 + kGlyphRows) * font;
    f.bottom = panel_height - 1 - (tick + 5 * font + rows + (panel.x_label.empty() ? 0 : 2 * font + rows));
    if (f.bottom - f.top < 8) f.top = 0, f.bottom = panel_height - 1;  // too small for text: all plot
    l.y_ticks = axis_ticks(y0, y1, f.ys, f.bottom - f.top, false, font);
    int widest = 0;
    for (const Tick& t : l.y_ticks) widest = std::max(widest, text_width(t.label, font));
    f.left = 4 * font + (panel.y_label.empty() ? 0 : rows + 3 * font) + std::min(widest, width / 3) + 2 * font + tick;
    f.right = width - 1 - 12 * font;
    if (f.right - f.left < 8) f.left = 0, f.right = width - 1;
    l.x_ticks = axis_ticks(x0, x1, f.xs, f.right - f.left, true, font);
    return l;
}

Rgb series_color(const PlotSeries& s, std::size_t index) {
    return s.color == Rgb{0, 0, 0} ? kPalette[index % kPalette.size()] : s.color;
}

void draw_series(Canvas& c, const PlotFrame& f, const PlotSeries& s, Rgb col, int font) {
    bool joined = false;  // whether (px, py) holds the previous point of an unbroken run
    double px = 0.0, py = 0.0;
    for (std::size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
        const double x = fx(f, s.x[i]), y = fy(f, s.y[i]);
        if (std::isnan(x) || std::isnan(y)) {
            joined = false;
            continue;
        }
        if (s.style == SeriesStyle::Markers) {
            c.fill(to_pixel(x) - font - 1, to_pixel(y) - font - 1, to_pixel(x) + font + 1, to_pixel(y) + font + 1, col);
        } else if (joined && s.style == SeriesStyle::Line) {
            line(c, px, py, x, y, font, col);
        } else if (joined) {
            line(c, px, py, x, py, font, col);
            line(c, x, py, x, y, font, col);
        }
        joined = true, px = x, py = y;
    }
}

/// The legend goes in the corner of the plot area with the least ink under it; the series are drawn by then.
void draw_legend(Canvas& c, const PlotFrame& f, const PlotPanel& panel, int font) {
    std::vector<std::size_t> shown;
    int widest = 0;
    for (std::size_t i = 0; i < panel.series.size(); ++i)
        if (!panel.series[i].label.empty()) {
            shown.push_back(i);
            widest = std::max(widest, text_width(panel.series[i].label, font));
        }
    if (shown.empty()) return;
    const int pad = 4 * font, sample = 14 * font, row = (kGlyphRows + 3) * font, inset = 4 * font;
    const int gap = 5 * font, w = pad + sample + gap + widest + pad;
    const int h = 2 * pad + static_cast<int>(std::min<std::size_t>(shown.size(), 1000)) * row - 3 * font;
    const int xs[2] = {f.right - inset - w + 1, f.left + inset}, ys[2] = {f.top + inset, f.bottom - inset - h + 1};
    int bx = xs[0], by = ys[0], least = std::numeric_limits<int>::max();
    for (const int y : ys)
        for (const int x : xs)
            if (const int n = c.ink(x, y, x + w - 1, y + h - 1); n < least) least = n, bx = x, by = y;
    c.fill(bx, by, bx + w - 1, by + h - 1, kLegendEdge);
    c.fill(bx + 1, by + 1, bx + w - 2, by + h - 2, kWhite);
    for (std::size_t k = 0; k < shown.size() && k < 1000; ++k) {
        const PlotSeries& s = panel.series[shown[k]];
        const Rgb col = series_color(s, shown[k]);
        const int x0 = bx + pad, x1 = x0 + sample, y = by + pad + static_cast<int>(k) * row, mid = y + kCap * font / 2;
        if (s.style == SeriesStyle::Markers)
            c.fill((x0 + x1) / 2 - font - 1, mid - font - 1, (x0 + x1) / 2 + font + 1, mid + font + 1, col);
        else if (s.style == SeriesStyle::Line)
            line(c, x0, mid, x1, mid, font, col);
        else
            for (const auto& [a, b, u, v] : {std::array{x0, mid + 2 * font, (x0 + x1) / 2, mid + 2 * font},
                                             std::array{(x0 + x1) / 2, mid + 2 * font, (x0 + x1) / 2, mid - 2 * font},
                                             std::array{(x0 + x1) / 2, mid - 2 * font, x1, mid - 2 * font}})
                line(c, a, b, u, v, font, col);
        text(c, x1 + gap, y, s.label, font, kInk);
    }
}

void draw_panel(Canvas& c, const PlotPanel& panel, int width, int panel_height, int top) {
    Layout l = make_layout(panel, width, panel_height);
    PlotFrame& f = l.frame;
    f.top += top, f.bottom += top;
    const int font = font_scale(width, panel_height), tick = tick_length(font), rows = kGlyphRows * font;
    c.clip(0, top, width - 1, top + panel_height - 1);
    for (const Tick& t : l.x_ticks)
        if (!t.label.empty()) c.fill(to_pixel(fx(f, t.value)), f.top, to_pixel(fx(f, t.value)), f.bottom, kGrid);
    for (const Tick& t : l.y_ticks)
        if (!t.label.empty()) c.fill(f.left, to_pixel(fy(f, t.value)), f.right, to_pixel(fy(f, t.value)), kGrid);

    c.clip(f.left, f.top, f.right, f.bottom);
    for (std::size_t i = 0; i < panel.series.size(); ++i)
        draw_series(c, f, panel.series[i], series_color(panel.series[i], i), font);

    c.clip(0, top, width - 1, top + panel_height - 1);
    c.fill(f.left, f.top, f.right, f.top, kInk);
    c.fill(f.left, f.bottom, f.right, f.bottom, kInk);
    c.fill(f.left, f.top, f.left, f.bottom, kInk);
    c.fill(f.right, f.top, f.right, f.bottom, kInk);
    for (const Tick& t : l.x_ticks) {
        const int x = to_pixel(fx(f, t.value)), w = text_width(t.label, font);
        if (x < f.left || x > f.right) continue;
        c.fill(x, f.bottom + 1, x, f.bottom + (t.label.empty() ? tick / 2 : tick), kInk);
        text(c, std::clamp(x - w / 2, 0, std::max(0, width - w)), f.bottom + tick + 2 * font, t.label, font, kInk);
    }
    for (const Tick& t : l.y_ticks) {
        const int y = to_pixel(fy(f, t.value)), w = text_width(t.label, font);
        if (y < f.top || y > f.bottom) continue;
        c.fill(f.left - (t.label.empty() ? tick / 2 : tick), y, f.left - 1, y, kInk);
        text(c, f.left - tick - 2 * font - w, y - kCap * font / 2, t.label, font, kInk);
    }
    const int centre_x = (f.left + f.right) / 2, centre_y = (f.top + f.bottom) / 2;
    const int title_w = text_width(panel.title, font), x_label_w = text_width(panel.x_label, font);
    text(c, std::clamp(centre_x - title_w / 2, 0, std::max(0, width - title_w)), top + 4 * font, panel.title, font,
         kInk);
    text(c, std::clamp(centre_x - x_label_w / 2, 0, std::max(0, width - x_label_w)),
         f.bottom + tick + 4 * font + rows, panel.x_label, font, kInk);
    text(c, 4 * font, std::min(centre_y + text_width(panel.y_label, font) / 2, top + panel_height - 1), panel.y_label,
         font, kInk, true);
    draw_legend(c, f, panel, font);
}

}  // namespace

int PlotFrame::px(double x) const {
    const double v = fx(*this, x);
    return std::isnan(v) ? -1 : to_pixel(v);
}

int PlotFrame::py(double y) const {
    const double v = fy(*this, y);
    return std::isnan(v) ? -1 : to_pixel(v);
}

PlotFrame plot_frame(const PlotPanel& panel, int width, int panel_height) {
    return make_layout(panel, width, panel_height).frame;
}

std::vector<std::uint8_t> render_plot(const std::vector<PlotPanel>& panels, int width, int panel_height) {
    if (width <= 0 || panel_height <= 0)
        throw Error("cannot plot panels of " + std::to_string(width) + " x " + std::to_string(panel_height) +
                    " pixels");
    // A gigabyte: far beyond any figure, and the image height then fits an int.
    if (3.0 * width * panel_height * static_cast<double>(panels.size()) > 1e9)
        throw Error("a plot of " + std::to_string(panels.size()) + " panels of " + std::to_string(width) + " x " +
                    std::to_string(panel_height) + " pixels is too large");
    Canvas c;
    c.width = width;
    c.height = static_cast<int>(panels.size()) * panel_height;
    c.rgb.assign(static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height) * 3, 255);
    for (std::size_t k = 0; k < panels.size(); ++k)
        draw_panel(c, panels[k], width, panel_height, static_cast<int>(k) * panel_height);
    return std::move(c.rgb);
}

void write_plot_png(const std::filesystem::path& path, const std::vector<PlotPanel>& panels, int width,
                    int panel_height) {
    if (panels.empty()) fail_input(path, "", "no panels to plot");
    if (width <= 0 || panel_height <= 0)
        fail_input(path, "", "cannot plot panels of " + std::to_string(width) + " x " + std::to_string(panel_height) +
                                 " pixels");
    const std::vector<std::uint8_t> rgb = render_plot(panels, width, panel_height);
    write_png(path, width, static_cast<int>(panels.size()) * panel_height, rgb.data());
}

}  // namespace tprf
