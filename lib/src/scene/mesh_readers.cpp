#include "mesh_readers.h"

#include "tprf/core/cancel.h"

#include <algorithm>
#include <charconv>
#include <cmath>

namespace tprf::mesh_read {

std::string count(std::size_t n) {
    const std::string digits = std::to_string(n);
    std::string out;
    for (std::size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out.push_back(',');
        out.push_back(digits[i]);
    }
    return out;
}

std::string count(std::size_t n, std::string_view singular, std::string_view plural) {
    return count(n) + " " + std::string(n == 1 ? singular : plural);
}

std::string at_line(std::size_t line) { return "line " + count(line); }

std::string at_byte(std::size_t offset) { return "byte " + count(offset); }

void check_finite(const Vec3& p, std::size_t vertex, Where where) {
    if (std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z())) return;
    throw MeshFileError(where.str() + ": vertex " + count(vertex + 1) +
                        " has a coordinate that is not a finite number (NaN or infinite)");
}

bool Lines::next(std::string_view& line, char comment) {
    if (m_rest.empty()) return false;
    const std::size_t end = m_rest.find_first_of("\r\n");
    line = m_rest.substr(0, end);
    if (end == std::string_view::npos) {
        m_rest = {};
    } else {
        const bool crlf = m_rest[end] == '\r' && end + 1 < m_rest.size() && m_rest[end + 1] == '\n';
        m_rest.remove_prefix(end + (crlf ? 2 : 1));
    }
    if ((++m_number & 0xffff) == 0) check_cancelled();  // a text mesh of millions of lines takes seconds
    if (comment != '\0')
        if (const std::size_t c = line.find(comment); c != std::string_view::npos) line = line.substr(0, c);
    return true;
}

std::string_view next_token(std::string_view& rest) {
    constexpr std::string_view kSpace = " \t\r\n\f\v";
    const std::size_t begin = rest.find_first_not_of(kSpace);
    if (begin == std::string_view::npos) {
        rest = {};
        return {};
    }
    const std::size_t end = rest.find_first_of(kSpace, begin);
    const std::string_view token = rest.substr(begin, end == std::string_view::npos ? end : end - begin);
    rest = end == std::string_view::npos ? std::string_view() : rest.substr(end);
    return token;
}

namespace {

// from_chars takes no leading '+', which some writers put before positive numbers.
std::string_view without_plus(std::string_view token) {
    return token.size() > 1 && token[0] == '+' && token[1] != '-' ? token.substr(1) : token;
}

}  // namespace

std::string quoted(std::string_view token) {
    constexpr std::size_t kShown = 40;  // a binary file read as text can hold very long "words"
    std::string s(token.substr(0, kShown));
    // Control bytes would garble the one-line message the user sees.
    std::replace_if(s.begin(), s.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }, '?');
    return "'" + s + (token.size() > kShown ? "...'" : "'");
}

namespace {

// `token` as a T; the words name what went wrong when it is out of T's range or not a T at all.
template <typename T>
T parse(std::string_view token, Where where, std::string_view too_large, std::string_view not_one) {
    const std::string_view t = without_plus(token);
    T value{};
    const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
    // Out of range ("1e999") is reported as such rather than read as infinity or zero.
    if (ec == std::errc::result_out_of_range)
        throw MeshFileError(where.str() + ": " + quoted(token) + " " + std::string(too_large));
    if (ec != std::errc() || end != t.data() + t.size())
        throw MeshFileError(where.str() + ": " + quoted(token) + " " + std::string(not_one));
    return value;
}

}  // namespace

double to_double(std::string_view token, Where where) {
    return parse<double>(token, where, "is out of the range of a double", "is not a number");
}

long long to_integer(std::string_view token, Where where) {
    return parse<long long>(token, where, "is too large", "is not a whole number");
}

}  // namespace tprf::mesh_read
