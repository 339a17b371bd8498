// PLY in its three encodings (ascii, binary_little_endian, binary_big_endian). The header declares
// elements, each a record of typed properties, and the data holds the records in the header's order.
// tprf needs x, y, z of `vertex` and the index list of `face`; everything else (normals, colours,
// texture lists, edges, materials) is stepped over by its declared types, so that any writer's
// layout reads. Text parts are located by line, binary data by byte offset.

#include "mesh_readers.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <limits>
#include <type_traits>

namespace tprf::mesh_read {
namespace {

enum class Type : std::uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

constexpr std::array<std::size_t, 8> kTypeSize{1, 1, 2, 2, 4, 4, 4, 8};

std::size_t size_of(Type t) { return kTypeSize[static_cast<std::size_t>(t)]; }

bool is_integer(Type t) { return t < Type::Float32; }

struct TypeName {
    std::string_view name;
    Type type;
};

// Both spellings: the original (char, uchar, ...) and the sized one later writers use (int8, ...).
constexpr std::array<TypeName, 16> kTypeNames{{{"char", Type::Int8},      {"int8", Type::Int8},
                                               {"uchar", Type::UInt8},    {"uint8", Type::UInt8},
                                               {"short", Type::Int16},    {"int16", Type::Int16},
                                               {"ushort", Type::UInt16},  {"uint16", Type::UInt16},
                                               {"int", Type::Int32},      {"int32", Type::Int32},
                                               {"uint", Type::UInt32},    {"uint32", Type::UInt32},
                                               {"float", Type::Float32},  {"float32", Type::Float32},
                                               {"double", Type::Float64}, {"float64", Type::Float64}}};

// What tprf takes from a property: a coordinate, the face's corners, or nothing.
enum class Slot : std::uint8_t { Skip, X, Y, Z, Corners };

struct Property {
    std::string name;
    Type type = Type::Float32;  // of the value, or of each item of a list
    bool list = false;
    Type count_type = Type::UInt8;
    Slot slot = Slot::Skip;
};

int axis(Slot s) { return static_cast<int>(s) - static_cast<int>(Slot::X); }

enum class Role : std::uint8_t { Other, Vertex, Face };

struct Element {
    std::string name;
    std::size_t count = 0;
    std::size_t line = 0;  // of its header line, where errors about its properties point
    Role role = Role::Other;
    std::vector<Property> properties;
};

enum class Format : std::uint8_t { None, Ascii, Little, Big };

struct Header {
    Format format = Format::None;
    std::vector<Element> elements;
    std::size_t lines = 0;  // the header's, end_header's included: ascii data counts on from there
    std::size_t data = 0;   // the offset of the first data byte
    std::size_t vertices = 0;
};

[[noreturn]] void fail(Where where, const std::string& what) { throw MeshFileError(where.str() + ": " + what); }

// The header's lines, ended by "\n" or "\r\n" only: a lone '\r' may be a data byte right after
// end_header, and where the data starts must be exact.
class HeaderLines {
public:
    explicit HeaderLines(std::string_view bytes) : m_bytes(bytes) {}
    bool next(std::string_view& line) {
        if (m_pos >= m_bytes.size()) return false;
        const std::size_t end = std::min(m_bytes.find('\n', m_pos), m_bytes.size());
        line = m_bytes.substr(m_pos, end - m_pos);
        if (line.ends_with('\r')) line.remove_suffix(1);
        m_ended = end < m_bytes.size();
        m_pos = m_ended ? end + 1 : end;
        ++m_number;
        return true;
    }
    std::size_t number() const { return m_number; }
    // Whether the line last returned has its line end (is not cut off by the end of the file).
    bool ended() const { return m_ended; }
    std::size_t offset() const { return m_pos; }
    Where here() const { return {Where::Line, std::max<std::size_t>(m_number, 1)}; }

private:
    std::string_view m_bytes;
    std::size_t m_pos = 0;
    std::size_t m_number = 0;
    bool m_ended = false;
};

Type parse_type(std::string_view token, Where where) {
    if (token.empty()) fail(where, "'property' needs a type and a name ('property float x', 'property list uchar int "
                                   "vertex_indices')");
    for (const TypeName& t : kTypeNames)
        if (t.name == token) return t.type;
    fail(where, quoted(token) + " is not a PLY type (char, uchar, short, ushort, int, uint, float, double, or "
                               "int8, uint8, int16, uint16, int32, uint32, float32, float64)");
}

void read_format(std::string_view rest, Header& h, Where where) {
    if (h.format != Format::None) fail(where, "a second 'format' line");
    const std::string_view name = next_token(rest);
    if (name == "ascii")
        h.format = Format::Ascii;
    else if (name == "binary_little_endian")
        h.format = Format::Little;
    else if (name == "binary_big_endian")
        h.format = Format::Big;
    else
        fail(where, quoted(name) + " is not a PLY format (ascii, binary_little_endian or binary_big_endian)");
}

void read_element(std::string_view rest, Header& h, Where where) {
    const std::string_view name = next_token(rest);
    const std::string_view number = next_token(rest);
    if (number.empty()) fail(where, "'element' needs a name and a count ('element vertex 8')");
    const long long n = to_integer(number, where);
    if (n < 0) fail(where, "element " + quoted(name) + " has a negative count");
    Element e;
    e.name = std::string(name);
    e.count = static_cast<std::size_t>(n);
    e.line = where.value;
    h.elements.push_back(std::move(e));
}

void read_property(std::string_view rest, Header& h, Where where) {
    if (h.elements.empty()) fail(where, "a property before any element");
    Property p;
    const std::string_view first = next_token(rest);
    if (first == "list") {
        p.list = true;
        p.count_type = parse_type(next_token(rest), where);
        p.type = parse_type(next_token(rest), where);
        if (!is_integer(p.count_type)) fail(where, "a list's length must have an integer type");
    } else {
        p.type = parse_type(first, where);
    }
    const std::string_view name = next_token(rest);
    if (name.empty()) fail(where, "the property has no name");
    p.name = std::string(name);
    h.elements.back().properties.push_back(std::move(p));
}

Property* find(Element& e, std::string_view name) {
    const auto it =
        std::find_if(e.properties.begin(), e.properties.end(), [&](const Property& p) { return p.name == name; });
    return it == e.properties.end() ? nullptr : &*it;
}

void mark_vertex(Element& e) {
    const Where where{Where::Line, e.line};
    e.role = Role::Vertex;
    constexpr std::array<std::string_view, 3> kAxes{"x", "y", "z"};
    for (std::size_t k = 0; k < 3; ++k) {
        Property* p = find(e, kAxes[k]);
        if (p == nullptr)
            fail(where, "the vertex element has no property '" + std::string(kAxes[k]) + "' (tprf needs x, y and z)");
        if (p->list) fail(where, "property '" + p->name + "' of the vertex element is a list, not a number");
        p->slot = static_cast<Slot>(static_cast<int>(Slot::X) + static_cast<int>(k));
    }
    // Corners are stored as int.
    if (e.count > static_cast<std::size_t>(std::numeric_limits<int>::max()))
        fail(where, count(e.count, "vertex", "vertices") + " are more than tprf reads");
}

void mark_face(Element& e) {
    const Where where{Where::Line, e.line};
    e.role = Role::Face;
    Property* p = find(e, "vertex_indices");
    if (p == nullptr) p = find(e, "vertex_index");
    if (p == nullptr) fail(where, "the face element has no 'vertex_indices' (or 'vertex_index') list");
    if (!p->list) fail(where, "property '" + p->name + "' of the face element is a single number, not a list");
    if (!is_integer(p->type))
        fail(where, "property '" + p->name + "' of the face element holds floating-point numbers, not vertex "
                    "indices (an integer type)");
    p->slot = Slot::Corners;
}

void finish_header(Header& h, Where end) {
    if (h.format == Format::None)
        fail(end, "the header has no 'format' line (format ascii 1.0, format binary_little_endian 1.0 or format "
                  "binary_big_endian 1.0)");
    bool has_vertices = false, has_faces = false;
    for (Element& e : h.elements) {
        if (e.name == "vertex") {
            if (has_vertices) fail({Where::Line, e.line}, "a second vertex element");
            mark_vertex(e);
            has_vertices = true;
            h.vertices = e.count;
        } else if (e.name == "face") {
            if (has_faces) fail({Where::Line, e.line}, "a second face element");
            mark_face(e);
            has_faces = true;
        }
    }
    if (!has_vertices) fail(end, "the header declares no vertex element");
}

bool is_magic(std::string_view line) {
    const std::string_view word = next_token(line);
    return word == "ply" && next_token(line).empty();
}

Header read_header(std::string_view bytes) {
    HeaderLines lines(bytes);
    std::string_view line;
    if (!bytes.starts_with("ply") || !lines.next(line) || !is_magic(line))
        fail({Where::Line, 1}, "not a PLY file (its first line must be 'ply')");
    Header h;
    while (lines.next(line)) {
        const Where where = lines.here();
        std::string_view rest = line;
        const std::string_view keyword = next_token(rest);
        if (!lines.ended() && keyword != "end_header") break;  // a cut-off line would only mislead
        if (keyword.empty() || keyword == "comment" || keyword == "obj_info") continue;
        if (keyword == "format") {
            read_format(rest, h, where);
        } else if (keyword == "element") {
            read_element(rest, h, where);
        } else if (keyword == "property") {
            read_property(rest, h, where);
        } else if (keyword == "end_header") {
            h.lines = lines.number();
            h.data = lines.offset();
            finish_header(h, where);
            return h;
        } else {
            fail(where, quoted(keyword) + " is not a PLY header keyword (format, comment, obj_info, element, property, "
                                         "end_header)");
        }
    }
    fail(lines.here(), "the file ends before the header's 'end_header' line");
}

void check_corner(long long v, std::size_t vertices, std::size_t face, Where where) {
    if (v < 0) fail(where, "face " + count(face + 1) + " has a negative vertex index (" + std::to_string(v) + ")");
    if (static_cast<unsigned long long>(v) >= vertices)
        fail(where, "face " + count(face + 1) + " refers to vertex " + std::to_string(v) + ", but the file has " +
                        count(vertices, "vertex", "vertices") + " (PLY counts from 0)");
}

void end_face(RawMesh& mesh, Where where) {
    // The offsets in `first` are 32-bit.
    if (mesh.indices.size() > std::numeric_limits<std::uint32_t>::max())
        fail(where, "more face corners than tprf reads");
    mesh.end_face();
}

[[noreturn]] void fail_end(Where where, const Element& e, std::size_t record) {
    fail(where, "the file ends inside " + e.name + " " + count(record + 1) + " of " + count(e.count));
}

[[noreturn]] void fail_negative_length(Where where, const Element& e, std::size_t record, const Property& p,
                                       long long n) {
    fail(where, e.name + " " + count(record + 1) + " has a list '" + p.name + "' of negative length (" +
                    std::to_string(n) + ")");
}

template <typename U>
U swap_bytes(U v) {
    U r = 0;
    for (std::size_t i = 0; i < sizeof(U); ++i) {
        r = static_cast<U>((r << 8) | (v & 0xFFu));
        v = static_cast<U>(v >> 8);
    }
    return r;
}

template <typename T>
T load(const char* p, bool swap) {
    using Bits = std::conditional_t<
        sizeof(T) == 1, std::uint8_t,
        std::conditional_t<sizeof(T) == 2, std::uint16_t,
                           std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;
    Bits bits;
    std::memcpy(&bits, p, sizeof bits);
    if (swap) bits = swap_bytes(bits);
    return std::bit_cast<T>(bits);
}

// The value at `p` of PLY type `t`, as an R. Lengths and indices are read as long long, which the
// header allows only for integer types.
template <typename R>
R load_as(const char* p, Type t, bool swap) {
    switch (t) {
    case Type::Int8: return static_cast<R>(load<std::int8_t>(p, swap));
    case Type::UInt8: return static_cast<R>(load<std::uint8_t>(p, swap));
    case Type::Int16: return static_cast<R>(load<std::int16_t>(p, swap));
    case Type::UInt16: return static_cast<R>(load<std::uint16_t>(p, swap));
    case Type::Int32: return static_cast<R>(load<std::int32_t>(p, swap));
    case Type::UInt32: return static_cast<R>(load<std::uint32_t>(p, swap));
    case Type::Float32: return static_cast<R>(load<float>(p, swap));
    case Type::Float64: return static_cast<R>(load<double>(p, swap));
    }
    return R{};
}

class BinaryData {
public:
    BinaryData(std::string_view bytes, const Header& h)
        : m_bytes(bytes), m_pos(h.data), m_vertices(h.vertices),
          m_swap((h.format == Format::Little) != (std::endian::native == std::endian::little)) {}

    void element(const Element& e, RawMesh& mesh) {
        const bool fixed =
            std::none_of(e.properties.begin(), e.properties.end(), [](const Property& p) { return p.list; });
        if (e.role == Role::Other && fixed) return skip_fixed(e);
        for (std::size_t i = 0; i < e.count; ++i) record(e, i, mesh);
    }

private:
    std::size_t left() const { return m_bytes.size() - m_pos; }
    Where here() const { return {Where::Byte, m_pos}; }

    // The next `n` bytes of record `i` of `e`, which the file must hold.
    const char* take(std::size_t n, const Element& e, std::size_t i) {
        if (n > left()) fail_end({Where::Byte, m_bytes.size()}, e, i);
        const char* p = m_bytes.data() + m_pos;
        m_pos += n;
        return p;
    }

    // Records of fixed size are stepped over all at once.
    void skip_fixed(const Element& e) {
        std::size_t stride = 0;
        for (const Property& p : e.properties) stride += size_of(p.type);
        if (stride == 0) return;
        if (e.count > left() / stride) fail_end({Where::Byte, m_bytes.size()}, e, left() / stride);
        m_pos += e.count * stride;
    }

    void record(const Element& e, std::size_t i, RawMesh& mesh) {
        const Where start = here();
        Vec3 p = Vec3::Zero();
        for (const Property& prop : e.properties) {
            if (!prop.list) {
                const char* at = take(size_of(prop.type), e, i);
                if (prop.slot != Slot::Skip) p[axis(prop.slot)] = load_as<double>(at, prop.type, m_swap);
                continue;
            }
            const Where length_at = here();
            const long long n = load_as<long long>(take(size_of(prop.count_type), e, i), prop.count_type, m_swap);
            if (n < 0) fail_negative_length(length_at, e, i, prop, n);
            const std::size_t item = size_of(prop.type);
            if (static_cast<unsigned long long>(n) > left() / item) fail_end({Where::Byte, m_bytes.size()}, e, i);
            const char* items = take(static_cast<std::size_t>(n) * item, e, i);
            if (prop.slot == Slot::Corners) corners(items, static_cast<std::size_t>(n), prop.type, i, mesh);
        }
        if (e.role == Role::Vertex) {
            check_finite(p, i, start);
            mesh.vertices.push_back(p);
        } else if (e.role == Role::Face) {
            end_face(mesh, start);
        }
    }

    void corners(const char* items, std::size_t n, Type t, std::size_t face, RawMesh& mesh) {
        const std::size_t item = size_of(t);
        for (std::size_t k = 0; k < n; ++k) {
            const long long v = load_as<long long>(items + k * item, t, m_swap);
            const std::size_t offset = static_cast<std::size_t>(items - m_bytes.data()) + k * item;
            check_corner(v, m_vertices, face, {Where::Byte, offset});
            mesh.indices.push_back(static_cast<int>(v));
        }
    }

    std::string_view m_bytes;
    std::size_t m_pos;
    std::size_t m_vertices;  // as the header declares them, which corners must stay below
    bool m_swap;
};

// The data of an ascii file, token by token. A record may go on over lines, but the next one starts
// on a new line: what follows a record on its line is ignored, as writers put extra values there
// (MeshLab's VCG library writes more per face than its header declares).
class AsciiData {
public:
    AsciiData(std::string_view text, const Header& h) : m_lines(text), m_before(h.lines), m_vertices(h.vertices) {}

    void element(const Element& e, RawMesh& mesh) {
        // A record with no properties has no tokens: reading a huge count of them would only spin.
        if (e.properties.empty()) return;
        for (std::size_t i = 0; i < e.count; ++i) record(e, i, mesh);
    }

private:
    Where here() const { return {Where::Line, m_before + m_lines.number()}; }

    std::string_view token(const Element& e, std::size_t i) {
        for (std::string_view t = next_token(m_rest);; t = next_token(m_rest)) {
            if (!t.empty()) return t;
            if (!m_lines.next(m_rest, '\0')) fail_end(here(), e, i);
        }
    }

    void record(const Element& e, std::size_t i, RawMesh& mesh) {
        Vec3 p = Vec3::Zero();
        for (const Property& prop : e.properties) {
            if (!prop.list) {
                const std::string_view t = token(e, i);
                if (prop.slot != Slot::Skip) p[axis(prop.slot)] = to_double(t, here());
                continue;
            }
            const std::string_view length = token(e, i);
            const long long n = to_integer(length, here());
            if (n < 0) fail_negative_length(here(), e, i, prop, n);
            for (long long k = 0; k < n; ++k) {
                const std::string_view t = token(e, i);
                if (prop.slot != Slot::Corners) continue;
                const long long v = to_integer(t, here());
                check_corner(v, m_vertices, i, here());
                mesh.indices.push_back(static_cast<int>(v));
            }
        }
        if (e.role == Role::Vertex) {
            check_finite(p, i, here());
            mesh.vertices.push_back(p);
        } else if (e.role == Role::Face) {
            end_face(mesh, here());
        }
        m_rest = {};
    }

    Lines m_lines;
    std::string_view m_rest;
    std::size_t m_before;    // lines of the header
    std::size_t m_vertices;  // as the header declares them, which corners must stay below
};

// The fewest bytes a record of `e` can take, so that a header's counts reserve no more than the file
// could hold.
std::size_t least_record_bytes(const Element& e, Format format) {
    if (format == Format::Ascii) return 2 * e.properties.size();  // a digit and a space per value
    std::size_t n = 0;
    for (const Property& p : e.properties) n += size_of(p.list ? p.count_type : p.type);
    return n;
}

void reserve(RawMesh& mesh, const Header& h, std::size_t data_bytes) {
    for (const Element& e : h.elements) {
        const std::size_t least = least_record_bytes(e, h.format);
        const std::size_t n = least == 0 ? 0 : std::min(e.count, data_bytes / least);
        if (e.role == Role::Vertex) mesh.vertices.reserve(n);
        if (e.role != Role::Face) continue;
        mesh.first.reserve(n + 1);
        const auto corners = std::find_if(e.properties.begin(), e.properties.end(),
                                          [](const Property& p) { return p.slot == Slot::Corners; });
        const std::size_t corner_bytes = h.format == Format::Ascii ? 2 : size_of(corners->type);
        mesh.indices.reserve(std::min(3 * n, data_bytes / corner_bytes));
    }
}

}  // namespace

RawMesh read_ply(std::string_view bytes) {
    const Header h = read_header(bytes);
    RawMesh mesh;
    reserve(mesh, h, bytes.size() - h.data);
    if (h.format == Format::Ascii) {
        AsciiData data(bytes.substr(h.data), h);
        for (const Element& e : h.elements) data.element(e, mesh);
    } else {
        BinaryData data(bytes, h);
        for (const Element& e : h.elements) data.element(e, mesh);
    }
    return mesh;
}

}  // namespace tprf::mesh_read
