#include "mitsuba_xml.h"

#include "tprf/core/error.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <set>
#include <system_error>
#include <utility>

namespace tprf::mitsuba {

namespace {

bool is_one_of(std::string_view s, std::initializer_list<std::string_view> set) {
    return std::find(set.begin(), set.end(), s) != set.end();
}

bool is_property_tag(std::string_view tag) {
    return is_one_of(tag, {"float", "integer", "boolean", "string", "rgb", "spectrum", "point", "vector", "transform"});
}

// Strings here are appended piece by piece: GCC 12 reports a false -Wrestrict for "x" + std::string(s).
std::string quote(std::string_view s) {
    std::string out;
    out.reserve(s.size() + 2);
    out += '"';
    out.append(s);
    out += '"';
    return out;
}

// Pre-order successor of `node` below `root` (no recursion: a document may nest deeply).
pugi::xml_node next_in_document(pugi::xml_node node, const pugi::xml_node& root) {
    if (node.first_child()) return node.first_child();
    while (node && node != root) {
        if (node.next_sibling()) return node.next_sibling();
        node = node.parent();
    }
    return {};
}

// `value` with every "$name" of `params` replaced, longer names first (so that $ab is not read as $a).
// The names replaced are added to `used`.
std::string substitute(std::string value, const std::vector<std::pair<std::string, std::string>>& params,
                       std::set<std::string>& used) {
    for (const auto& [name, replacement] : params) {
        const std::string key = "$" + name;
        for (std::size_t at = value.find(key); at != std::string::npos; at = value.find(key, at + replacement.size())) {
            value.replace(at, key.size(), replacement);
            used.insert(name);
        }
    }
    return value;
}

void add_parameter(std::vector<std::pair<std::string, std::string>>& params, std::string name, std::string value) {
    for (const auto& p : params)
        if (p.first == name) return;  // the first definition wins: -D, then the first <default>
    params.emplace_back(std::move(name), std::move(value));
    std::stable_sort(params.begin(), params.end(),
                     [](const auto& a, const auto& b) { return a.first.size() > b.first.size(); });
}

Eigen::Vector3d xyz(const XmlSource& src, const pugi::xml_node& op, double missing) {
    Eigen::Vector3d v = Eigen::Vector3d::Constant(missing);
    if (const auto value = op.attribute("value")) {
        if (op.attribute("x") || op.attribute("y") || op.attribute("z"))
            src.fail(op, "give either \"value\" or \"x\", \"y\", \"z\", not both");
        const std::vector<std::string> t = tokens(value.value());
        if (t.size() != 1 && t.size() != 3) src.fail(op, "\"value\" must hold 1 or 3 numbers");
        for (int i = 0; i < 3; ++i) v[i] = to_number(src, op, t[t.size() == 1 ? 0 : std::size_t(i)]);
        return v;
    }
    const char* names[3] = {"x", "y", "z"};
    for (int i = 0; i < 3; ++i)
        if (const auto a = op.attribute(names[i])) v[i] = to_number(src, op, a.value());
    return v;
}

Eigen::Vector3d named_vector(const XmlSource& src, const pugi::xml_node& op, const char* name) {
    const std::vector<std::string> t = tokens(op.attribute(name).value());
    if (t.size() != 3) src.fail(op, quote(name) + " must hold 3 numbers");
    return {to_number(src, op, t[0]), to_number(src, op, t[1]), to_number(src, op, t[2])};
}

// Mitsuba's look_at: columns left = normalize(up x dir), up' = dir x left, dir, origin. Without `up` (or
// with a zero one), the first axis of the frame Mitsuba builds around dir (Duff et al. 2017, "Building an
// orthonormal basis").
Eigen::Matrix4d look_at(const XmlSource& src, const pugi::xml_node& op) {
    check_attributes(src, op, {"origin", "target", "up"});
    const Eigen::Vector3d origin = named_vector(src, op, "origin");
    const Eigen::Vector3d target = named_vector(src, op, "target");
    const Eigen::Vector3d dir = (target - origin).normalized();
    if ((target - origin).norm() == 0.0 || !dir.allFinite()) src.fail(op, "origin and target are the same point");
    // An `up` of zero is no up at all (Mitsuba builds the frame around dir then too).
    Eigen::Vector3d up = op.attribute("up") ? named_vector(src, op, "up") : Eigen::Vector3d::Zero();
    if (up.squaredNorm() == 0.0) {
        const double sign = std::copysign(1.0, dir.z()), a = -1.0 / (sign + dir.z()), b = dir.x() * dir.y() * a;
        up = {1.0 + sign * dir.x() * dir.x() * a, sign * b, -sign * dir.x()};
    }
    const Eigen::Vector3d left = up.cross(dir).normalized();
    if (up.cross(dir).norm() == 0.0 || !left.allFinite()) src.fail(op, "up is zero or parallel to target - origin");
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.block<3, 1>(0, 0) = left;
    m.block<3, 1>(0, 1) = dir.cross(left);
    m.block<3, 1>(0, 2) = dir;
    m.block<3, 1>(0, 3) = origin;
    return m;
}

Eigen::Matrix4d matrix_op(const XmlSource& src, const pugi::xml_node& op) {
    check_attributes(src, op, {"value"});
    const std::vector<std::string> t = tokens(op.attribute("value").value());
    if (t.size() != 16 && t.size() != 9) src.fail(op, "\"value\" must hold 16 (or 9) numbers, row-major");
    const int n = t.size() == 16 ? 4 : 3;
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    for (int r = 0; r < n; ++r)
        for (int c = 0; c < n; ++c) m(r, c) = to_number(src, op, t[std::size_t(r * n + c)]);
    return m;
}

// One operation of a <transform> as a matrix. The rotation is built as the JSON parser builds its own
// (Eigen's angle-axis of angle * pi / 180), so that the same rotation gives the same bits.
Eigen::Matrix4d operation(const XmlSource& src, const pugi::xml_node& op) {
    const std::string_view tag = op.name();
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    if (tag == "translate" || tag == "scale") {
        check_attributes(src, op, {"value", "x", "y", "z"});
        const Eigen::Vector3d v = xyz(src, op, tag == "scale" ? 1.0 : 0.0);
        if (tag == "translate") m.block<3, 1>(0, 3) = v;
        else m.diagonal().head<3>() = v;
    } else if (tag == "rotate") {
        check_attributes(src, op, {"value", "x", "y", "z", "angle"});
        const Eigen::Vector3d axis = xyz(src, op, 0.0);
        if (!op.attribute("angle")) src.fail(op, "missing attribute \"angle\" (degrees)");
        if (axis.norm() == 0.0) src.fail(op, "the rotation axis is zero");
        const double angle = to_number(src, op, op.attribute("angle").value()) * std::numbers::pi / 180.0;
        m.block<3, 3>(0, 0) = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
    } else if (tag == "matrix") {
        m = matrix_op(src, op);
    } else if (tag == "lookat") {
        m = look_at(src, op);
    } else {
        src.fail(op, "not a transform operation (translate, scale, rotate, matrix or lookat)");
    }
    if (!m.allFinite()) src.fail(op, "gives a matrix that is not finite");
    return m;
}

}  // namespace

XmlSource::XmlSource(const std::string& text, std::filesystem::path file) : m_file(std::move(file)) {
    m_line_starts.push_back(0);
    for (std::size_t i = 0; i < text.size(); ++i)
        if (text[i] == '\n') m_line_starts.push_back(std::ptrdiff_t(i + 1));
    const pugi::xml_parse_result r = m_doc.load_buffer(text.data(), text.size(), pugi::parse_default, pugi::encoding_utf8);
    if (!r)
        throw Error(m_file.string() + ":" + std::to_string(line_at(r.offset)) + ": malformed XML: " + r.description());
    int elements = 0;
    for (const pugi::xml_node& n : m_doc.children()) {
        if (n.type() == pugi::node_element) ++elements;
        else if (n.type() != pugi::node_doctype) fail(n, "unexpected content outside the root element");
    }
    if (elements != 1) throw Error(m_file.string() + ":1: expected one root element <scene version=...>");
}

int XmlSource::line_at(std::ptrdiff_t offset) const {
    if (offset < 0) return 0;
    return int(std::upper_bound(m_line_starts.begin(), m_line_starts.end(), offset) - m_line_starts.begin());
}

int XmlSource::line(const pugi::xml_node& node) const { return line_at(node.offset_debug()); }

void XmlSource::fail(const pugi::xml_node& node, std::string_view what) const {
    throw Error(m_file.string() + ":" + std::to_string(line(node)) + ": " + describe(node) + ": " + std::string(what));
}

std::string describe(const pugi::xml_node& node) {
    if (node.type() != pugi::node_element) return "text";
    std::string s = "<";
    s.append(node.name());
    for (const char* key : {"type", "name", "id"})
        if (const auto a = node.attribute(key)) s.append(" ").append(key).append("=").append(quote(a.value()));
    return s + ">";
}

std::vector<std::string> substitute_parameters(const XmlSource& src, const XmlDefines& defines) {
    std::vector<std::pair<std::string, std::string>> params;
    std::set<std::string> used;
    for (const auto& [name, value] : defines) add_parameter(params, name, value);
    const pugi::xml_node root = src.root();
    for (pugi::xml_node n = root; n; n = next_in_document(n, root)) {
        if (n.type() != pugi::node_element) continue;
        for (pugi::xml_attribute a : n.attributes()) {
            const std::string_view value = a.value();
            if (value.find('$') == std::string_view::npos) continue;
            const std::string replaced = substitute(std::string(value), params, used);
            if (replaced.find('$') != std::string::npos)
                src.fail(n, "undefined parameter in " + quote(value) + " (give it a <default> or -D name=value)");
            a.set_value(replaced.c_str());
        }
        if (std::string_view(n.name()) != "default") continue;
        if (n.parent() != root) src.fail(n, "<default> must be a child of the root element");
        check_attributes(src, n, {"name", "value"});
        const std::string name = n.attribute("name").value();
        if (name.empty() || !n.attribute("value")) src.fail(n, "needs a non-empty \"name\" and a \"value\"");
        add_parameter(params, name, n.attribute("value").value());
    }
    std::vector<std::string> unused;
    for (const auto& define : defines)
        if (!used.contains(define.first)) unused.push_back(define.first);
    return unused;
}

std::vector<std::string> tokens(std::string_view text) {
    std::vector<std::string> out;
    std::string current;
    for (const char c : text) {
        if (c == ',' || c == ' ' || c == '\t' || c == '\n' || c == '\r') {
            if (!current.empty()) out.push_back(std::move(current));
            current.clear();
        } else {
            current += c;
        }
    }
    if (!current.empty()) out.push_back(std::move(current));
    return out;
}

double to_number(const XmlSource& src, const pugi::xml_node& node, std::string_view text) {
    std::string_view t = text;
    while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
    while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
    if (t.size() > 1 && t.front() == '+' && t[1] != '-') t.remove_prefix(1);
    double v = 0.0;
    const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (t.empty() || ec != std::errc() || end != t.data() + t.size() || !std::isfinite(v))
        src.fail(node, "expected a finite number, got " + quote(text));
    return v;
}

void check_attributes(const XmlSource& src, const pugi::xml_node& node,
                      std::initializer_list<std::string_view> allowed) {
    for (const pugi::xml_attribute& a : node.attributes())
        if (!is_one_of(a.name(), allowed)) src.fail(node, "unknown attribute " + quote(a.name()));
}

Eigen::Matrix4d parse_transform(const XmlSource& src, const pugi::xml_node& transform) {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    for (const pugi::xml_node& op : transform.children()) {
        if (op.type() != pugi::node_element) src.fail(transform, "unexpected text inside <transform>");
        m = operation(src, op) * m;
    }
    return m;
}

Props::Props(const XmlSource& src, pugi::xml_node object) : m_src(src), m_node(object) {
    check_attributes(src, object, {"type", "id", "name"});
    if (!object.attribute("type")) src.fail(object, "missing attribute \"type\"");
    for (const pugi::xml_node& n : object.children()) {
        if (n.type() != pugi::node_element) src.fail(object, "unexpected text inside the element");
        Child c{n, n.attribute("name").value(), is_property_tag(n.name())};
        if (c.property) {
            if (c.name.empty()) src.fail(n, "missing attribute \"name\"");
            for (const Child& other : m_children)
                if (other.property && other.name == c.name)
                    src.fail(n, "property " + quote(c.name) + " given twice (first at line " +
                                    std::to_string(src.line(other.node)) + ")");
        }
        m_children.push_back(std::move(c));
    }
}

pugi::xml_node Props::find(std::string_view name) const {
    for (const Child& c : m_children)
        if (c.property && c.name == name) return c.node;
    return {};
}

const Props::Child* Props::take(std::string_view name, std::initializer_list<std::string_view> tags) {
    for (Child& c : m_children) {
        if (!c.property || c.name != name) continue;
        if (!is_one_of(c.node.name(), tags)) {
            std::string expected;
            for (const std::string_view t : tags) expected += (expected.empty() ? "<" : " or <") + std::string(t) + ">";
            m_src.fail(c.node, "expected " + expected);
        }
        c.taken = true;
        return &c;
    }
    return nullptr;
}

std::string Props::value_of(const pugi::xml_node& node) const {
    check_attributes(m_src, node, {"name", "value"});
    if (!node.attribute("value")) m_src.fail(node, "missing attribute \"value\"");
    if (node.first_child()) m_src.fail(node, "unexpected content inside a property");
    return node.attribute("value").value();
}

std::optional<double> Props::number(std::string_view name) {
    const Child* c = take(name, {"float"});
    if (!c) return std::nullopt;
    return to_number(m_src, c->node, value_of(c->node));
}

std::optional<int> Props::integer(std::string_view name) {
    const Child* c = take(name, {"integer"});
    if (!c) return std::nullopt;
    const std::string value = value_of(c->node);
    std::string_view t = value;
    while (!t.empty() && t.front() == ' ') t.remove_prefix(1);
    while (!t.empty() && t.back() == ' ') t.remove_suffix(1);
    int v = 0;
    const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (t.empty() || ec != std::errc() || end != t.data() + t.size())
        m_src.fail(c->node, "expected an integer that fits 32 bits, got " + quote(c->node.attribute("value").value()));
    return v;
}

std::optional<bool> Props::boolean(std::string_view name) {
    const Child* c = take(name, {"boolean"});
    if (!c) return std::nullopt;
    std::string v = value_of(c->node);
    std::transform(v.begin(), v.end(), v.begin(), [](unsigned char ch) { return char(std::tolower(ch)); });
    if (v != "true" && v != "false") m_src.fail(c->node, "expected \"true\" or \"false\", got " + quote(v));
    return v == "true";
}

std::optional<std::string> Props::string(std::string_view name) {
    const Child* c = take(name, {"string"});
    if (!c) return std::nullopt;
    return value_of(c->node);
}

std::optional<Rgb> Props::color(std::string_view name) {
    const Child* c = take(name, {"rgb", "float", "spectrum"});
    if (!c) return std::nullopt;
    if (std::string_view(c->node.name()) == "spectrum")
        m_src.fail(c->node, "tprf renders in RGB: give the colour as <rgb> or <float>");
    const std::vector<std::string> t = tokens(value_of(c->node));
    if (t.size() != 1 && (t.size() != 3 || std::string_view(c->node.name()) == "float"))
        m_src.fail(c->node, "expected 1 or 3 numbers (<float>: 1)");
    Rgb rgb;
    for (int i = 0; i < 3; ++i) rgb[i] = to_number(m_src, c->node, t[t.size() == 1 ? 0 : std::size_t(i)]);
    return rgb;
}

std::optional<Vec3> Props::point(std::string_view name) {
    const Child* c = take(name, {"point", "vector"});
    if (!c) return std::nullopt;
    check_attributes(m_src, c->node, {"name", "value", "x", "y", "z"});
    if (c->node.first_child()) m_src.fail(c->node, "unexpected content inside a property");
    return xyz(m_src, c->node, 0.0);
}

std::optional<Eigen::Matrix4d> Props::transform(std::string_view name) {
    const Child* c = take(name, {"transform"});
    if (!c) return std::nullopt;
    check_attributes(m_src, c->node, {"name"});
    return parse_transform(m_src, c->node);
}

std::vector<pugi::xml_node> Props::objects(std::initializer_list<std::string_view> tags) {
    std::vector<pugi::xml_node> out;
    for (Child& c : m_children)
        if (!c.property && !c.taken && is_one_of(c.node.name(), tags)) {
            c.taken = true;
            out.push_back(c.node);
        }
    return out;
}

void Props::finish() const {
    for (const Child& c : m_children) {
        if (c.taken) continue;
        if (c.property)
            m_src.fail(c.node, "unknown property of " + describe(m_node) + " (tprf reads the subset in docs/mitsuba.md)");
        m_src.fail(c.node, "unsupported inside " + describe(m_node) + " (tprf reads the subset in docs/mitsuba.md)");
    }
}

}  // namespace tprf::mitsuba
