// Mitsuba 3 XML scenes (docs/mitsuba.md): every element and attribute of
// the subset against an answer fixed by Mitsuba's definitions, the errors, and meshes/cornell-box.xml
// against meshes/cornell-box.json.
#include "tprf/core/error.h"
#include "tprf/imaging/camera.h"
#include "tprf/io/npy.h"
#include "tprf/pipeline/render.h"
#include "tprf/scene/parse_json.h"
#include "tprf/scene/parse_mitsuba.h"

#include "test_process.h"
#include "test_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <variant>
#include <vector>

namespace {

namespace fs = std::filesystem;
using tprf::Vec3;

const fs::path kSource(TPRF_SOURCE_DIR);

struct TempDir : tprf::test::MeshDir {
    TempDir() : tprf::test::MeshDir("tprf_mitsuba_test_") {}
};

// A sensor and film that every scene below can share, around `body` (one rectangle when empty), which
// starts on line 12.
std::string scene_xml(const std::string& body, const std::string& sensor_extra = "") {
    return R"(<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>)" +
           sensor_extra + R"(
    <film type="transient_hdr_film">
      <integer name="width" value="8"/>
      <integer name="height" value="8"/>
      <integer name="temporal_bins" value="16"/>
      <float name="bin_width_opl" value="0.1"/>
    </film>
  </sensor>
)" + (body.empty() ? "<shape type=\"rectangle\"/>" : body) + "\n</scene>\n";
}

tprf::Scene parse(const std::string& text, const TempDir& dir, const tprf::XmlDefines& defines = {}) {
    return tprf::parse_mitsuba_scene(text, dir.path / "scene.xml", defines);
}

// The message of the Error that parsing `text` throws ("" when it parses).
std::string error_of(const std::string& text, const TempDir& dir, const tprf::XmlDefines& defines = {}) {
    try {
        parse(text, dir, defines);
    } catch (const tprf::Error& e) {
        return e.what();
    }
    return "";
}

const tprf::RectangleShape& rect(const tprf::Object& o) { return std::get<tprf::RectangleShape>(o.shape); }
const tprf::MeshShape& mesh(const tprf::Object& o) { return std::get<tprf::MeshShape>(o.shape); }
Vec3 normal(const tprf::RectangleShape& r) { return r.u.cross(r.v).normalized(); }

const std::string kWhite = R"(<bsdf type="diffuse"><float name="reflectance" value="0.5"/></bsdf>)";

}  // namespace

// Mitsuba's rectangle is [-1, 1]^2 at z = 0 with its front +z: scale (2, 3) then translate (1, 2, 3)
// puts corner (-1, -1) at (-1, -1, 3), with edges 4 along x and 6 along y.
TEST(Mitsuba, RectangleCornersAreTheMappedUnitSquare) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(<shape type="rectangle"><transform name="to_world">
        <scale x="2" y="3"/><translate value="1 2 3"/></transform></shape>)"),
                                dir);
    ASSERT_EQ(s.objects.size(), 1u);
    const tprf::RectangleShape& r = rect(s.objects[0]);
    EXPECT_EQ(r.origin, Vec3(-1, -1, 3));
    EXPECT_EQ(r.u, Vec3(4, 0, 0));
    EXPECT_EQ(r.v, Vec3(0, 6, 0));
    EXPECT_EQ(s.objects[0].albedo.matrix(), Vec3::Constant(0.5));  // Mitsuba's default BSDF
    EXPECT_EQ(s.objects[0].json_path, "shape at line 12");
}

// Mitsuba transforms a rectangle's normal by the inverse transpose: a mirror in x keeps it +z (while
// u x v of the mapped corners would turn to -z), a mirror in z turns it to -z.
TEST(Mitsuba, MirroredRectangleKeepsMitsubasFront) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(
      <shape type="rectangle"><transform name="to_world"><scale x="-1"/></transform></shape>
      <shape type="rectangle"><transform name="to_world"><scale z="-1"/></transform></shape>)"),
                                dir);
    EXPECT_TRUE(normal(rect(s.objects[0])).isApprox(Vec3(0, 0, 1)));
    EXPECT_TRUE(normal(rect(s.objects[1])).isApprox(Vec3(0, 0, -1)));
}

// Mitsuba's cube is [-1, 1]^3 with outward normals: scaled by 0.5 and moved to (1, 1, 1), six unit
// squares whose centres sit 0.5 from (1, 1, 1) along their outward normals.
TEST(Mitsuba, CubeIsSixOutwardUnitFaces) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(<shape type="cube"><transform name="to_world">
        <scale value="0.5"/><translate value="1"/></transform>)" + kWhite + "</shape>"),
                                dir);
    ASSERT_EQ(s.objects.size(), 6u);
    std::vector<Vec3> normals;
    for (const tprf::Object& o : s.objects) {
        const tprf::RectangleShape& r = rect(o);
        EXPECT_DOUBLE_EQ(r.u.norm(), 1.0);
        EXPECT_DOUBLE_EQ(r.v.norm(), 1.0);
        const Vec3 n = normal(r);
        const Vec3 centre = r.origin + 0.5 * (r.u + r.v);
        EXPECT_TRUE((centre - Vec3(1, 1, 1)).isApprox(0.5 * n)) << o.json_path;
        normals.push_back(n);
    }
    EXPECT_TRUE(normals[0].isApprox(Vec3(1, 0, 0)));
    EXPECT_TRUE(normals[1].isApprox(Vec3(-1, 0, 0)));
    EXPECT_TRUE(normals[5].isApprox(Vec3(0, 0, -1)));
    EXPECT_NE(s.objects[0].json_path.find("cube face +x"), std::string::npos);
}

// Each operation applies after the ones above it: translate then rotate 90 degrees about z takes the
// origin to (0, 1, 0); rotate then translate takes it to (1, 0, 0). A matrix is row-major.
TEST(Mitsuba, TransformsComposeInDocumentOrder) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(
      <shape type="obj"><string name="filename" value="meshes/tri.obj"/>
        <transform name="to_world"><translate x="1"/><rotate z="1" angle="90"/></transform></shape>
      <shape type="obj"><string name="filename" value="meshes/tri.obj"/>
        <transform name="to_world"><rotate value="0 0 1" angle="90"/><translate x="1"/></transform></shape>
      <shape type="ply"><string name="filename" value="meshes/tri.obj"/>
        <transform name="to_world"><matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/></transform></shape>)"),
                                dir);
    const auto origin = [](const tprf::Object& o) { return Vec3(mesh(o).transform.block<3, 1>(0, 3)); };
    EXPECT_TRUE(origin(s.objects[0]).isApprox(Vec3(0, 1, 0)));
    EXPECT_LT(std::abs(origin(s.objects[0]).x()), 1e-15);
    EXPECT_EQ(origin(s.objects[1]), Vec3(1, 0, 0));
    EXPECT_EQ(origin(s.objects[2]), Vec3(5, 6, 7));
    EXPECT_EQ(mesh(s.objects[0]).file, dir.path / "meshes/tri.obj");
}

// fov_axis x (the default) is horizontal: on a 2:1 film, 90 degrees across is 2 atan(tan(45) / 2) =
// 53.1301 degrees vertically; y is vertical; smaller is y and larger is x on a wide film; diagonal: 2
// atan(tan(45) * 1 / sqrt(5)) = 48.1897 degrees.
TEST(Mitsuba, FovAxisBecomesTheVerticalFov) {
    TempDir dir;
    const auto vertical = [&](const std::string& axis) {
        std::string xml = scene_xml("", axis.empty() ? "" : "<string name=\"fov_axis\" value=\"" + axis + "\"/>");
        xml.replace(xml.find("value=\"40\""), 10, "value=\"90\"");
        xml.replace(xml.find("name=\"width\" value=\"8\""), 22, "name=\"width\" value=\"16\"");
        return parse(xml, dir).camera->fov_deg;
    };
    EXPECT_NEAR(vertical(""), 53.13010235415598, 1e-12);
    EXPECT_NEAR(vertical("x"), 53.13010235415598, 1e-12);
    EXPECT_EQ(vertical("y"), 90.0);
    EXPECT_EQ(vertical("smaller"), 90.0);
    EXPECT_NEAR(vertical("larger"), 53.13010235415598, 1e-12);
    EXPECT_NEAR(vertical("diagonal"), 48.18968510422141, 1e-12);
    EXPECT_NE(error_of(scene_xml("", "<string name=\"fov_axis\" value=\"z\"/>"), dir).find("unknown fov_axis"),
              std::string::npos);
}

// Mitsuba's camera +x points to the image's left. mitransient's Cornell box looks from z = -800 toward
// +z with +y up, and its red wall (x = 556) is on the left of the image: the left edge of ours must look
// toward +x. A general to_world (rotated 180 degrees about y: looking along -z) agrees with its lookat.
TEST(Mitsuba, CameraSeesMitsubasImageNotItsMirror) {
    TempDir dir;
    std::string xml = scene_xml("");
    xml.replace(xml.find("<lookat"), xml.find("/></transform>") - xml.find("<lookat"),
                R"(<lookat origin="278, 273, -800" target="278, 273, -799" up="0, 1, 0")");
    const tprf::Camera c = *parse(xml, dir).camera;
    EXPECT_EQ(c.position, Vec3(278, 273, -800));
    EXPECT_GT(tprf::camera_ray(c, 0.0, 4.0).x(), 0.0);   // left edge, middle row
    EXPECT_LT(tprf::camera_ray(c, 8.0, 4.0).x(), 0.0);   // right edge
    EXPECT_GT(tprf::camera_ray(c, 4.0, 0.0).y(), 0.0);   // top row looks up
    std::string rotated = scene_xml("");
    rotated.replace(rotated.find("<lookat"), rotated.find("/></transform>") - rotated.find("<lookat"),
                    R"(<rotate y="1" angle="180"/><translate z="5")");
    const tprf::Camera r = *parse(rotated, dir).camera;
    const tprf::Camera l = *parse(scene_xml(""), dir).camera;
    EXPECT_TRUE(tprf::camera_ray(r, 0.0, 4.0).isApprox(tprf::camera_ray(l, 0.0, 4.0)));
    EXPECT_LT(tprf::camera_ray(l, 0.0, 4.0).x(), 0.0);  // looking along -z, the left is -x
}

// A zero `up` is no up (Mitsuba's lookat builds its frame around the direction, as without one).
TEST(Mitsuba, LookatWithZeroUpIsLookatWithoutUp) {
    TempDir dir;
    const auto camera_with = [&](const std::string& up) {
        std::string xml = scene_xml("");
        xml.replace(xml.find("<lookat"), xml.find("/></transform>") - xml.find("<lookat"),
                    R"(<lookat origin="1, 2, 3" target="1, 2.5, 0")" + up);
        return *parse(xml, dir).camera;
    };
    const tprf::Camera none = camera_with(""), zero = camera_with(R"( up="0, 0, 0")");
    EXPECT_EQ(none.up, zero.up);
    EXPECT_TRUE(tprf::camera_ray(none, 1.0, 2.0).isApprox(tprf::camera_ray(zero, 1.0, 2.0)));
}

// An exported camera's to_world written to six digits (columns orthonormal to about 5e-7, as
// mitransient's staircase) is a rotation; a mirroring one renders Mitsuba's mirrored image (its left
// column looking along the matrix's +x); a scale is refused, naming how far from a rotation it is.
TEST(Mitsuba, ExportedAndMirroringCamerasAreTakenAScaledOneRefused) {
    TempDir dir;
    const auto with = [&](const std::string& transform) {
        std::string xml = scene_xml("");
        const std::size_t at = xml.find("<lookat");
        xml.replace(at, xml.find("/></transform>") - at + 2, transform);
        return xml;
    };
    // A rotation about (1, 2, 3) by 0.7 rad and a translation, exactly and to six significant digits.
    const Eigen::Matrix3d r = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    const auto matrix = [&](const Eigen::Matrix3d& m, int digits) {
        char text[400], *at = text;
        for (int i = 0; i < 3; ++i)
            at += std::snprintf(at, sizeof text - std::size_t(at - text), "%.*g %.*g %.*g %g ", digits, m(i, 0),
                                digits, m(i, 1), digits, m(i, 2), 0.5 * (i + 1));
        std::snprintf(at, sizeof text - std::size_t(at - text), "0 0 0 1");
        return std::string(R"(<matrix value=")") + text + R"("/>)";
    };
    const tprf::Camera exact = *parse(with(matrix(r, 17)), dir).camera;
    const tprf::Camera rounded = *parse(with(matrix(r, 6)), dir).camera;
    for (const double column : {0.0, 4.0, 8.0})
        EXPECT_TRUE(tprf::camera_ray(rounded, column, 2.0).isApprox(tprf::camera_ray(exact, column, 2.0), 1e-5));
    EXPECT_FALSE(exact.mirrored);
    // Mirrored in the camera's x: the image's left column looks along the matrix's +x.
    Eigen::Matrix3d mirror = r;
    mirror.col(0) = -mirror.col(0);
    const tprf::Camera m = *parse(with(matrix(mirror, 17)), dir).camera;
    EXPECT_TRUE(m.mirrored);
    EXPECT_TRUE(tprf::camera_ray(m, 0.0, 4.0).isApprox(tprf::camera_ray(exact, 8.0, 4.0), 1e-12));
    EXPECT_TRUE(tprf::camera_ray(m, 8.0, 4.0).isApprox(tprf::camera_ray(exact, 0.0, 4.0), 1e-12));
    EXPECT_GT(tprf::camera_ray(m, 0.0, 4.0).dot(mirror.col(0)), tprf::camera_ray(m, 8.0, 4.0).dot(mirror.col(0)));
    std::string xml = scene_xml("");
    xml.replace(xml.find("<lookat"), 0, R"(<scale x="-1"/>)");
    EXPECT_TRUE(parse(xml, dir).camera->mirrored);
    xml = scene_xml("");
    xml.replace(xml.find("<lookat"), 0, R"(<scale value="2"/>)");
    EXPECT_NE(error_of(xml, dir).find("scene.xml:4: <transform name=\"to_world\">: has a scale or shear (its columns are "
                                      "orthonormal to 1.5, not 1e-05)"),
              std::string::npos)
        << error_of(xml, dir);
    xml = scene_xml("");
    xml.replace(xml.find("<lookat"), 0, R"(<scale value="1.0001"/>)");
    EXPECT_NE(error_of(xml, dir).find("scale or shear"), std::string::npos);
}

// <default> gives $name a value; -D overrides it; an undefined $name is an error.
TEST(Mitsuba, DefaultsAndDefinesSubstitute) {
    TempDir dir;
    std::string xml = scene_xml("");
    xml.replace(xml.find("<sensor"), 0, R"(<default name="res" value="12"/><default name="r" value="3"/>
      )");
    xml.replace(xml.find("name=\"width\" value=\"8\""), 22, "name=\"width\" value=\"$res\"");
    xml.replace(xml.find("name=\"height\" value=\"8\""), 23, "name=\"height\" value=\"$r$r\"");
    tprf::Scene s = parse(xml, dir);
    EXPECT_EQ(s.camera->width, 12);   // $res is not $r followed by "es"
    EXPECT_EQ(s.camera->height, 33);
    s = parse(xml, dir, {{"res", "20"}, {"r", "1"}});
    EXPECT_EQ(s.camera->width, 20);
    EXPECT_EQ(s.camera->height, 11);
    const std::string e = error_of(scene_xml(R"(<shape type="$what"/>)"), dir);
    EXPECT_NE(e.find("scene.xml:12: <shape type=\"$what\">: undefined parameter"), std::string::npos) << e;
}

// A top-level BSDF with an id, reached by <ref>; twosided around diffuse is tprf's two_sided.
TEST(Mitsuba, RefAndTwosided) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(
      <shape type="rectangle"><ref id="paper" name="bsdf"/></shape>
      <bsdf type="twosided" id="paper"><bsdf type="diffuse"><rgb name="reflectance" value="0.1, 0.2, 0.3"/></bsdf></bsdf>
      <shape type="rectangle"><bsdf type="diffuse"><float name="reflectance" value="0.25"/></bsdf></shape>)"),
                                dir);
    EXPECT_EQ(s.objects[0].albedo.matrix(), Vec3(0.1, 0.2, 0.3));
    EXPECT_TRUE(s.objects[0].two_sided);
    EXPECT_EQ(s.objects[1].albedo.matrix(), Vec3::Constant(0.25));
    EXPECT_FALSE(s.objects[1].two_sided);
}

// A conductor is a mirror (Mitsuba's perfect "none", times its specular_reflectance), twosided it
// reflects on both sides (glass that passes nothing); a thin dielectric of index 1.5 is glass with the
// normal-incidence R = 2r / (1 + r), T = (1 - r) / (1 + r), r = 0.04. A solid dielectric is refused.
TEST(Mitsuba, ConductorsAndThinDielectricsAreMirrorsAndGlass) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(
      <shape type="rectangle"><bsdf type="conductor"><float name="specular_reflectance" value="0.9"/></bsdf></shape>
      <shape type="rectangle"><bsdf type="twosided"><bsdf type="conductor"/></bsdf></shape>
      <shape type="rectangle"><bsdf type="thindielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf></shape>)"),
                                dir);
    ASSERT_EQ(s.objects.size(), 3u);
    EXPECT_EQ(s.objects[0].material.type, tprf::MaterialType::Mirror);
    EXPECT_EQ(s.objects[0].material.reflectance.matrix(), Vec3::Constant(0.9));
    EXPECT_EQ(s.objects[0].albedo.matrix(), Vec3::Zero());
    EXPECT_EQ(s.objects[1].material.type, tprf::MaterialType::Glass);
    EXPECT_EQ(s.objects[1].material.reflectance.matrix(), Vec3::Constant(1.0));
    EXPECT_EQ(s.objects[1].material.transmittance.matrix(), Vec3::Zero());
    EXPECT_EQ(s.objects[2].material.type, tprf::MaterialType::Glass);
    EXPECT_NEAR(s.objects[2].material.reflectance[0], 2 * 0.04 / 1.04, 1e-12);
    EXPECT_NEAR(s.objects[2].material.transmittance[0], 0.96 / 1.04, 1e-12);
    EXPECT_NE(error_of(scene_xml(R"(<shape type="rectangle"><bsdf type="dielectric"/></shape>)"), dir)
                  .find("scene.xml:12: <bsdf type=\"dielectric\">: a solid dielectric refracts"),
              std::string::npos);
    EXPECT_NE(error_of(scene_xml(R"(<shape type="rectangle"><bsdf type="conductor"><string name="material" value="Au"/></bsdf></shape>)"),
                       dir)
                  .find("conductor material \"Au\""),
              std::string::npos);
}

TEST(Mitsuba, AreaAndPointEmitters) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(
      <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter></shape>
      <emitter type="point"><point name="position" x="1" y="2" z="3"/><rgb name="intensity" value="4"/></emitter>
      <emitter type="point"><transform name="to_world"><translate value="-1 0 2"/></transform>
        <float name="intensity" value="0.5"/></emitter>)"),
                                dir);
    EXPECT_EQ(s.objects[0].emission.matrix(), Vec3(1, 2, 3));
    ASSERT_EQ(s.lights.size(), 2u);
    const auto& p0 = std::get<tprf::PointLight>(s.lights[0]);
    const auto& p1 = std::get<tprf::PointLight>(s.lights[1]);
    EXPECT_EQ(p0.position, Vec3(1, 2, 3));
    EXPECT_EQ(p0.intensity.matrix(), Vec3::Constant(4));
    EXPECT_EQ(p1.position, Vec3(-1, 0, 2));
    EXPECT_EQ(p1.intensity.matrix(), Vec3::Constant(0.5));
}

// mitransient's film: temporal_bins bins of bin_width_opl from start_opl, optical path in scene units;
// max_depth m is m - 1 bounces (-1: all), camera_unwarp is camera.unwarp, sample_count is spp.
TEST(Mitsuba, TimeAxisDepthAndSamples) {
    TempDir dir;
    std::string xml = scene_xml(R"(<shape type="rectangle"/><integrator type="transient_path">
        <integer name="max_depth" value="$depth"/><boolean name="camera_unwarp" value="true"/>
        <string name="temporal_filter" value="box"/><float name="gaussian_stddev" value="2"/>
      </integrator>)",
                                R"(<sampler type="independent"><integer name="sample_count" value="9"/></sampler>)");
    xml.replace(xml.find("<float name=\"bin_width_opl\""), 0, R"(<float name="start_opl" value="5.25"/>)");
    tprf::Scene s = parse(xml, dir, {{"depth", "8"}});
    EXPECT_EQ(s.time.bins, 16);
    EXPECT_EQ(s.time.bin_width, 0.1);
    EXPECT_EQ(s.time.start, 5.25);
    EXPECT_EQ(s.time.unit, tprf::TimeUnit::Metres);
    EXPECT_EQ(s.solver.max_bounces, 7);
    EXPECT_TRUE(s.camera->unwarp);
    EXPECT_EQ(s.camera->spp, 9);
    EXPECT_EQ(parse(xml, dir, {{"depth", "-1"}}).solver.max_bounces, -1);
    EXPECT_EQ(parse(xml, dir, {{"depth", "1"}}).solver.max_bounces, 0);
    EXPECT_NE(error_of(xml, dir, {{"depth", "0"}}).find("must be -1 (all bounces) or >= 1"), std::string::npos);
}

// Each refusal names file:line, the element and what is wrong.
TEST(Mitsuba, UnsupportedInputNamesFileLineAndElement) {
    TempDir dir;
    const auto expect_error = [&](const std::string& body, const std::string& expected) {
        const std::string e = error_of(scene_xml(body), dir);
        EXPECT_NE(e.find(expected), std::string::npos) << "got: " << e;
        EXPECT_NE(e.find("scene.xml:12: "), std::string::npos) << "got: " << e;
    };
    expect_error(R"(<bsdf type="roughdielectric" id="a"/>)", "<bsdf type=\"roughdielectric\" id=\"a\">: unsupported BSDF type");
    expect_error(R"(<medium type="homogeneous"/>)", "<medium type=\"homogeneous\">: unsupported element");
    expect_error(R"(<shape type="rectangle" flavour="x"/>)", "unknown attribute \"flavour\"");
    expect_error(R"(<shape type="rectangle"><bsdf type="diffuse"><float name="roughness" value="1"/></bsdf></shape>)",
                 "<float name=\"roughness\">: unknown property");
    expect_error(R"(<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"/></bsdf></shape>)",
                 "<texture type=\"bitmap\" name=\"reflectance\">: unsupported inside <bsdf type=\"diffuse\">");
    expect_error(R"(<shape type="sphere"/>)", "unsupported shape type \"sphere\"");
    expect_error(R"(<emitter type="constant"/>)", "unsupported emitter type \"constant\"");
    expect_error(R"(<integrator type="transient_nlos_path"/>)", "NLOS");
    expect_error(R"(<shape type="rectangle"><ref id="nowhere"/></shape>)", "no element has this id");
    expect_error(R"(<shape type="rectangle"><bsdf type="diffuse"><spectrum name="reflectance" value="0.5"/></bsdf></shape>)",
                 "give the colour as <rgb> or <float>");
    expect_error(R"(<shape type="rectangle"><bsdf type="diffuse"><rgb name="reflectance" value="1.5"/></bsdf></shape>)",
                 "must lie in [0, 1]");
    expect_error(R"(<shape type="rectangle"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf>)"
                 R"(<emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>)",
                 "an area emitter on a shape with a twosided BSDF");
    std::string film = scene_xml("");
    film.replace(film.find("transient_hdr_film"), 18, "hdrfilm");
    EXPECT_NE(error_of(film, dir).find("scene.xml:5: <film type=\"hdrfilm\">: unsupported film type"), std::string::npos);
    EXPECT_NE(error_of("<scene version=\"3.0.0\">\n<shape", dir).find("scene.xml:2: malformed XML"), std::string::npos);
}

// The structure of mitransient's examples/transient/cornell-box/cbox_diffuse.xml (written out here in
// other words and numbers): defaults used in the integrator's type, a sensor with clip planes and a
// focus distance, obj shapes with referenced and nested BSDFs and an area light moved by a translate.
TEST(Mitsuba, MitransientDiffuseSceneParsesUnchanged) {
    TempDir dir;
    const std::string xml = R"(<scene version="3.3.0">
    <default name="spp" value="64"/>
    <default name="res" value="32"/>
    <default name="integrator" value="transient_path"/>
    <integrator type='$integrator'>
      <boolean name="camera_unwarp" value="false"/>
      <integer name="max_depth" value="5"/>
      <string name="temporal_filter" value="box"/>
      <float name="gaussian_stddev" value="1.5"/>
    </integrator>
    <sensor type="perspective" id="camera">
        <string name="fov_axis" value="smaller"/>
        <float name="near_clip" value="1"/>
        <float name="far_clip" value="100"/>
        <float name="focus_distance" value="10"/>
        <float name="fov" value="30"/>
        <transform name="to_world">
            <lookat origin="1, 2, -10" target="1, 2, -9" up="0, 1, 0"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="transient_hdr_film">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <integer name="temporal_bins" value="100"/>
            <float name="start_opl" value="8"/>
            <float name="bin_width_opl" value="0.25"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>
    <shape type="obj" id="lamp">
        <string name="filename" value="meshes/tri.obj"/>
        <transform name="to_world"><translate x="0" y="-0.25" z="0"/></transform>
        <ref id="grey"/>
        <emitter type="area"><rgb name="radiance" value="10, 8, 3"/></emitter>
    </shape>
    <shape type="obj" id="wall">
        <string name="filename" value="meshes/tri.obj"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.1, 0.1"/></bsdf>
    </shape>
</scene>
)";
    const tprf::Scene s = parse(xml, dir);
    ASSERT_EQ(s.objects.size(), 2u);
    EXPECT_EQ(s.objects[0].emission.matrix(), Vec3(10, 8, 3));
    EXPECT_EQ(mesh(s.objects[0]).transform(1, 3), -0.25);
    EXPECT_EQ(s.objects[1].albedo.matrix(), Vec3(0.5, 0.1, 0.1));
    EXPECT_EQ(s.solver.max_bounces, 4);
    EXPECT_EQ(s.camera->spp, 64);
    EXPECT_EQ(s.camera->fov_deg, 30.0);
    EXPECT_EQ(s.time.start, 8.0);
    // Mitsuba's own path integrator has no camera_unwarp: it refuses the file so switched, and so does tprf.
    EXPECT_NE(error_of(xml, dir, {{"integrator", "path"}}).find("<boolean name=\"camera_unwarp\">: unknown property"),
              std::string::npos);
}

// meshes/cornell-box.xml is meshes/cornell-box.json to the last bit: the same corners, mesh transforms,
// camera ray directions, samples and time axis.
TEST(Mitsuba, CornellBoxXmlIsTheJsonScene) {
    const tprf::Scene x = tprf::load_scene(kSource / "meshes" / "cornell-box.xml");
    const tprf::Scene j = tprf::load_scene(kSource / "meshes" / "cornell-box.json");
    ASSERT_EQ(x.objects.size(), j.objects.size());
    for (std::size_t i = 0; i < x.objects.size(); ++i) {
        EXPECT_EQ(x.objects[i].albedo.matrix(), j.objects[i].albedo.matrix()) << i;
        EXPECT_EQ(x.objects[i].emission.matrix(), j.objects[i].emission.matrix()) << i;
        if (const auto* r = std::get_if<tprf::RectangleShape>(&x.objects[i].shape)) {
            const tprf::RectangleShape& q = rect(j.objects[i]);
            EXPECT_EQ(r->origin, q.origin) << i;
            EXPECT_EQ(r->u, q.u) << i;
            EXPECT_EQ(r->v, q.v) << i;
        } else {
            EXPECT_EQ(mesh(x.objects[i]).transform, mesh(j.objects[i]).transform) << i;
            EXPECT_EQ(fs::weakly_canonical(mesh(x.objects[i]).file), fs::weakly_canonical(mesh(j.objects[i]).file));
        }
    }
    for (const Vec3& at : {Vec3(0.0, 0.0, 0), Vec3(64.5, 64.5, 0), Vec3(127.0, 3.0, 0)})
        EXPECT_EQ(tprf::camera_ray(*x.camera, at.x(), at.y()), tprf::camera_ray(*j.camera, at.x(), at.y()));
    EXPECT_EQ(x.camera->spp, j.camera->spp);
    EXPECT_EQ(x.time.bins, j.time.bins);
    EXPECT_EQ(x.time.bin_width, j.time.bin_width);
    EXPECT_EQ(x.solver.max_bounces, j.solver.max_bounces);
}

TEST(Mitsuba, JsonSceneRefusesDefines) {
    try {
        tprf::load_scene(kSource / "meshes" / "corner.json", tprf::XmlDefines{{"a", "1"}});
        FAIL() << "no error";
    } catch (const tprf::Error& e) {
        EXPECT_NE(std::string(e.what()).find("-D applies to Mitsuba XML scenes only"), std::string::npos);
    }
}

// A -D that no $name uses is a warning of the scene (a <default> of that name does not count as a use);
// the others are not.
TEST(Mitsuba, UnusedDefinesAreTheNamesNoParameterUses) {
    TempDir dir;
    const std::string text = scene_xml(R"(<default name="level" value="4"/>
    <default name="unused_default" value="1"/>
    <shape type="rectangle"><bsdf type="diffuse"><float name="reflectance" value="0.$level"/></bsdf></shape>)");
    const tprf::XmlDefines defines{{"level", "8"}, {"levl", "4"}, {"unused_default", "2"}};
    const tprf::Scene scene = parse(text, dir, defines);
    EXPECT_EQ(scene.objects.at(0).albedo[0], 0.8);
    EXPECT_EQ(scene.warnings, (std::vector<std::string>{"-D levl=4: the scene has no parameter $levl",
                                                        "-D unused_default=2: the scene has no parameter $unused_default"}));
    EXPECT_TRUE(parse(text, dir).warnings.empty());
}

namespace {

// The largest difference of two float arrays relative to the largest magnitude of the first.
double relative_difference(const fs::path& a, const fs::path& b) {
    const tprf::NpyArray x = tprf::read_npy(a), y = tprf::read_npy(b);
    EXPECT_EQ(x.shape, y.shape);
    if (x.shape != y.shape) return 1.0;
    double diff = 0.0, scale = 0.0;
    for (std::size_t i = 0; i < x.data.size(); ++i) {
        diff = std::max(diff, double(std::abs(x.data[i] - y.data[i])));
        scale = std::max(scale, double(std::abs(x.data[i])));
    }
    EXPECT_GT(scale, 0.0) << a;  // a comparison of two black images would prove nothing
    return scale > 0.0 ? diff / scale : 1.0;
}

// `text` with the first `from` replaced by `to`.
std::string replaced(std::string text, const std::string& from, const std::string& to) {
    const std::size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) text.replace(at, from.size(), to);
    return text;
}

}  // namespace

// Both Cornell boxes rendered by the command line at 24 x 24 pixels (and the same patch size):
// the geometry is the same to the bit, so the images agree to float rounding; 1e-6 of the maximum
// leaves room only for a different order of summation.
TEST(MitsubaCli, CornellBoxXmlRendersAsTheJson) {
    TempDir dir;
    fs::copy_file(kSource / "meshes" / "block.obj", dir.path / "block.obj");
    std::string json = tprf::test::read_bytes(kSource / "meshes" / "cornell-box.json");
    json = replaced(json, "\"width\": 128, \"height\": 128", "\"width\": 24, \"height\": 24");
    std::ofstream(dir.path / "box.json") << json;
    std::string xml = tprf::test::read_bytes(kSource / "meshes" / "cornell-box.xml");
    xml = replaced(xml, "name=\"res\" value=\"128\"", "name=\"res\" value=\"24\"");
    std::ofstream(dir.path / "box.xml") << xml;
    for (const char* name : {"box.json", "box.xml"}) {
        const tprf::test::Outcome r = tprf::test::run_tprf("render " + (dir.path / name).string() + " --max-edge 0.1 -o " +
                                                           (dir.path / (std::string(name) + ".out")).string());
        ASSERT_EQ(r.status, 0) << r.err;
    }
    for (const char* file : {"steady.npy", "transient.npy"})
        EXPECT_LE(relative_difference(dir.path / "box.json.out" / file, dir.path / "box.xml.out" / file), 1e-6) << file;
}

// -D reaches the scene through `tprf render` and `tprf info`.
TEST(MitsubaCli, DefinesReachTheScene) {
    TempDir dir;
    const std::string scene = (kSource / "meshes" / "cornell-box.xml").string();
    const tprf::test::Outcome bad = tprf::test::run_tprf("info " + scene + " -D res=0");
    EXPECT_EQ(bad.status, 2);
    EXPECT_NE(bad.err.find("cornell-box.xml:"), std::string::npos) << bad.err;
    EXPECT_NE(bad.err.find("must be > 0"), std::string::npos) << bad.err;
    const tprf::test::Outcome ok = tprf::test::run_tprf("render " + scene + " -D res=6 -Dbins=32 --max-edge 0.25 -o " +
                                                        (dir.path / "out").string());
    ASSERT_EQ(ok.status, 0) << ok.err;
    EXPECT_EQ(ok.err.find("-D"), std::string::npos) << ok.err;  // both used: no warning
    EXPECT_EQ(tprf::read_npy(dir.path / "out" / "transient.npy").shape, (std::vector<std::size_t>{6, 6, 32, 3}));
    const tprf::test::Outcome json = tprf::test::run_tprf("info " + (kSource / "meshes" / "corner.json").string() + " -D a=1");
    EXPECT_EQ(json.status, 2);
    EXPECT_NE(json.err.find("-D applies to Mitsuba XML scenes only"), std::string::npos) << json.err;
}

// A -D that the scene never uses is a warning on stderr, not a failure.
TEST(MitsubaCli, UnusedDefineIsAWarning) {
    const std::string scene = (kSource / "meshes" / "cornell-box.xml").string();
    const tprf::test::Outcome r = tprf::test::run_tprf("info --meshes " + scene + " -D sppp=4 -D res=8");
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.err, "tprf: warning: -D sppp=4: the scene has no parameter $sppp\n");
}

TEST(MitsubaCli, BadElementExitsTwoWithFileLineAndWritesNothing) {
    TempDir dir;
    std::ofstream(dir.path / "bad.xml") << scene_xml(R"(<shape type="rectangle"><bsdf type="roughdielectric"/></shape>)");
    const tprf::test::Outcome r =
        tprf::test::run_tprf("render " + (dir.path / "bad.xml").string() + " -o " + (dir.path / "out").string());
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("bad.xml:12: <bsdf type=\"roughdielectric\">: unsupported BSDF type"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(dir.path / "out"));
}

namespace {

// The normal-incidence Fresnel reflectance of a conductor of complex index eta + ik.
double fresnel0(double eta, double k) { return ((eta - 1) * (eta - 1) + k * k) / ((eta + 1) * (eta + 1) + k * k); }

// `scene_xml` around `body`, with meshes/block.obj (a box: curved as a whole) beside it as block.obj.
std::string with_block(const std::string& body, const TempDir& dir) {
    fs::copy_file(kSource / "meshes" / "block.obj", dir.path / "block.obj", fs::copy_options::overwrite_existing);
    return scene_xml(body);
}

}  // namespace

// A rough conductor is glossy: its alpha, the normal-incidence Fresnel reflectance of eta + ik times
// specular_reflectance (Mitsuba's "none", eta 0 and k 1, reflects 1), no diffuse part, on any shape,
// with a GGX or a Beckmann distribution.
TEST(Mitsuba, RoughConductorIsGlossy) {
    TempDir dir;
    const tprf::Scene s = parse(with_block(R"(
      <shape type="rectangle"><bsdf type="roughconductor"><string name="distribution" value="ggx"/>
        <float name="alpha" value="0.3"/><rgb name="eta" value="0.2, 0.9, 1.1"/><rgb name="k" value="3.9, 2.45, 2.1"/>
        <float name="specular_reflectance" value="0.9"/></bsdf></shape>
      <shape type="obj"><string name="filename" value="block.obj"/><bsdf type="roughconductor">
        <string name="distribution" value="GGX"/><float name="alpha_u" value="0.2"/><float name="alpha_v" value="0.2"/>
        <boolean name="sample_visible" value="false"/><rgb name="specular_reflectance" value="0.8, 0.6, 0.4"/></bsdf></shape>
      <shape type="rectangle"><bsdf type="twosided"><bsdf type="roughconductor">
        <float name="eta" value="1.5"/></bsdf></bsdf></shape>
      <shape type="rectangle"><bsdf type="roughconductor"><string name="distribution" value="beckmann"/>
        <float name="alpha" value="0.25"/></bsdf></shape>)",
                                           dir),
                                dir);
    ASSERT_EQ(s.objects.size(), 4u);
    const tprf::Object& a = s.objects[0];
    EXPECT_EQ(a.material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(a.material.roughness, 0.3);
    EXPECT_EQ(a.albedo.matrix(), Vec3::Zero());
    EXPECT_FALSE(a.two_sided);
    const Vec3 eta(0.2, 0.9, 1.1), k(3.9, 2.45, 2.1);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(a.material.reflectance[c], 0.9 * fresnel0(eta[c], k[c]), 1e-15) << c;
    const tprf::Object& b = s.objects[1];
    EXPECT_EQ(b.material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(b.material.roughness, 0.2);
    EXPECT_EQ(b.material.reflectance.matrix(), Vec3(0.8, 0.6, 0.4));
    // Mitsuba's k defaults to 1 when eta is given.
    const tprf::Object& c = s.objects[2];
    EXPECT_EQ(c.material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(c.material.roughness, 0.1);  // Mitsuba's default alpha
    EXPECT_TRUE(c.two_sided);
    EXPECT_NEAR(c.material.reflectance[0], fresnel0(1.5, 1.0), 1e-15);
    // Beckmann (Mitsuba's default distribution, as for c, or named) becomes GGX of the same alpha.
    const tprf::Object& d = s.objects[3];
    EXPECT_EQ(d.material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(d.material.roughness, 0.25);
}

// A smooth conductor stays a mirror on a planar shape (a rectangle, a mesh in one plane) and becomes
// glossy of roughness 0.01 on a curved mesh, with its Fresnel reflectance either way; twosided, it is
// glass that passes nothing on a plane and a two-sided glossy surface on a curved mesh.
TEST(Mitsuba, SmoothConductorIsAMirrorOnAPlaneAndGlossyOnACurvedMesh) {
    TempDir dir;
    const std::string gold = R"(<bsdf type="conductor"><rgb name="eta" value="0.2, 0.4, 1.4"/>)"
                             R"(<rgb name="k" value="3.6, 2.3, 1.8"/></bsdf>)";
    const tprf::Scene s = parse(with_block(R"(
      <shape type="rectangle">)" + gold + R"(</shape>
      <shape type="obj"><string name="filename" value="meshes/tri.obj"/>)" + gold + R"(</shape>
      <shape type="obj"><string name="filename" value="block.obj"/>)" + gold + R"(</shape>
      <shape type="obj"><string name="filename" value="meshes/tri.obj"/><bsdf type="twosided"><bsdf type="conductor"/></bsdf></shape>
      <shape type="obj"><string name="filename" value="block.obj"/><bsdf type="twosided"><bsdf type="conductor"/></bsdf></shape>)",
                                           dir),
                                dir);
    ASSERT_EQ(s.objects.size(), 5u);
    const Vec3 eta(0.2, 0.4, 1.4), k(3.6, 2.3, 1.8);
    for (std::size_t i = 0; i < 3; ++i) {
        EXPECT_EQ(s.objects[i].albedo.matrix(), Vec3::Zero()) << i;
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.objects[i].material.reflectance[c], fresnel0(eta[c], k[c]), 1e-15) << i;
    }
    EXPECT_EQ(s.objects[0].material.type, tprf::MaterialType::Mirror);
    EXPECT_EQ(s.objects[1].material.type, tprf::MaterialType::Mirror);
    EXPECT_EQ(s.objects[2].material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(s.objects[2].material.roughness, 0.01);
    EXPECT_FALSE(s.objects[2].two_sided);
    EXPECT_EQ(s.objects[3].material.type, tprf::MaterialType::Glass);
    EXPECT_EQ(s.objects[3].material.transmittance.matrix(), Vec3::Zero());
    EXPECT_FALSE(s.objects[3].two_sided);
    EXPECT_EQ(s.objects[4].material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(s.objects[4].material.reflectance.matrix(), Vec3::Ones());
    EXPECT_TRUE(s.objects[4].two_sided);
}

// Plastics: alpha (smooth: 0.01), ior = int_ior / ext_ior (numbers or Mitsuba's names, in any case;
// defaults polypropylene in air), diffuse_reflectance as the base's albedo (default 0.5); nonlinear and
// a specular_reflectance of 1 are accepted; twosided is two-sided.
TEST(Mitsuba, PlasticsArePlastic) {
    TempDir dir;
    const tprf::Scene s = parse(scene_xml(R"(
      <shape type="rectangle"><bsdf type="roughplastic"><string name="distribution" value="ggx"/>
        <float name="alpha" value="0.25"/><float name="int_ior" value="1.6"/><float name="ext_ior" value="1"/>
        <rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/><float name="specular_reflectance" value="1"/></bsdf></shape>
      <shape type="rectangle"><bsdf type="plastic"/></shape>
      <shape type="rectangle"><bsdf type="twosided"><bsdf type="plastic"><string name="int_ior" value="BK7"/>
        <string name="ext_ior" value="water"/><boolean name="nonlinear" value="true"/></bsdf></bsdf></shape>
      <shape type="rectangle"><bsdf type="thindielectric"><string name="int_ior" value="diamond"/></bsdf></shape>)"),
                                dir);
    ASSERT_EQ(s.objects.size(), 4u);
    const tprf::Object& a = s.objects[0];
    EXPECT_EQ(a.material.type, tprf::MaterialType::Plastic);
    EXPECT_EQ(a.material.roughness, 0.25);
    EXPECT_EQ(a.material.ior, 1.6);
    EXPECT_EQ(a.albedo.matrix(), Vec3(0.1, 0.2, 0.3));
    EXPECT_FALSE(a.two_sided);
    const tprf::Object& b = s.objects[1];
    EXPECT_EQ(b.material.type, tprf::MaterialType::Plastic);
    EXPECT_EQ(b.material.roughness, 0.01);
    EXPECT_EQ(b.material.ior, 1.49 / 1.000277);
    EXPECT_EQ(b.albedo.matrix(), Vec3::Constant(0.5));
    const tprf::Object& c = s.objects[2];
    EXPECT_EQ(c.material.type, tprf::MaterialType::Plastic);
    EXPECT_EQ(c.material.ior, 1.5046 / 1.333);
    EXPECT_TRUE(c.two_sided);
    const double r = std::pow((2.419 / 1.000277 - 1) / (2.419 / 1.000277 + 1), 2);
    EXPECT_NEAR(s.objects[3].material.reflectance[0], 2 * r / (1 + r), 1e-12);
}

// Values tprf cannot render exit with file:line, the element and the reason.
TEST(Mitsuba, GlossyRefusalsNameFileLineAndElement) {
    TempDir dir;
    const auto expect_error = [&](const std::string& bsdf, const std::string& expected, int line = 12) {
        const std::string e = error_of(scene_xml("<shape type=\"rectangle\">" + bsdf + "</shape>"), dir);
        EXPECT_NE(e.find(expected), std::string::npos) << "got: " << e;
        EXPECT_NE(e.find("scene.xml:" + std::to_string(line) + ": "), std::string::npos) << "got: " << e;
    };
    const std::string ggx = R"(<string name="distribution" value="ggx"/>)";
    expect_error("<bsdf type=\"roughplastic\">\n<string name=\"distribution\" value=\"phong\"/></bsdf>",
                 "<string name=\"distribution\">: \"phong\": expected \"ggx\" or \"beckmann\"", 13);
    expect_error("<bsdf type=\"roughconductor\">" + ggx + "\n<float name=\"alpha\" value=\"0.005\"/></bsdf>",
                 "<float name=\"alpha\">: must lie in [0.01, 1]", 13);
    expect_error("<bsdf type=\"roughplastic\">" + ggx + R"(<float name="alpha" value="1.5"/></bsdf>)", "must lie in [0.01, 1]");
    expect_error("<bsdf type=\"roughconductor\">" + ggx +
                     R"(<float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.2"/></bsdf>)",
                 "<float name=\"alpha_v\">: differs from alpha_u: tprf's lobes are isotropic");
    expect_error("<bsdf type=\"roughconductor\">" + ggx + R"(<float name="alpha_u" value="0.1"/></bsdf>)",
                 "alpha_u and alpha_v go together");
    expect_error("<bsdf type=\"roughconductor\">" + ggx +
                     R"(<float name="alpha" value="0.1"/><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.1"/></bsdf>)",
                 "give either alpha or alpha_u and alpha_v");
    expect_error("<bsdf type=\"roughconductor\">" + ggx + R"(<string name="material" value="Cu"/></bsdf>)",
                 "conductor material \"Cu\": tprf holds no spectral tables");
    expect_error(R"(<bsdf type="conductor"><float name="k" value="-1"/></bsdf>)", "<float name=\"k\">: must be >= 0");
    expect_error("<bsdf type=\"roughconductor\">" + ggx + R"(<texture type="bitmap" name="alpha"/></bsdf>)",
                 "<texture type=\"bitmap\" name=\"alpha\">: unsupported inside <bsdf type=\"roughconductor\">");
    expect_error(R"(<bsdf type="plastic"><float name="specular_reflectance" value="0.5"/></bsdf>)",
                 "<float name=\"specular_reflectance\">: must be 1");
    expect_error(R"(<bsdf type="plastic"><float name="int_ior" value="1.2"/><float name="ext_ior" value="1.33"/></bsdf>)",
                 "<bsdf type=\"plastic\">: int_ior / ext_ior must be > 1");
    expect_error(R"(<bsdf type="plastic"><string name="int_ior" value="unobtainium"/></bsdf>)",
                 "<string name=\"int_ior\">: unknown index of refraction \"unobtainium\"");
    expect_error(R"(<bsdf type="plastic"><float name="alpha" value="0.1"/></bsdf>)", "<float name=\"alpha\">: unknown property");
}

// A Cornell box whose floor is a rough conductor and whose tall block is a rough plastic, lit by its
// area light and a point light, renders as the same box written as a JSON scene (32 x 32 pixels, one
// sample, 100 bins, patches of 0.2 m): the XML becomes the same Scene, so the images agree to the bit.
TEST(Mitsuba, GlossyCornellBoxXmlRendersAsTheJson) {
    TempDir dir;
    fs::copy_file(kSource / "meshes" / "block.obj", dir.path / "block.obj");
    std::string xml = tprf::test::read_bytes(kSource / "meshes" / "cornell-box.xml");
    xml = replaced(xml, "<ref id=\"white\"/>", R"(<bsdf type="roughconductor"><string name="distribution" value="ggx"/>
            <float name="alpha" value="0.2"/><rgb name="eta" value="1, 3, 0"/><rgb name="k" value="2, 0, 1"/>
            <float name="specular_reflectance" value="0.8"/></bsdf>)");
    xml.replace(xml.rfind("<ref id=\"white\"/>"), 17, R"(<bsdf type="roughplastic"><string name="distribution" value="ggx"/>
            <float name="alpha" value="0.3"/><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/>
            <float name="diffuse_reflectance" value="0.6"/></bsdf>)");
    xml = replaced(xml, "name=\"bin_width_opl\" value=\"0.005\"", "name=\"bin_width_opl\" value=\"0.05\"");
    xml = replaced(xml, "</scene>", R"(<emitter type="point"><point name="position" x="0.5" y="0.3" z="0.8"/>
        <float name="intensity" value="0.5"/></emitter></scene>)");
    std::ofstream(dir.path / "box.xml") << xml;
    // Fresnel at normal incidence of (eta, k) = (1, 2), (3, 0), (0, 1): 0.5, 0.25, 1; times 0.8.
    std::string json = tprf::test::read_bytes(kSource / "meshes" / "cornell-box.json");
    json = replaced(json, "\"albedo\": 0.73}",
                    R"("material": {"type": "glossy", "reflectance": [0.4, 0.2, 0.8], "roughness": 0.2}})");
    json.replace(json.rfind("\"albedo\": 0.73,"), 15,
                 R"("material": {"type": "plastic", "albedo": 0.6, "roughness": 0.3, "ior": 1.5},)");
    json = replaced(json, "\"width\": 128, \"height\": 128, \"spp\": 4", "\"width\": 32, \"height\": 32, \"spp\": 1");
    json = replaced(json, "\"bins\": 1024, \"bin_width\": 0.005", "\"bins\": 100, \"bin_width\": 0.05");
    json = replaced(json, "\"lights\":  []", R"("lights": [{"type": "point", "position": [0.5, 0.3, 0.8], "intensity": 0.5}])");
    std::ofstream(dir.path / "box.json") << json;

    const tprf::Scene x = tprf::load_scene(dir.path / "box.xml", tprf::XmlDefines{{"res", "32"}, {"bins", "100"}, {"spp", "1"}});
    const tprf::Scene j = tprf::load_scene(dir.path / "box.json");
    ASSERT_EQ(x.objects.size(), j.objects.size());
    for (std::size_t i = 0; i < x.objects.size(); ++i) {
        const tprf::Material &a = x.objects[i].material, &b = j.objects[i].material;
        EXPECT_EQ(a.type, b.type) << i;
        EXPECT_EQ(a.reflectance.matrix(), b.reflectance.matrix()) << i;
        EXPECT_EQ(x.objects[i].albedo.matrix(), j.objects[i].albedo.matrix()) << i;
        if (a.glossy()) {
            EXPECT_EQ(a.roughness, b.roughness) << i;
            EXPECT_EQ(a.ior, b.ior) << i;
        }
    }
    EXPECT_EQ(x.objects.front().material.type, tprf::MaterialType::Glossy);
    EXPECT_EQ(x.objects.back().material.type, tprf::MaterialType::Plastic);
    tprf::RenderOptions options;
    options.max_edge = 0.2;
    options.threads = 1;  // the same numbers for any count; one thread waits for no other on a busy machine
    const tprf::RenderResult rx = tprf::render_scene(x, options), rj = tprf::render_scene(j, options);
    for (const char* name : {"steady", "transient"}) {
        const tprf::FloatArray &a = rx.arrays.at(name), &b = rj.arrays.at(name);
        EXPECT_EQ(a.shape, b.shape) << name;
        EXPECT_TRUE(a.data == b.data) << name;
        EXPECT_GT(*std::max_element(b.data.begin(), b.data.end()), 0.0f) << name;  // not two black images
    }
}
