#pragma once
/// Private to the scene stage (not installed). Typed reading of JSON input (scene files, sensor blocks):
/// one value with its JSON path, so that every error can say where it is ("FILE: objects[2].u[1]:
/// expected a number"). Value ranges are checked later, on the built data (scene/validate.h).

#include "tprf/core/types.h"
#include "tprf/scene/scene.h"
#include "tprf/scene/sensor_settings.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>

namespace tprf {

/// A JSON value, its path from the document's root ("" for the root) and the file it came from.
/// Every accessor throws tprf::Error "FILE: PATH: what is wrong" when the value is not what it expects.
struct JsonNode {
    const nlohmann::json& j;
    std::string path;
    const std::filesystem::path& file;

    /// Throws tprf::Error naming this node.
    [[noreturn]] void fail(std::string_view what) const;

    void expect_object() const;
    /// The size of an array (fails on anything else).
    std::size_t array_size() const;
    bool has(std::string_view key) const { return j.contains(key); }
    /// A required member.
    JsonNode child(std::string_view key) const;
    /// An optional member.
    std::optional<JsonNode> find(std::string_view key) const;
    /// Element i of an array.
    JsonNode at(std::size_t i) const;
    /// Unknown keys are errors rather than ignored, so that a misspelt optional key cannot silently
    /// fall back to its default.
    void check_keys(std::initializer_list<std::string_view> allowed) const;

    double number() const;          ///< finite
    /// A finite number > 0, for inputs that validate() never sees (a gate step).
    double positive() const;
    /// A whole number that fits an int; its range is validate()'s.
    int integer() const;
    bool boolean() const;
    std::string string() const;
    Vec3 vec3() const;
    /// A colour: a grey number or an RGB triple (docs/scene.md).
    Rgb rgb() const;
    /// A member named `key` of this object.
    JsonNode member(std::string_view key, const nlohmann::json& value) const;
};

/// `s` in double quotes, for messages.
std::string in_quotes(std::string_view s);

/// Parses JSON text; malformed text throws tprf::Error "FILE: line L, column C: malformed JSON: why".
nlohmann::json parse_json_text(const std::string& text, const std::filesystem::path& file);

/// Reads and parses a JSON file (errors as parse_json_text, or "cannot read").
nlohmann::json read_json_file(const std::filesystem::path& file, std::string_view what = "file");

/// Reads a `sensor` block; errors name the node's file and JSON path. A table pulse's CSV is read (and
/// checked) here, relative to the node's file; the ranges of the result are validate_sensor()'s.
SensorSettings parse_sensor(const JsonNode& block);

/// Reads a `capture` block (parse_capture.cpp); its ranges and grids are validate()'s.
Capture parse_capture(const JsonNode& block);

}  // namespace tprf
