#pragma once
// The project's own readers of OFF, OBJ, PLY and STL (docs/meshes.md says why not OpenMesh's): each
// takes the whole file's bytes and returns the faces as the file holds them, or throws MeshFileError
// naming the line (text) or byte offset (binary) and what is wrong. Private to the library: load_mesh
// (scene/mesh_io.h) is the entry point, which repairs, transforms and names the scene file.

#include "tprf/core/types.h"

#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tprf::mesh_read {

/// A mesh as its file holds it: coordinates in the file's units, faces of any size (fewer than three
/// corners included: load_mesh counts those as degenerate), every index in [0, vertices.size()).
struct RawMesh {
    std::vector<Vec3> vertices;         ///< V, as written (finite: the readers check)
    std::vector<int> indices;           ///< the corners of every face, face after face
    std::vector<std::uint32_t> first{0};///< F + 1 offsets into `indices`
    std::size_t lines = 0;              ///< polylines (OBJ `l`), which tprf does not render

    std::size_t faces() const { return first.size() - 1; }
    /// Ends the face whose corners were pushed onto `indices` since the last call.
    void end_face() {
        if (indices.size() > UINT32_MAX) throw std::length_error("more than 4 billion face corners");
        first.push_back(static_cast<std::uint32_t>(indices.size()));
    }
};

/// What is wrong with a mesh file and where: the message starts with the place ("line 12: ",
/// "byte 4,096: ") and says the rest in words a user understands.
class MeshFileError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// "line 12" (1-based).
std::string at_line(std::size_t line);
/// "byte 4,096" (0-based offset from the start of the file).
std::string at_byte(std::size_t offset);

/// A place in a file, cheap to pass along: its words are made only when an error needs them.
struct Where {
    enum Kind { Line, Byte } kind = Line;
    std::size_t value = 0;  ///< the line (from 1) or the byte offset (from 0)
    /// "line 12" or "byte 4,096".
    std::string str() const { return kind == Line ? at_line(value) : at_byte(value); }
};

/// A word of a file for a message: in quotes, cut after 40 characters, control bytes shown as '?'.
std::string quoted(std::string_view token);
/// A count with thousands separators: 5210 -> "5,210".
std::string count(std::size_t n);
/// "1 vertex" / "5,210 vertices": the count and the noun, singular or plural.
std::string count(std::size_t n, std::string_view singular, std::string_view plural);

/// Throws MeshFileError("<where>: vertex <n> has a coordinate that is not a finite number") unless
/// all three coordinates are finite. `vertex` is 0-based; the message counts from 1.
void check_finite(const Vec3& p, std::size_t vertex, Where where);

/// A text file line by line, counting lines.
class Lines {
public:
    explicit Lines(std::string_view text) : m_rest(text) {}
    /// The next line, without its line end ("\n", "\r\n", "\r") and without what follows `comment`
    /// ('\0': nothing is a comment); false at the end of the text.
    bool next(std::string_view& line, char comment);
    /// The number of the line last returned, from 1.
    std::size_t number() const { return m_number; }
    /// The line last returned, as a place for errors.
    Where here() const { return {Where::Line, m_number}; }

private:
    std::string_view m_rest;
    std::size_t m_number = 0;
};

/// Cuts the first whitespace-separated token off `rest`; empty when there is none.
std::string_view next_token(std::string_view& rest);
/// The number `token` spells; throws MeshFileError("<where>: '<token>' is not a number").
double to_double(std::string_view token, Where where);
/// The integer `token` spells; throws MeshFileError("<where>: '<token>' is not a whole number").
long long to_integer(std::string_view token, Where where);

/// ASCII OFF and its header variants ([ST][C][N][4][n]OFF). Binary OFF ("OFF BINARY") is not read
/// here: is_binary_off tells load_mesh to hand it to OpenMesh.
RawMesh read_off(std::string_view text);
bool is_binary_off(std::string_view text);
/// Wavefront OBJ: `v` and `f` lines; every other statement is skipped.
RawMesh read_obj(std::string_view text);
/// STL, ASCII or binary: binary when the size matches the triangle count in bytes 80-83, whatever
/// the 80-byte header says.
RawMesh read_stl(std::string_view bytes);
/// PLY: ascii, binary_little_endian and binary_big_endian.
RawMesh read_ply(std::string_view bytes);

}  // namespace tprf::mesh_read
