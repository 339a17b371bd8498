#include "tprf/scene/parse_json.h"

#include "tprf/core/error.h"
#include "tprf/scene/validate.h"
#include "json_node.h"

#include <cctype>
#include <cmath>
#include <cstddef>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <string>
#include <string_view>
#include <utility>

namespace tprf {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Only what the JSON text decides is checked here: keys, types, array lengths, enum names, and inputs
// that the Scene does not keep (a laser's target, a transform's scale and axis, a gate step). Ranges and
// geometry are checked by validate() on the built Scene, whatever built it.

using Node = JsonNode;

// The enum value that `n` names among `choices`; else one error that says what `n` is and what it may be.
template <class E>
E parse_choice(const Node& n, std::string_view what, std::initializer_list<std::pair<std::string_view, E>> choices) {
    const std::string name = n.string();
    std::string expected;
    for (const auto& [key, value] : choices) {
        if (name == key) return value;
        if (!expected.empty()) expected += " or ";
        expected += in_quotes(key);
    }
    n.fail("unknown " + std::string(what) + " " + in_quotes(name) + " (expected " + expected + ")");
}

Camera parse_camera(const Node& n) {
    n.check_keys({"position", "look_at", "up", "fov", "intrinsics", "distortion", "width", "height", "spp", "unwarp",
                  "footprint", "shift_second_bounce"});
    Camera c;
    c.position = n.child("position").vec3();
    c.look_at = n.child("look_at").vec3();
    c.up = n.child("up").vec3();
    const auto fov = n.find("fov");
    const auto intrinsics = n.find("intrinsics");
    if (fov && intrinsics) n.fail("give either \"fov\" or \"intrinsics\", not both");
    if (intrinsics) {
        intrinsics->check_keys({"fx", "fy", "cx", "cy"});
        c.intrinsics = Intrinsics{intrinsics->child("fx").number(), intrinsics->child("fy").number(),
                                  intrinsics->child("cx").number(), intrinsics->child("cy").number()};
    } else {
        c.fov_deg = n.child("fov").number();  // "missing key fov" when neither is there
    }
    if (const auto distortion = n.find("distortion")) {
        distortion->check_keys({"k1", "k2", "k3", "p1", "p2"});
        const auto coefficient = [&](const char* key) {
            const auto value = distortion->find(key);
            return value ? value->number() : 0.0;
        };
        c.distortion = {coefficient("k1"), coefficient("k2"), coefficient("k3"), coefficient("p1"), coefficient("p2")};
    }
    c.width = n.child("width").integer();
    c.height = n.child("height").integer();
    if (const auto spp = n.find("spp")) c.spp = spp->integer();
    if (const auto unwarp = n.find("unwarp")) c.unwarp = unwarp->boolean();
    if (const auto footprint = n.find("footprint")) c.footprint = footprint->boolean();
    if (const auto shift = n.find("shift_second_bounce")) c.shift_second_bounce = shift->boolean();
    return c;
}

// A zero direction is kept as it is, for validate() to name. Where the squared norm underflows or
// overflows, rescaling first keeps a tiny or huge but valid direction exact.
Vec3 unit_or_zero(const Vec3& d) {
    if (d.norm() == 0.0) return d;
    const double squared = d.squaredNorm();
    const bool in_range = std::isfinite(squared) && squared >= std::numeric_limits<double>::min();
    return in_range ? d.normalized() : d.stableNormalized();
}

// A beam's or cone's unit direction from `direction` or from `target` seen from `from`, one of them.
Vec3 parse_aim(const Node& n, const Vec3& from, std::string_view from_key) {
    const auto direction = n.find("direction");
    const auto target = n.find("target");
    if (direction && target) n.fail("give either \"direction\" or \"target\", not both");
    if (direction) return unit_or_zero(direction->vec3());
    if (!target) n.fail("missing key \"direction\" or \"target\"");
    const Vec3 d = target->vec3() - from;
    if (d.norm() == 0.0) target->fail("equals " + std::string(from_key) + ", so there is no direction");
    return unit_or_zero(d);
}

Light parse_laser(const Node& n) {
    n.check_keys({"type", "origin", "direction", "target", "power"});
    Laser l;
    l.origin = n.child("origin").vec3();
    l.direction = parse_aim(n, l.origin, "origin");
    l.power = n.child("power").rgb();
    return l;
}

Light parse_light(const Node& n) {
    const Node type = n.child("type");
    const std::string name = type.string();
    if (name == "laser") return parse_laser(n);
    if (name != "point" && name != "spot")
        type.fail("unknown light type " + in_quotes(name) + " (expected \"point\", \"spot\" or \"laser\")");
    if (name == "point") n.check_keys({"type", "position", "intensity"});
    else n.check_keys({"type", "position", "intensity", "direction", "target", "half_angle", "falloff"});
    PointLight p;
    p.position = n.child("position").vec3();
    p.intensity = n.child("intensity").rgb();
    if (name == "spot") {
        p.spot = true;
        p.direction = parse_aim(n, p.position, "position");
        p.half_angle_deg = n.child("half_angle").number();
        if (const auto falloff = n.find("falloff")) p.falloff_deg = falloff->number();
    }
    return p;
}

RectangleShape parse_rectangle(const Node& n) {
    RectangleShape r;
    r.origin = n.child("origin").vec3();
    r.u = n.child("u").vec3();
    r.v = n.child("v").vec3();
    return r;
}

// The 16 numbers, row-major; validate() checks that they are affine and not singular.
Eigen::Matrix4d parse_matrix(const Node& n) {
    if (!n.j.is_array() || n.j.size() != 16) n.fail("expected an array of 16 numbers (row-major 4x4)");
    Eigen::Matrix4d m;
    for (Eigen::Index r = 0; r < 4; ++r)
        for (Eigen::Index c = 0; c < 4; ++c) m(r, c) = n.at(static_cast<std::size_t>(4 * r + c)).number();
    return m;
}

Eigen::Matrix4d parse_transform(const Node& n) {
    n.check_keys({"matrix", "translate", "scale", "rotate"});
    if (const auto matrix = n.find("matrix")) {
        if (n.has("translate") || n.has("scale") || n.has("rotate"))
            n.fail("\"matrix\" cannot be combined with translate, scale or rotate");
        return parse_matrix(*matrix);
    }
    Eigen::Affine3d t = Eigen::Affine3d::Identity();
    if (const auto translate = n.find("translate")) t.translate(translate->vec3());
    if (const auto rotate = n.find("rotate")) {
        rotate->check_keys({"axis", "angle"});
        const Node axis_node = rotate->child("axis");
        const Vec3 axis = axis_node.vec3();
        if (axis.norm() == 0.0) axis_node.fail("has zero length");
        const double angle = rotate->child("angle").number() * std::numbers::pi / 180.0;
        t.rotate(Eigen::AngleAxisd(angle, axis.normalized()));
    }
    if (const auto scale = n.find("scale")) {
        const Vec3 s = scale->j.is_number() ? Vec3::Constant(scale->number()) : scale->vec3();
        if ((s.array() == 0.0).any()) scale->fail("must not be 0 (the mesh would have no area)");
        t.scale(s);
    }
    // Eigen's translate/rotate/scale multiply on the right, so building T, then R, then S gives T*R*S:
    // scale applied first, then rotate, then translate.
    return t.matrix();
}

// Relative to the scene file; validate() checks that it can be read. An empty name is refused here,
// since resolved it would name the scene's directory.
fs::path parse_mesh_file(const Node& n) {
    const std::string name = n.string();
    if (name.empty()) n.fail("is empty");
    fs::path p(name);
    if (p.is_relative()) p = n.file.parent_path() / p;
    return p;
}

// The `material` block. Its `albedo` (the diffuse part; a plastic's base) may be given there or on the
// object, not both; a mirror, glass or glossy object without one has no diffuse part.
void parse_material(const Node& n, bool object_albedo, Object& o) {
    const Node type = n.child("type");
    const std::string name = type.string();
    Material& m = o.material;
    if (name == "diffuse") {
        n.check_keys({"type", "albedo"});
    } else if (name == "mirror") {
        n.check_keys({"type", "reflectance", "albedo"});
        m.type = MaterialType::Mirror;
        m.reflectance = n.child("reflectance").rgb();
    } else if (name == "glass") {
        n.check_keys({"type", "reflectance", "transmittance", "albedo"});
        m.type = MaterialType::Glass;
        m.reflectance = n.child("reflectance").rgb();
        m.transmittance = n.child("transmittance").rgb();
    } else if (name == "glossy") {
        n.check_keys({"type", "reflectance", "roughness", "albedo"});
        m.type = MaterialType::Glossy;
        m.reflectance = n.child("reflectance").rgb();
        if (const auto roughness = n.find("roughness")) m.roughness = roughness->number();
    } else if (name == "plastic") {
        n.check_keys({"type", "roughness", "ior", "albedo"});
        m.type = MaterialType::Plastic;
        if (const auto roughness = n.find("roughness")) m.roughness = roughness->number();
        if (const auto ior = n.find("ior")) m.ior = ior->number();
    } else {
        type.fail("unknown material type " + in_quotes(name) +
                  R"( (expected "diffuse", "mirror", "glass", "glossy" or "plastic"))");
    }
    if (const auto albedo = n.find("albedo")) {
        if (object_albedo) albedo->fail("the object gives an albedo too; give it in one place");
        o.albedo = albedo->rgb();
    } else if ((m.specular() || m.type == MaterialType::Glossy) && !object_albedo) {
        o.albedo = Rgb::Zero();  // a mirror's, glass's or rough metal's diffuse part is what is asked for
    }
}

Object parse_object(const Node& n) {
    const Node type = n.child("type");
    const std::string name = type.string();
    Object o;
    o.json_path = n.path;
    if (name == "rectangle") {
        n.check_keys({"type", "origin", "u", "v", "albedo", "emission", "two_sided", "material"});
        o.shape = parse_rectangle(n);
    } else if (name == "mesh") {
        n.check_keys({"type", "file", "transform", "albedo", "emission", "two_sided", "material"});
        MeshShape m;
        m.file = parse_mesh_file(n.child("file"));
        if (const auto transform = n.find("transform")) m.transform = parse_transform(*transform);
        o.shape = std::move(m);
    } else {
        type.fail("unknown object type " + in_quotes(name) + " (expected \"rectangle\" or \"mesh\")");
    }
    const auto albedo = n.find("albedo");
    if (albedo) o.albedo = albedo->rgb();
    if (const auto material = n.find("material")) parse_material(*material, albedo.has_value(), o);
    if (const auto emission = n.find("emission")) o.emission = emission->rgb();
    if (const auto two_sided = n.find("two_sided")) o.two_sided = two_sided->boolean();
    return o;
}

SolverSettings parse_solver(const Node& n) {
    n.check_keys({"max_bounces", "delay", "bounces", "max_specular"});
    SolverSettings s;
    if (const auto max_bounces = n.find("max_bounces")) {
        s.max_bounces = max_bounces->integer();
        // -1 is the Scene's "every bounce", which a scene file says by leaving the key out; validate()
        // refuses the other negative counts.
        if (s.max_bounces == -1) max_bounces->fail("must be >= 0");
    }
    if (const auto delay = n.find("delay"))
        s.delay = parse_choice<DelayMode>(*delay, "delay mode",
                                          {{"nearest", DelayMode::Nearest}, {"linear", DelayMode::Linear}});
    if (const auto bounces = n.find("bounces")) s.bounces = bounces->boolean();
    if (const auto max_specular = n.find("max_specular")) s.max_specular = max_specular->integer();
    return s;
}

TimeAxis parse_time(const JsonNode& n) {
    n.check_keys({"bins", "bin_width", "start", "unit"});
    TimeAxis t;
    t.bins = n.child("bins").integer();
    t.bin_width = n.child("bin_width").number();
    if (const auto start = n.find("start")) t.start = start->number();
    if (const auto unit = n.find("unit"))
        t.unit = parse_choice<TimeUnit>(*unit, "time unit", {{"m", TimeUnit::Metres}, {"ps", TimeUnit::Picoseconds}});
    return t;
}

// 0 is the Scene's "absent" (build_patches picks a size), so written out it is refused here;
// validate() refuses negative sizes.
double parse_max_edge(const Node& n) {
    const double max_edge = n.number();
    if (max_edge == 0.0) n.fail("must be > 0");
    return max_edge;
}

LinkSettings parse_links(const Node& n) {
    n.check_keys({"method", "tolerance", "time_bins", "spread_pieces", "glossy_resolution"});
    LinkSettings links;
    if (const auto method = n.find("method"))
        links.method = parse_choice<LinkMethod>(*method, "link method",
                                                {{"hierarchical", LinkMethod::Hierarchical}, {"flat", LinkMethod::Flat}});
    if (const auto tolerance = n.find("tolerance")) links.tolerance = tolerance->number();
    if (const auto time_bins = n.find("time_bins")) links.time_bins = time_bins->number();
    if (const auto pieces = n.find("spread_pieces")) links.spread_pieces = pieces->integer();
    if (const auto rings = n.find("glossy_resolution")) {
        if (rings->j.is_string()) {
            if (rings->string() != "auto") rings->fail("must be \"auto\" or an integer in [0, 8]");
            links.glossy_resolution = kGlossyAuto;
        } else {
            links.glossy_resolution = rings->integer();
        }
    }
    return links;
}

// Builds the Scene from the document without judging its values: validate() does that afterwards.
Scene build_scene(const nlohmann::json& root, const std::filesystem::path& file) {
    if (!root.is_object()) fail_input(file, "", "the top level must be a JSON object");
    const Node n{root, "", file};
    n.check_keys({"time", "camera", "lights", "objects", "patches", "links", "solver", "sensor", "capture"});

    Scene scene;
    scene.file = file;
    scene.time = parse_time(n.child("time"));
    if (const auto camera = n.find("camera")) scene.camera = parse_camera(*camera);
    if (const auto lights = n.find("lights")) {
        const std::size_t count = lights->array_size();
        for (std::size_t i = 0; i < count; ++i) scene.lights.push_back(parse_light(lights->at(i)));
    }
    const Node objects = n.child("objects");
    const std::size_t count = objects.array_size();
    for (std::size_t i = 0; i < count; ++i) scene.objects.push_back(parse_object(objects.at(i)));
    if (const auto patches = n.find("patches")) {
        patches->check_keys({"max_edge"});
        if (const auto max_edge = patches->find("max_edge")) scene.max_edge = parse_max_edge(*max_edge);
    }
    if (const auto links = n.find("links")) scene.links = parse_links(*links);
    if (const auto solver = n.find("solver")) scene.solver = parse_solver(*solver);
    if (const auto sensor = n.find("sensor")) scene.sensor = parse_sensor(*sensor);
    if (const auto capture = n.find("capture")) scene.capture = parse_capture(*capture);
    return scene;
}

}  // namespace

Scene parse_scene(const std::string& text, const std::filesystem::path& file) {
    Scene scene = build_scene(parse_json_text(text, file), file);
    validate(scene);
    return scene;
}

Scene load_scene(const std::filesystem::path& file) { return load_scene(file, XmlDefines{}); }

Scene load_scene(const std::filesystem::path& file, const XmlDefines& defines) {
    std::string extension = file.extension().string();
    for (char& c : extension) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (extension == ".xml") return load_mitsuba_scene(file, defines);
    if (!defines.empty()) fail_input(file, "", "-D applies to Mitsuba XML scenes only");
    Scene scene = build_scene(read_json_file(file, "scene file"), file);
    validate(scene);
    return scene;
}

TimeAxis parse_time_block(const std::string& text, const std::filesystem::path& file, std::string_view json_path) {
    const nlohmann::json root = parse_json_text(text, file);
    const TimeAxis time = parse_time(JsonNode{root, std::string(json_path), file});
    validate_time(time, file, std::string(json_path));
    return time;
}

TimeAxis read_render_time(const std::filesystem::path& render_json) {
    const nlohmann::json info = read_json_file(render_json, "render.json");
    const JsonNode root{info, "", render_json};
    root.expect_object();
    const TimeAxis time = parse_time(root.child("time"));
    validate_time(time, render_json, "time");
    return time;
}

}  // namespace tprf
