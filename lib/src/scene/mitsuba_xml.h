#pragma once
/// Private to the scene stage (not installed). Typed reading of Mitsuba 3 XML (scene/parse_mitsuba.h):
/// the document with line numbers for messages, `$name` parameters, and the properties of one object
/// element, each of which must be asked for: whatever is left is an error, as in Mitsuba itself.

#include "tprf/core/types.h"
#include "tprf/scene/parse_mitsuba.h"
#include "tprf/scene/scene.h"

#include <pugixml.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tprf::mitsuba {

/// A parsed XML document and its file: every message says "FILE:LINE: <element>: what is wrong".
class XmlSource {
public:
    /// Parses `text`; malformed XML throws tprf::Error "FILE:LINE: malformed XML: why".
    XmlSource(const std::string& text, std::filesystem::path file);
    XmlSource(const XmlSource&) = delete;
    XmlSource& operator=(const XmlSource&) = delete;

    const std::filesystem::path& file() const { return m_file; }
    /// The root element (checked to be the only element at the top).
    pugi::xml_node root() const { return m_doc.document_element(); }
    /// The 1-based line where `node` starts (0 when pugixml does not know).
    int line(const pugi::xml_node& node) const;
    /// Throws tprf::Error "FILE:LINE: <tag type=...>: what".
    [[noreturn]] void fail(const pugi::xml_node& node, std::string_view what) const;

private:
    int line_at(std::ptrdiff_t offset) const;

    std::filesystem::path m_file;
    std::vector<std::ptrdiff_t> m_line_starts;  ///< byte offset of each line's first character
    pugi::xml_document m_doc;
};

/// An element as messages name it: `<shape type="obj">`, `<float name="fov">`, `<ref id="white">`.
std::string describe(const pugi::xml_node& node);

/// Replaces `$name` in every attribute value, in document order, by the command line's `defines` or
/// else by the `<default name value>` seen before (Mitsuba's rule: longer names first; an undefined
/// `$` is an error). `<default>` must be a child of the root. Returns the names of `defines` that no
/// `$name` refers to (they change nothing), in name order.
std::vector<std::string> substitute_parameters(const XmlSource& src, const XmlDefines& defines);

/// The words of an attribute value, split at commas and white space.
std::vector<std::string> tokens(std::string_view text);

/// A finite number written in `text` (an attribute of `node`, for the message).
double to_number(const XmlSource& src, const pugi::xml_node& node, std::string_view text);

/// Refuses attributes of `node` not in `allowed`.
void check_attributes(const XmlSource& src, const pugi::xml_node& node,
                      std::initializer_list<std::string_view> allowed);

/// The 4x4 matrix of a `<transform>`: its operations (translate, scale, rotate, matrix, lookat)
/// composed in document order, each applied after those before it (M = op * M), as Mitsuba does.
Eigen::Matrix4d parse_transform(const XmlSource& src, const pugi::xml_node& transform);

/// The children of one object element (`<shape>`, `<bsdf>`, `<sensor>`, ...): named properties and
/// nested objects. Each accessor takes what it returns; finish() refuses whatever was not taken, so that
/// nothing in the file is silently ignored.
class Props {
public:
    /// Reads the children of `object` and checks its attributes (type, id, name).
    Props(const XmlSource& src, pugi::xml_node object);

    pugi::xml_node node() const { return m_node; }
    std::string type() const { return m_node.attribute("type").value(); }
    const XmlSource& source() const { return m_src; }
    [[noreturn]] void fail(std::string_view what) const { m_src.fail(m_node, what); }

    std::optional<double> number(std::string_view name);        ///< `<float>`
    std::optional<int> integer(std::string_view name);          ///< `<integer>`
    std::optional<bool> boolean(std::string_view name);         ///< `<boolean>`
    std::optional<std::string> string(std::string_view name);   ///< `<string>`
    std::optional<Rgb> color(std::string_view name);            ///< `<rgb>` (1 or 3 values) or `<float>`
    std::optional<Vec3> point(std::string_view name);           ///< `<point>` or `<vector>`
    std::optional<Eigen::Matrix4d> transform(std::string_view name);  ///< `<transform>`
    /// The property element named `name` (taken or not), or an empty node.
    pugi::xml_node find(std::string_view name) const;
    /// Nested objects and `<ref>`s whose tag is one of `tags`, taken, in document order.
    std::vector<pugi::xml_node> objects(std::initializer_list<std::string_view> tags);
    /// Throws for the first child that was not taken, naming it.
    void finish() const;

private:
    struct Child {
        pugi::xml_node node;
        std::string name;       ///< the `name` attribute of a property ("" for an object)
        bool property = false;  ///< a typed property (float, rgb, transform, ...)
        bool taken = false;
    };
    /// The property `name`, taken, with its tag checked against `tags`; nullptr when absent.
    const Child* take(std::string_view name, std::initializer_list<std::string_view> tags);
    /// The `value` attribute of a property element, checked to be its only attribute beside `name`.
    std::string value_of(const pugi::xml_node& node) const;

    const XmlSource& m_src;
    pugi::xml_node m_node;
    std::vector<Child> m_children;
};

/// A `<sensor type="perspective">` with its sampler and film: scene.camera and scene.time
/// (parse_mitsuba_sensor.cpp).
void parse_sensor(const XmlSource& src, const pugi::xml_node& node, Scene& scene);

/// An `<integrator>` (transient_path or path): scene.solver.max_bounces and camera.unwarp (the camera,
/// when the sensor comes later, gets it then).
void parse_integrator(const XmlSource& src, const pugi::xml_node& node, Scene& scene, bool& unwarp);

}  // namespace tprf::mitsuba
