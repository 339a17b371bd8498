#include "json_node.h"
#include "open_reason.h"

#include "tprf/core/error.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <system_error>

namespace tprf {

namespace fs = std::filesystem;
using nlohmann::json;

// Built by append: GCC 12 warns falsely (-Wrestrict) on `"\"" + std::string(s)`.
std::string in_quotes(std::string_view s) {
    std::string out;
    out.reserve(s.size() + 2);
    out.push_back('"');
    out.append(s);
    out.push_back('"');
    return out;
}

void JsonNode::fail(std::string_view what) const { fail_input(file, path, what); }

void JsonNode::expect_object() const {
    if (!j.is_object()) fail(std::string("expected an object, got ") + j.type_name());
}

std::size_t JsonNode::array_size() const {
    if (!j.is_array()) fail(std::string("expected an array, got ") + j.type_name());
    return j.size();
}

JsonNode JsonNode::child(std::string_view key) const {
    expect_object();
    const auto it = j.find(key);
    if (it == j.end()) fail("missing key " + in_quotes(key));
    return member(key, *it);
}

std::optional<JsonNode> JsonNode::find(std::string_view key) const {
    expect_object();
    const auto it = j.find(key);
    if (it == j.end()) return std::nullopt;
    return member(key, *it);
}

JsonNode JsonNode::at(std::size_t i) const { return JsonNode{j.at(i), path + "[" + std::to_string(i) + "]", file}; }

void JsonNode::check_keys(std::initializer_list<std::string_view> allowed) const {
    expect_object();
    for (const auto& [key, value] : j.items()) {
        if (std::find(allowed.begin(), allowed.end(), key) != allowed.end()) continue;
        std::string list;
        for (const std::string_view a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        member(key, value).fail("unknown key (allowed here: " + list + ")");
    }
}

double JsonNode::number() const {
    if (!j.is_number()) fail(std::string("expected a number, got ") + j.type_name());
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail("expected a finite number");
    return v;
}

double JsonNode::positive() const {
    const double v = number();
    if (v <= 0.0) fail("must be > 0");
    return v;
}

int JsonNode::integer() const {
    const double v = number();
    if (v != std::floor(v)) fail("expected an integer");
    if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max()) fail("integer out of range");
    return static_cast<int>(v);
}

bool JsonNode::boolean() const {
    if (!j.is_boolean()) fail(std::string("expected true or false, got ") + j.type_name());
    return j.get<bool>();
}

std::string JsonNode::string() const {
    if (!j.is_string()) fail(std::string("expected a string, got ") + j.type_name());
    return j.get<std::string>();
}

Vec3 JsonNode::vec3() const {
    if (!j.is_array() || j.size() != 3) fail("expected an array of 3 numbers");
    return Vec3(at(0).number(), at(1).number(), at(2).number());
}

Rgb JsonNode::rgb() const {
    if (j.is_number()) return Rgb::Constant(number());
    if (!j.is_array() || j.size() != 3) fail("expected a number or an array of 3 numbers");
    return Rgb(at(0).number(), at(1).number(), at(2).number());
}

JsonNode JsonNode::member(std::string_view key, const json& value) const {
    return JsonNode{value, path.empty() ? std::string(key) : path + "." + std::string(key), file};
}

namespace {

// nlohmann reports a byte offset; users need a line and column to find the mistake in an editor.
std::string line_column(const std::string& text, std::size_t byte) {
    const std::size_t before = std::min(byte == 0 ? 0 : byte - 1, text.size());
    const auto prefix = std::string_view(text).substr(0, before);
    const std::size_t line = 1 + static_cast<std::size_t>(std::count(prefix.begin(), prefix.end(), '\n'));
    const std::size_t last_newline = prefix.rfind('\n');
    const std::size_t column = last_newline == std::string_view::npos ? before + 1 : before - last_newline;
    return "line " + std::to_string(line) + ", column " + std::to_string(column);
}

// nlohmann's own message starts with an exception id and its own position; keep only the reason.
std::string reason(const json::exception& e) {
    const std::string what = e.what();
    const std::size_t column = what.find("column ");
    const std::size_t colon = what.find(": ", column == std::string::npos ? 0 : column);
    return colon == std::string::npos ? what : what.substr(colon + 2);
}

}  // namespace

json parse_json_text(const std::string& text, const fs::path& file) {
    try {
        return json::parse(text);
    } catch (const json::parse_error& e) {
        fail_input(file, "", line_column(text, e.byte) + ": malformed JSON: " + reason(e));
    } catch (const json::exception& e) {
        // A number too large for a double (1e999) is out_of_range, which carries no position; the
        // message quotes the token, so locate it.
        std::string where;
        const std::string what = e.what();
        const std::size_t open = what.find('\'');
        const std::size_t close = what.rfind('\'');
        if (open != std::string::npos && close > open) {
            const std::size_t at = text.find(what.substr(open + 1, close - open - 1));
            if (at != std::string::npos) where = line_column(text, at + 1) + ": ";
        }
        fail_input(file, "", where + "invalid JSON: " + what.substr(what.find(']') + 2));
    }
}

json read_json_file(const fs::path& file, std::string_view what) {
    std::error_code ec;
    // An ifstream opens a directory without complaint on POSIX and then reads nothing.
    if (fs::is_directory(file, ec)) fail_input(file, "", "cannot read " + std::string(what) + " (it is a directory)");
    errno = 0;
    std::ifstream in(file, std::ios::binary);
    if (!in) fail_input(file, "", "cannot read " + std::string(what) + open_reason(errno));
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) fail_input(file, "", "cannot read " + std::string(what));
    return parse_json_text(text, file);
}

}  // namespace tprf
