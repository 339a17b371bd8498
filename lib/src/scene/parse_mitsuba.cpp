#include "tprf/scene/parse_mitsuba.h"

#include "tprf/core/error.h"
#include "tprf/scene/mesh_io.h"
#include "tprf/scene/validate.h"
#include "mitsuba_xml.h"
#include "open_reason.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tprf {

namespace {

namespace fs = std::filesystem;
using mitsuba::Props;
using mitsuba::XmlSource;
using mitsuba::describe;

// What a BSDF gives an object.
struct Surface {
    Rgb albedo = Rgb::Constant(0.5);  // Mitsuba's default diffuse reflectance
    bool two_sided = false;
    Material material;                // a conductor, a thin dielectric or a plastic
    bool smooth_conductor = false;    // a mirror or glossy, by its shape (place_conductor)
};

// What is read while walking the document: elements with an id (for <ref>), and whether the one-of
// elements were seen.
struct Context {
    const XmlSource& src;
    std::map<std::string, pugi::xml_node, std::less<>> ids;
    pugi::xml_node sensor, integrator;
    bool unwarp = false;  // the integrator's camera_unwarp, for the camera whichever comes first
};

std::string line_name(const XmlSource& src, const pugi::xml_node& n, std::string_view what) {
    return std::string(what) + " at line " + std::to_string(src.line(n));
}

Vec3 apply_point(const Eigen::Matrix4d& m, const Vec3& p) { return m.block<3, 3>(0, 0) * p + m.block<3, 1>(0, 3); }

void check_color(const Props& p, std::string_view name, const Rgb& c, bool at_most_one) {
    if ((c < 0.0).any()) p.source().fail(p.find(name), "must be >= 0");
    if (at_most_one && (c > 1.0).any()) p.source().fail(p.find(name), "must lie in [0, 1] (a diffuse reflectance)");
}

// The GGX alpha that Mitsuba's smooth BSDFs get where tprf needs a lobe (a plastic, a conductor on a
// curved mesh): the least roughness tprf renders.
constexpr double kSmoothRoughness = 0.01;

// Mitsuba's named refractive indices (its table, measured near 589 nm), for int_ior and ext_ior.
struct NamedIor {
    std::string_view name;
    double value;
};
constexpr NamedIor kNamedIors[] = {
    {"vacuum", 1.0},       {"helium", 1.000036},        {"hydrogen", 1.000132},    {"air", 1.000277},
    {"carbon dioxide", 1.00045}, {"water", 1.333},      {"acetone", 1.36},         {"ethanol", 1.361},
    {"carbon tetrachloride", 1.461}, {"glycerol", 1.4729}, {"benzene", 1.501},     {"silicone oil", 1.52045},
    {"bromine", 1.661},    {"water ice", 1.31},         {"fused quartz", 1.458},   {"pyrex", 1.47},
    {"acrylic glass", 1.49}, {"polypropylene", 1.49},   {"bk7", 1.5046},           {"sodium chloride", 1.544},
    {"amber", 1.55},       {"pet", 1.575},              {"diamond", 2.419},
};
constexpr double kAirIor = 1.000277;

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

// An index of refraction: a <float>, or a <string> naming one of kNamedIors (in any case, as Mitsuba
// reads it); `fallback` when absent.
double read_ior(Props& p, std::string_view name, double fallback) {
    const pugi::xml_node node = p.find(name);
    if (!node) return fallback;
    if (std::string_view(node.name()) != "string") return *p.number(name);
    const std::string value = lower(*p.string(name));
    std::string names;
    for (const NamedIor& n : kNamedIors) {
        if (n.name == value) return n.value;
        names += (names.empty() ? "" : ", ") + std::string(n.name);
    }
    p.source().fail(node, "unknown index of refraction \"" + value + "\" (a number, or one of Mitsuba's names: " +
                              names + ")");
}

// The GGX alpha of a rough BSDF: `alpha` (Mitsuba's default 0.1), or alpha_u and alpha_v when they are
// equal, in [0.01, 1]. `distribution` "ggx" is read as it is; "beckmann" (Mitsuba's default) becomes a
// GGX lobe of the same alpha (docs/mitsuba.md says what that changes). `sample_visible` only steers
// Mitsuba's sampling.
double rough_alpha(Props& p) {
    if (const auto distribution = p.string("distribution"); distribution) {
        const std::string name = lower(*distribution);
        if (name != "ggx" && name != "beckmann")
            p.source().fail(p.find("distribution"), "\"" + *distribution + "\": expected \"ggx\" or \"beckmann\"");
    }
    p.boolean("sample_visible");
    const auto alpha = p.number("alpha"), alpha_u = p.number("alpha_u"), alpha_v = p.number("alpha_v");
    if ((alpha_u || alpha_v) && alpha) p.fail("give either alpha or alpha_u and alpha_v, not both");
    if (alpha_u.has_value() != alpha_v.has_value()) p.fail("alpha_u and alpha_v go together");
    if (alpha_u && *alpha_u != *alpha_v)
        p.source().fail(p.find("alpha_v"), "differs from alpha_u: tprf's lobes are isotropic (give one alpha)");
    const double a = alpha_u ? *alpha_u : alpha.value_or(0.1);
    if (!(a >= kSmoothRoughness && a <= 1.0))
        p.source().fail(p.find(alpha_u ? "alpha_u" : "alpha"),
                        "must lie in [0.01, 1] (tprf's GGX roughness; a smoother surface is Mitsuba's smooth "
                        "\"conductor\" or \"plastic\")");
    return a;
}

// A conductor's reflectance: the Fresnel reflectance of its complex index eta + ik at normal incidence,
// ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2) per channel, times specular_reflectance. Mitsuba's default,
// material "none" (eta 0, k 1), reflects exactly 1. Named materials are spectral tables tprf does not hold.
Rgb conductor_reflectance(Props& p) {
    const auto material = p.string("material");
    if (material && *material != "none")
        p.fail("conductor material \"" + *material + "\": tprf holds no spectral tables; give the material's RGB "
               "index as <rgb name=\"eta\"> and <rgb name=\"k\">, or material \"none\" and a specular_reflectance");
    Rgb eta = Rgb::Zero(), k = Rgb::Ones(), scale = Rgb::Ones();
    for (auto [name, value] : {std::pair{"eta", &eta}, std::pair{"k", &k}, std::pair{"specular_reflectance", &scale}})
        if (const auto c = p.color(name)) {
            *value = *c;
            check_color(p, name, *c, value == &scale);
        }
    return (((eta - 1.0).square() + k.square()) / ((eta + 1.0).square() + k.square())) * scale;
}

Surface diffuse_bsdf(const Context& ctx, const pugi::xml_node& node);
Surface conductor_bsdf(const Context& ctx, const pugi::xml_node& node, bool rough);
Surface plastic_bsdf(const Context& ctx, const pugi::xml_node& node, bool rough);
Surface thin_dielectric_bsdf(const Context& ctx, const pugi::xml_node& node);

// A <bsdf> (any type read) or a <ref> to one; `inside_twosided` for the one a twosided BSDF wraps.
Surface parse_bsdf(const Context& ctx, pugi::xml_node node, bool inside_twosided) {
    if (std::string_view(node.name()) == "ref") {
        mitsuba::check_attributes(ctx.src, node, {"id", "name"});
        const auto it = ctx.ids.find(std::string_view(node.attribute("id").value()));
        if (it == ctx.ids.end()) ctx.src.fail(node, "no element has this id");
        if (std::string_view(it->second.name()) != "bsdf")
            ctx.src.fail(node, "refers to " + describe(it->second) + " at line " + std::to_string(ctx.src.line(it->second)) +
                                   ", not to a <bsdf>");
        node = it->second;
    }
    const std::string type = node.attribute("type").value();
    if (type == "diffuse") return diffuse_bsdf(ctx, node);
    if (type == "conductor" || type == "roughconductor") return conductor_bsdf(ctx, node, type == "roughconductor");
    if (type == "plastic" || type == "roughplastic") return plastic_bsdf(ctx, node, type == "roughplastic");
    if (type == "thindielectric") return thin_dielectric_bsdf(ctx, node);
    if (type == "dielectric")
        ctx.src.fail(node, "a solid dielectric refracts, which tprf does not; a thin sheet of glass is "
                           "<bsdf type=\"thindielectric\"> (docs/materials.md)");
    if (type != "twosided")
        ctx.src.fail(node, "unsupported BSDF type \"" + type +
                               "\" (tprf reads \"diffuse\", \"conductor\", \"roughconductor\", \"plastic\", "
                               "\"roughplastic\", \"thindielectric\" and \"twosided\" around one of the first five)");
    if (inside_twosided) ctx.src.fail(node, "a twosided BSDF inside a twosided BSDF");
    Props p(ctx.src, node);
    const std::vector<pugi::xml_node> inner = p.objects({"bsdf", "ref"});
    p.finish();
    if (inner.size() != 1) p.fail("needs exactly one nested <bsdf> (tprf has no separate back side)");
    Surface s = parse_bsdf(ctx, inner.front(), true);
    if (s.material.type == MaterialType::Glass) ctx.src.fail(node, "a thin dielectric is two-sided already");
    s.two_sided = true;  // a smooth conductor's two sides are settled by its shape (place_conductor)
    return s;
}

// <bsdf type="roughconductor"> as glossy: a GGX lobe of its alpha with the constant reflectance
// conductor_reflectance gives, and no diffuse part. <bsdf type="conductor"> as a smooth conductor of
// that reflectance: a mirror on a planar shape, else glossy of the least roughness (place_conductor).
// Real conductors' Fresnel curves vary with the angle; tprf's reflectance does not (docs/mitsuba.md).
Surface conductor_bsdf(const Context& ctx, const pugi::xml_node& node, bool rough) {
    Props p(ctx.src, node);
    Surface s;
    s.albedo = Rgb::Zero();
    s.material.reflectance = conductor_reflectance(p);
    if (rough) {
        s.material.type = MaterialType::Glossy;
        s.material.roughness = rough_alpha(p);
    } else {
        s.material.type = MaterialType::Mirror;
        s.smooth_conductor = true;
    }
    p.finish();
    return s;
}

// <bsdf type="roughplastic"> and <bsdf type="plastic"> as plastic: a GGX coat of index int_ior / ext_ior
// and the BSDF's alpha (smooth: 0.01) over a Lambertian base of diffuse_reflectance. tprf's base has no
// light bouncing between it and the coat, so `nonlinear`, which changes how Mitsuba sums those bounces,
// changes nothing here (docs/mitsuba.md).
Surface plastic_bsdf(const Context& ctx, const pugi::xml_node& node, bool rough) {
    Props p(ctx.src, node);
    Surface s;
    s.material.type = MaterialType::Plastic;
    s.material.roughness = rough ? rough_alpha(p) : kSmoothRoughness;
    const double int_ior = read_ior(p, "int_ior", 1.49), ext_ior = read_ior(p, "ext_ior", kAirIor);
    s.material.ior = int_ior / ext_ior;
    if (!(int_ior > 0.0) || !(ext_ior > 0.0) || !(s.material.ior > 1.0))
        p.fail("int_ior / ext_ior must be > 1: tprf's plastic coat is denser than what surrounds it (got " +
               std::to_string(int_ior) + " / " + std::to_string(ext_ior) + ")");
    if (const auto r = p.color("diffuse_reflectance")) {
        s.albedo = *r;
        check_color(p, "diffuse_reflectance", s.albedo, true);
    }
    if (const auto r = p.color("specular_reflectance"); r && !(*r == 1.0).all())
        p.source().fail(p.find("specular_reflectance"),
                        "must be 1: tprf's plastic coat reflects its Fresnel term unscaled");
    p.boolean("nonlinear");
    p.finish();
    return s;
}

// <bsdf type="thindielectric"> as glass with the normal-incidence reflectance and transmittance of a thin
// sheet of relative index n: r = ((n - 1) / (n + 1))^2, R = 2r / (1 + r), T = (1 - r) / (1 + r), times
// the specular_ factors. tprf's glass does not vary with the angle (docs/mitsuba.md).
Surface thin_dielectric_bsdf(const Context& ctx, const pugi::xml_node& node) {
    Props p(ctx.src, node);
    Surface s;
    s.albedo = Rgb::Zero();
    Rgb scale = Rgb::Ones(), transmit = Rgb::Ones();
    if (const auto r = p.color("specular_reflectance")) {
        scale = *r;
        check_color(p, "specular_reflectance", scale, true);
    }
    const double int_ior = read_ior(p, "int_ior", 1.5046), ext_ior = read_ior(p, "ext_ior", kAirIor);
    if (!(int_ior > 0.0) || !(ext_ior > 0.0)) p.fail("int_ior and ext_ior must be > 0");
    if (const auto t = p.color("specular_transmittance")) {
        transmit = *t;
        check_color(p, "specular_transmittance", transmit, true);
    }
    const double n = int_ior / ext_ior, r = ((n - 1.0) / (n + 1.0)) * ((n - 1.0) / (n + 1.0));
    s.material.type = MaterialType::Glass;
    s.material.reflectance = scale * (2.0 * r / (1.0 + r));
    s.material.transmittance = transmit * ((1.0 - r) / (1.0 + r));
    p.finish();
    return s;
}

Surface diffuse_bsdf(const Context& ctx, const pugi::xml_node& node) {
    Props p(ctx.src, node);
    Surface s;
    if (const auto r = p.color("reflectance")) {
        s.albedo = *r;
        check_color(p, "reflectance", s.albedo, true);
    }
    p.finish();
    return s;
}

// Whether every vertex of a mesh lies in the plane of its first face, within 1e-6 of its size (the
// tolerance tprf's mirrors are held to, docs/materials.md).
bool planar_mesh(const MeshShape& shape, const XmlSource& src, const std::string& json_path) {
    const PolygonMesh mesh = load_mesh(shape.file, shape.transform, src.file(), json_path + ".file");
    const std::span<const int> face = mesh.face(0);
    Vec3 normal = Vec3::Zero();  // Newell's normal of the first face
    for (std::size_t i = 0; i < face.size(); ++i)
        normal += mesh.vertices[std::size_t(face[i])].cross(mesh.vertices[std::size_t(face[(i + 1) % face.size()])]);
    normal.normalize();
    const Vec3& point = mesh.vertices[std::size_t(face[0])];
    const double tolerance = 1e-6 * mesh.bounds.diagonal().norm();
    return std::all_of(mesh.vertices.begin(), mesh.vertices.end(),
                       [&](const Vec3& v) { return std::abs(normal.dot(v - point)) <= tolerance; });
}

// A smooth conductor on a planar shape (a rectangle, a cube's face, a mesh in one plane) is a mirror, and
// twosided, glass that passes nothing; on a curved mesh, where no mirror can be, it is glossy of the least
// roughness with the same reflectance.
void place_conductor(Surface& s, bool planar) {
    if (!s.smooth_conductor) return;
    if (!planar) {
        s.material.type = MaterialType::Glossy;
        s.material.roughness = kSmoothRoughness;
    } else if (s.two_sided) {
        s.material.type = MaterialType::Glass;
        s.two_sided = false;
    }
}

// The <bsdf> (or <ref>) and <emitter type="area"> of a shape.
void parse_material(const Context& ctx, Props& p, Surface& surface, Rgb& emission) {
    const std::vector<pugi::xml_node> bsdfs = p.objects({"bsdf", "ref"});
    if (bsdfs.size() > 1) ctx.src.fail(bsdfs[1], "a shape has one BSDF");
    if (!bsdfs.empty()) surface = parse_bsdf(ctx, bsdfs.front(), false);
    const std::vector<pugi::xml_node> emitters = p.objects({"emitter"});
    if (emitters.size() > 1) ctx.src.fail(emitters[1], "a shape has one emitter");
    if (emitters.empty()) return;
    Props e(ctx.src, emitters.front());
    if (e.type() != "area") e.fail("a shape's emitter must be of type \"area\"");
    const auto radiance = e.color("radiance");
    if (!radiance) e.fail("missing <rgb name=\"radiance\">");
    check_color(e, "radiance", *radiance, false);
    e.finish();
    emission = *radiance;
}

// A rectangle [-1, 1]^2 x {0} (normal +z) of local frame (a, b) around `centre`, mapped by `m`: corners
// M(centre - a - b), M(centre + a - b), ... The front side is the transformed normal (the inverse
// transpose), as Mitsuba has it, so a mirroring `m` swaps u and v. u = L(2a) rather than a difference of
// two mapped corners: the same numbers without a rounding.
RectangleShape map_rectangle(const Eigen::Matrix4d& m, const Vec3& centre, const Vec3& a, const Vec3& b) {
    const Eigen::Matrix3d l = m.block<3, 3>(0, 0);
    RectangleShape r;
    r.origin = apply_point(m, centre) - l * a - l * b;
    r.u = l * (2.0 * a);
    r.v = l * (2.0 * b);
    if (l.determinant() < 0.0) std::swap(r.u, r.v);
    return r;
}

std::vector<Object> cube_faces(const Eigen::Matrix4d& m, const Object& base) {
    static const char* const names[3] = {"x", "y", "z"};
    std::vector<Object> faces;
    for (int k = 0; k < 3; ++k)
        for (const double sign : {1.0, -1.0}) {
            Vec3 a = Vec3::Unit((k + 1) % 3), b = Vec3::Unit((k + 2) % 3);  // a x b = e_k
            if (sign < 0.0) std::swap(a, b);                                   // outward: -e_k
            Object face = base;
            face.shape = map_rectangle(m, sign * Vec3::Unit(k), a, b);
            face.json_path += std::string(" (cube face ") + (sign > 0 ? "+" : "-") + names[k] + ")";
            faces.push_back(std::move(face));
        }
    return faces;
}

fs::path mesh_file(const XmlSource& src, Props& p) {
    const auto name = p.string("filename");
    if (!name) p.fail("missing <string name=\"filename\">");
    if (name->empty()) src.fail(p.find("filename"), "is empty");
    fs::path file(*name);
    return file.is_relative() ? src.file().parent_path() / file : file;
}

void parse_shape(const Context& ctx, const pugi::xml_node& node, std::vector<Object>& objects) {
    Props p(ctx.src, node);
    const std::string type = p.type();
    if (type != "obj" && type != "ply" && type != "rectangle" && type != "cube")
        p.fail("unsupported shape type \"" + type + "\" (tprf reads obj, ply, rectangle and cube)");
    Object o;
    o.json_path = line_name(ctx.src, node, "shape");
    const Eigen::Matrix4d m = p.transform("to_world").value_or(Eigen::Matrix4d::Identity());
    if (m.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) ctx.src.fail(p.find("to_world"), "is not affine (last row 0 0 0 1)");
    if (std::abs(m.block<3, 3>(0, 0).determinant()) == 0.0) ctx.src.fail(p.find("to_world"), "is singular");
    Surface surface;
    parse_material(ctx, p, surface, o.emission);
    if (type == "obj" || type == "ply") {
        MeshShape mesh;
        mesh.file = mesh_file(ctx.src, p);
        mesh.transform = m;
        p.boolean("face_normals");  // tprf's patches are flat: face normals whatever this says
        o.shape = std::move(mesh);
    }
    p.finish();
    const auto* mesh = std::get_if<MeshShape>(&o.shape);
    place_conductor(surface, !mesh || !surface.smooth_conductor || planar_mesh(*mesh, ctx.src, o.json_path));
    // Mitsuba's area emitter lights the front alone, whatever the BSDF; a two-sided tprf object would
    // emit from both sides.
    if (surface.two_sided && (o.emission.array() > 0.0).any())
        ctx.src.fail(node, "an area emitter on a shape with a twosided BSDF: Mitsuba lights its front alone, a "
                           "two-sided tprf surface would emit from both sides (use a one-sided BSDF)");
    o.albedo = surface.albedo;
    o.two_sided = surface.two_sided;
    o.material = surface.material;
    if (type == "rectangle") {
        o.shape = map_rectangle(m, Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
        objects.push_back(std::move(o));
    } else if (type == "cube") {
        for (Object& face : cube_faces(m, o)) objects.push_back(std::move(face));
    } else {
        objects.push_back(std::move(o));
    }
}

void parse_point_light(const XmlSource& src, const pugi::xml_node& node, std::vector<Light>& lights) {
    Props p(src, node);
    if (p.type() != "point")
        p.fail("unsupported emitter type \"" + p.type() +
               "\" (tprf reads \"point\", and \"area\" inside a shape)");
    PointLight l;
    const auto intensity = p.color("intensity");
    if (!intensity) p.fail("missing <rgb name=\"intensity\">");
    check_color(p, "intensity", *intensity, false);
    l.intensity = *intensity;
    const auto position = p.point("position");
    const auto to_world = p.transform("to_world");
    if (position && to_world) p.fail("give either \"position\" or \"to_world\", not both");
    if (position) l.position = *position;
    if (to_world) l.position = apply_point(*to_world, Vec3::Zero());
    p.finish();
    lights.push_back(l);
}

// Every element with an id, at any depth, for <ref>; an id given twice is an error, as in Mitsuba.
void collect_ids(Context& ctx) {
    std::vector<pugi::xml_node> todo{ctx.src.root()};
    while (!todo.empty()) {
        const pugi::xml_node n = todo.back();
        todo.pop_back();
        for (const pugi::xml_node& child : n.children())
            if (child.type() == pugi::node_element) todo.push_back(child);
        const auto id = n.attribute("id");
        if (!id || std::string_view(n.name()) == "ref") continue;
        const auto [it, fresh] = ctx.ids.emplace(id.value(), n);
        if (!fresh) {
            // Name the later of the two in the message, whichever the walk met first.
            const bool later = ctx.src.line(n) >= ctx.src.line(it->second);
            ctx.src.fail(later ? n : it->second, "id given twice (also at line " +
                                                     std::to_string(ctx.src.line(later ? it->second : n)) + ")");
        }
    }
}

void parse_child(Context& ctx, const pugi::xml_node& n, Scene& scene) {
    const std::string_view tag = n.name();
    if (tag == "default") return;  // read by substitute_parameters
    if (tag == "shape") return parse_shape(ctx, n, scene.objects);
    if (tag == "emitter") return parse_point_light(ctx.src, n, scene.lights);
    if (tag == "bsdf") {
        if (!n.attribute("id")) ctx.src.fail(n, "a BSDF at the top needs an id (shapes refer to it with <ref id=...>)");
        parse_bsdf(ctx, n, false);  // checked even when no shape refers to it
        return;
    }
    if (tag == "sensor" || tag == "integrator") {
        pugi::xml_node& seen = tag == "sensor" ? ctx.sensor : ctx.integrator;
        if (seen) ctx.src.fail(n, "a second <" + std::string(tag) + "> (the first at line " + std::to_string(ctx.src.line(seen)) + ")");
        seen = n;
        if (tag == "sensor") mitsuba::parse_sensor(ctx.src, n, scene);
        else mitsuba::parse_integrator(ctx.src, n, scene, ctx.unwarp);
        return;
    }
    ctx.src.fail(n, "unsupported element (tprf reads <default>, <bsdf>, <shape>, <emitter>, <sensor> and <integrator>; "
                    "docs/mitsuba.md)");
}

// The text of the XML scene file.
std::string read_scene_text(const std::filesystem::path& file) {
    std::error_code ec;
    if (fs::is_directory(file, ec)) fail_input(file, "", "cannot read scene file (it is a directory)");
    errno = 0;
    std::ifstream in(file, std::ios::binary);
    if (!in) fail_input(file, "", "cannot read scene file" + open_reason(errno));
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) fail_input(file, "", "cannot read scene file");
    return text;
}

Scene build_scene(const XmlSource& src, const XmlDefines& defines) {
    const pugi::xml_node root = src.root();
    if (std::string_view(root.name()) != "scene") src.fail(root, "the root element must be <scene version=...>");
    mitsuba::check_attributes(src, root, {"version"});
    const std::vector<std::string> unused = mitsuba::substitute_parameters(src, defines);
    Context ctx{src, {}, {}, {}, false};
    collect_ids(ctx);
    Scene scene;
    scene.file = src.file();
    // A -D that no $name uses changes nothing (a misspelt name, most likely): said, not refused.
    for (const std::string& name : unused)
        scene.warnings.push_back("-D " + name + "=" + defines.find(name)->second + ": the scene has no parameter $" + name);
    for (const pugi::xml_node& n : root.children()) {
        if (n.type() != pugi::node_element) src.fail(root, "unexpected text inside <scene>");
        parse_child(ctx, n, scene);
    }
    if (!ctx.sensor)
        src.fail(root, "no <sensor>: tprf takes its time axis from the sensor's <film type=\"transient_hdr_film\">");
    if (scene.objects.empty()) src.fail(root, "no <shape>: a scene needs at least one surface");
    scene.camera->unwarp = ctx.unwarp;
    return scene;
}

}  // namespace

Scene parse_mitsuba_scene(const std::string& text, const std::filesystem::path& file, const XmlDefines& defines) {
    const XmlSource src(text, file);
    Scene scene = build_scene(src, defines);
    validate(scene);
    return scene;
}

Scene load_mitsuba_scene(const std::filesystem::path& file, const XmlDefines& defines) {
    return parse_mitsuba_scene(read_scene_text(file), file, defines);
}

}  // namespace tprf
