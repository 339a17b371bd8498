// The sensor, film, sampler and integrator of a Mitsuba 3 scene (scene/parse_mitsuba.h): tprf's camera,
// time axis and bounce limit.
#include "mitsuba_xml.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <string_view>

namespace tprf::mitsuba {

namespace {

constexpr double kDegrees = std::numbers::pi / 180.0;
// How far from orthonormal a camera's to_world columns may be (their dot products and lengths).
constexpr double kRotationTolerance = 1e-5;

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

// Mitsuba's fov of axis `axis` as tprf's vertical fov, in degrees. Where the axis is the vertical one,
// or the image is square, the number is kept as written (no round trip through tan and atan).
double vertical_fov(Props& p, double fov, std::string axis, int width, int height) {
    const double aspect = double(width) / double(height);
    if (axis == "smaller") axis = aspect > 1.0 ? "y" : "x";
    if (axis == "larger") axis = aspect > 1.0 ? "x" : "y";
    const double half = std::tan(0.5 * fov * kDegrees);
    if (axis == "y" || (axis == "x" && width == height)) return fov;
    if (axis == "x") return 2.0 * std::atan(half / aspect) / kDegrees;
    if (axis == "diagonal") return 2.0 * std::atan(half * height / std::hypot(double(width), double(height))) / kDegrees;
    p.source().fail(p.find("fov_axis"), "unknown fov_axis \"" + axis + "\" (expected x, y, smaller, larger or diagonal)");
}

// Mitsuba's camera looks along its +z with +y up, and its +x points to the image's left: tprf's pinhole
// (right = forward x up) sees the same image from position M(0,0,0), forward M's +z, up M's +y when M is
// a rotation and a translation. Exported cameras write their matrices to six or so digits: columns
// orthonormal to 1e-5 count as a rotation. A mirroring M (negative determinant) keeps its image's left
// column looking along M's +x, which is then the frame's right: the image is mirrored (Camera::mirrored),
// as Mitsuba renders it.
void set_pose(Props& p, const Eigen::Matrix4d& m, Camera& camera) {
    const pugi::xml_node where = p.find("to_world") ? p.find("to_world") : p.node();
    const Eigen::Matrix3d l = m.block<3, 3>(0, 0);
    if (m.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) p.source().fail(where, "is not affine (last row 0 0 0 1)");
    const double off = (l.transpose() * l - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (!(off <= 2.0 * kRotationTolerance)) {
        char text[200];
        std::snprintf(text, sizeof text,
                      "has a scale or shear (its columns are orthonormal to %.2g, not %g): a camera's to_world must be "
                      "a rotation, or a mirror, and a translation",
                      0.5 * off, kRotationTolerance);
        p.source().fail(where, text);
    }
    camera.position = m.block<3, 1>(0, 3);
    camera.look_at = camera.position + l.col(2).normalized();
    camera.up = l.col(1).normalized();
    camera.mirrored = l.determinant() < 0.0;
}

int positive(Props& p, std::string_view name, int fallback) {
    const int v = p.integer(name).value_or(fallback);
    if (v <= 0) p.source().fail(p.find(name), "must be > 0");
    return v;
}

// <sampler>: only its sample count matters (tprf samples pixels on a fixed pattern, docs/scene.md).
int parse_sampler(const XmlSource& src, const pugi::xml_node& node) {
    Props p(src, node);
    const std::string type = p.type();
    if (type != "independent" && type != "stratified" && type != "multijitter" && type != "orthogonal" &&
        type != "ldsampler")
        p.fail("unsupported sampler type \"" + type + "\"");
    const int spp = positive(p, "sample_count", 4);
    p.integer("seed");  // tprf's pattern has no seed
    p.finish();
    return spp;
}

// <film type="transient_hdr_film">: the image size and the time axis, in the scene's length unit.
void parse_film(const XmlSource& src, const pugi::xml_node& node, Camera& camera, TimeAxis& time) {
    Props p(src, node);
    if (p.type() != "transient_hdr_film")
        p.fail("unsupported film type \"" + p.type() +
               "\": tprf needs a time axis, from mitransient's \"transient_hdr_film\" (temporal_bins, bin_width_opl)");
    camera.width = positive(p, "width", 768);
    camera.height = positive(p, "height", 576);
    time.bins = positive(p, "temporal_bins", 2048);
    time.bin_width = p.number("bin_width_opl").value_or(0.003);
    if (!(time.bin_width > 0.0)) src.fail(p.find("bin_width_opl"), "must be > 0");
    time.start = p.number("start_opl").value_or(0.0);
    time.unit = TimeUnit::Metres;
    for (const pugi::xml_node& f : p.objects({"rfilter"})) {
        Props filter(src, f);
        if (filter.type() != "box") filter.fail("tprf's film is a box filter: only type \"box\"");
        filter.finish();
    }
    p.finish();
}

}  // namespace

void parse_sensor(const XmlSource& src, const pugi::xml_node& node, Scene& scene) {
    Props p(src, node);
    if (p.type() != "perspective") p.fail("unsupported sensor type \"" + p.type() + "\" (tprf reads \"perspective\")");
    Camera camera;
    const auto fov = p.number("fov");
    if (!fov) p.fail("missing <float name=\"fov\"> (degrees)");
    if (!(*fov > 0.0 && *fov < 180.0)) src.fail(p.find("fov"), "must lie in (0, 180) degrees");
    const std::string axis = lower(p.string("fov_axis").value_or("x"));
    for (const char* ignored : {"near_clip", "far_clip", "focus_distance"}) p.number(ignored);
    for (const char* offset : {"principal_point_offset_x", "principal_point_offset_y"})
        if (p.number(offset).value_or(0.0) != 0.0)
            src.fail(p.find(offset), "tprf's pinhole has its principal point at the image centre: only 0");
    set_pose(p, p.transform("to_world").value_or(Eigen::Matrix4d::Identity()), camera);
    const std::vector<pugi::xml_node> samplers = p.objects({"sampler"});
    const std::vector<pugi::xml_node> films = p.objects({"film"});
    if (samplers.size() > 1) src.fail(samplers[1], "a second <sampler>");
    if (films.size() != 1) p.fail("needs one <film type=\"transient_hdr_film\">");
    if (!samplers.empty()) camera.spp = parse_sampler(src, samplers.front());
    else camera.spp = 4;  // Mitsuba's default sampler takes 4 samples per pixel
    parse_film(src, films.front(), camera, scene.time);
    p.finish();
    camera.fov_deg = vertical_fov(p, *fov, axis, camera.width, camera.height);
    scene.camera = camera;
}

void parse_integrator(const XmlSource& src, const pugi::xml_node& node, Scene& scene, bool& unwarp) {
    Props p(src, node);
    const std::string type = p.type();
    if (type != "transient_path" && type != "path")
        p.fail("unsupported integrator type \"" + type + "\" (tprf reads \"transient_path\" and \"path\"" +
               (type.find("nlos") != std::string::npos ? "; NLOS scans are tprf's JSON `capture` block" : "") + ")");
    const int depth = p.integer("max_depth").value_or(-1);
    if (depth == 0 || depth < -1) src.fail(p.find("max_depth"), "must be -1 (all bounces) or >= 1");
    scene.solver.max_bounces = depth == -1 ? -1 : depth - 1;
    p.integer("rr_depth");  // Russian roulette changes the noise of a sampler, not what tprf computes
    if (type == "transient_path") {
        unwarp = p.boolean("camera_unwarp").value_or(false);
        const std::string filter = lower(p.string("temporal_filter").value_or("box"));
        if (filter != "box" && !filter.empty())
            src.fail(p.find("temporal_filter"), "tprf bins time with a box: only \"box\"");
        p.number("gaussian_stddev");  // used by a gaussian temporal filter only
    }
    p.finish();
}

}  // namespace tprf::mitsuba
