#include "tprf/scene/parse_mitsuba.h"

#include "tprf/core/error.h"
#include "tprf/scene/validate.h"
#include "mitsuba_xml.h"

#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <optional>
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
    Material material;                // a conductor or a thin dielectric: mirror or glass
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

Surface diffuse_bsdf(const Context& ctx, const pugi::xml_node& node);
Surface specular_bsdf(const Context& ctx, const pugi::xml_node& node, std::string_view type);

// <bsdf type="diffuse"> or <bsdf type="twosided"> around one, or a <ref> to either.
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
    if (type == "conductor" || type == "thindielectric") return specular_bsdf(ctx, node, type);
    if (type == "dielectric")
        ctx.src.fail(node, "a solid dielectric refracts, which tprf does not; a thin sheet of glass is "
                           "<bsdf type=\"thindielectric\"> (docs/materials.md)");
    if (type != "twosided")
        ctx.src.fail(node, "unsupported BSDF type " + std::string("\"") + type +
                               "\" (tprf reads \"diffuse\", \"conductor\", \"thindielectric\" and \"twosided\" "
                               "around a diffuse or conductor one)");
    if (inside_twosided) ctx.src.fail(node, "a twosided BSDF inside a twosided BSDF");
    Props p(ctx.src, node);
    const std::vector<pugi::xml_node> inner = p.objects({"bsdf", "ref"});
    p.finish();
    if (inner.size() != 1) p.fail("needs exactly one nested diffuse <bsdf> (tprf has no separate back side)");
    Surface s = parse_bsdf(ctx, inner.front(), true);
    if (s.material.type == MaterialType::Glass) ctx.src.fail(node, "a thin dielectric is two-sided already");
    if (s.material.type == MaterialType::Mirror) {
        // A mirror on both sides is glass that lets nothing through.
        s.material.type = MaterialType::Glass;
        return s;
    }
    s.two_sided = true;
    return s;
}

// <bsdf type="conductor"> as a mirror (material "none": Mitsuba's perfect mirror, times its
// specular_reflectance), <bsdf type="thindielectric"> as glass with the normal-incidence reflectance
// and transmittance of a thin sheet of relative index n: r = ((n - 1) / (n + 1))^2, R = 2r / (1 + r),
// T = (1 - r) / (1 + r). tprf's specular parts do not vary with the angle (docs/mitsuba.md).
Surface specular_bsdf(const Context& ctx, const pugi::xml_node& node, std::string_view type) {
    Props p(ctx.src, node);
    Surface s;
    s.albedo = Rgb::Zero();
    Rgb scale = Rgb::Ones();
    if (const auto r = p.color("specular_reflectance")) {
        scale = *r;
        check_color(p, "specular_reflectance", scale, true);
    }
    if (type == "conductor") {
        const auto material = p.string("material");
        if (material && *material != "none")
            p.fail("conductor material \"" + *material + "\": tprf's mirrors reflect alike at every angle; give "
                   "material \"none\" and a specular_reflectance");
        s.material.type = MaterialType::Mirror;
        s.material.reflectance = scale;
    } else {
        const double int_ior = p.number("int_ior").value_or(1.5046), ext_ior = p.number("ext_ior").value_or(1.000277);
        if (!(int_ior > 0.0) || !(ext_ior > 0.0)) p.fail("int_ior and ext_ior must be > 0 (numbers)");
        Rgb transmit = Rgb::Ones();
        if (const auto t = p.color("specular_transmittance")) {
            transmit = *t;
            check_color(p, "specular_transmittance", transmit, true);
        }
        const double n = int_ior / ext_ior, r = ((n - 1.0) / (n + 1.0)) * ((n - 1.0) / (n + 1.0));
        s.material.type = MaterialType::Glass;
        s.material.reflectance = scale * (2.0 * r / (1.0 + r));
        s.material.transmittance = transmit * ((1.0 - r) / (1.0 + r));
    }
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
    // Mitsuba's area emitter lights the front alone, whatever the BSDF; a two-sided tprf object would
    // emit from both sides.
    if (surface.two_sided && (o.emission.array() > 0.0).any())
        ctx.src.fail(node, "an area emitter on a shape with a twosided BSDF: Mitsuba lights its front alone, a "
                           "two-sided tprf surface would emit from both sides (use a one-sided diffuse BSDF)");
    o.albedo = surface.albedo;
    o.two_sided = surface.two_sided;
    o.material = surface.material;
    if (type == "obj" || type == "ply") {
        MeshShape mesh;
        mesh.file = mesh_file(ctx.src, p);
        mesh.transform = m;
        p.boolean("face_normals");  // tprf's patches are flat: face normals whatever this says
        o.shape = std::move(mesh);
    }
    p.finish();
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

Scene build_scene(const XmlSource& src, const XmlDefines& defines) {
    const pugi::xml_node root = src.root();
    if (std::string_view(root.name()) != "scene") src.fail(root, "the root element must be <scene version=...>");
    mitsuba::check_attributes(src, root, {"version"});
    mitsuba::substitute_parameters(src, defines);
    Context ctx{src, {}, {}, {}, false};
    collect_ids(ctx);
    Scene scene;
    scene.file = src.file();
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
    std::error_code ec;
    if (fs::is_directory(file, ec)) fail_input(file, "", "cannot read scene file (it is a directory)");
    std::ifstream in(file, std::ios::binary);
    if (!in) fail_input(file, "", "cannot read scene file");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) fail_input(file, "", "cannot read scene file");
    return parse_mitsuba_scene(text, file, defines);
}

}  // namespace tprf
