#include "tprf/io/npy.h"

#include "tprf/core/error.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

namespace tprf {

namespace fs = std::filesystem;

// The payload is written and read as the host's floats: '<f4' is what they are on every platform
// tprf builds for.
static_assert(std::endian::native == std::endian::little, "the .npy writer assumes a little-endian host");

namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr std::size_t kMagicSize = 6;
constexpr std::size_t kAlign = 64;

[[noreturn]] void fail_errno(const fs::path& path, const std::string& what, int err) {
    throw Error(path.string() + ": " + what + ": " + std::system_category().message(err));
}

// Payload size in bytes, refusing shapes whose size does not fit in memory addresses.
std::size_t payload_bytes(const fs::path& path, const std::vector<std::size_t>& shape, std::size_t& count) {
    count = 1;
    for (const std::size_t n : shape) {
        if (n != 0 && count > std::numeric_limits<std::size_t>::max() / sizeof(float) / n)
            fail_input(path, "", "array too large");
        count *= n;
    }
    return count * sizeof(float);
}

// Version 1.0 header: magic, version, little-endian uint16 length, then the dict that numpy writes,
// spaces and '\n' so that magic + length + dict is a multiple of 64 bytes.
std::string make_header(const fs::path& path, const std::vector<std::size_t>& shape, const char* descr = "<f4") {
    std::string dict = std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (";
    for (std::size_t i = 0; i < shape.size(); ++i) {
        if (i > 0) dict += ", ";
        dict += std::to_string(shape[i]);
    }
    if (shape.size() == 1) dict += ',';  // Python's one-element tuple
    dict += "), }";
    const std::size_t prefix = kMagicSize + 4;
    const std::size_t total = (prefix + dict.size() + 1 + kAlign - 1) / kAlign * kAlign;
    dict.append(total - prefix - dict.size() - 1, ' ');
    dict += '\n';
    if (dict.size() > 0xffff) fail_input(path, "", "array has too many dimensions for a .npy header");
    std::string header(kMagic, kMagicSize);
    header += '\x01';
    header += '\x00';
    header += static_cast<char>(dict.size() & 0xff);
    header += static_cast<char>(dict.size() >> 8);
    return header + dict;
}

void write_all(int fd, const fs::path& path, const char* bytes, std::size_t n) {
    while (n > 0) {
        // Linux writes at most about 2 GiB per call; smaller chunks keep every call complete.
        const ssize_t written = ::write(fd, bytes, std::min<std::size_t>(n, std::size_t{1} << 30));
        if (written < 0) {
            if (errno == EINTR) continue;
            fail_output(path, "cannot write", errno);
        }
        bytes += written;
        n -= static_cast<std::size_t>(written);
    }
}

// A tolerant reader of the header dict: numpy's own text, and hand-written variants of it.
class DictParser {
public:
    DictParser(const fs::path& path, std::string_view text) : m_path(path), m_text(text) {}

    [[noreturn]] void fail(const std::string& what) const {
        fail_input(m_path, "", "unsupported .npy header (" + what + "): " + std::string(m_text));
    }
    void skip_space() {
        while (m_pos < m_text.size() && (m_text[m_pos] == ' ' || m_text[m_pos] == '\t' || m_text[m_pos] == '\n'))
            ++m_pos;
    }
    bool eat(char c) {
        skip_space();
        if (m_pos < m_text.size() && m_text[m_pos] == c) {
            ++m_pos;
            return true;
        }
        return false;
    }
    void expect(char c) {
        if (!eat(c)) fail(std::string("expected '") + c + "'");
    }
    std::string string() {
        skip_space();
        if (m_pos >= m_text.size() || (m_text[m_pos] != '\'' && m_text[m_pos] != '"')) fail("expected a string");
        const char quote = m_text[m_pos++];
        const std::size_t end = m_text.find(quote, m_pos);
        if (end == std::string_view::npos) fail("unterminated string");
        std::string s(m_text.substr(m_pos, end - m_pos));
        m_pos = end + 1;
        return s;
    }
    std::string word() {
        skip_space();
        const std::size_t begin = m_pos;
        while (m_pos < m_text.size() && std::isalnum(static_cast<unsigned char>(m_text[m_pos])) != 0) ++m_pos;
        return std::string(m_text.substr(begin, m_pos - begin));
    }
    std::vector<std::size_t> tuple() {
        expect('(');
        std::vector<std::size_t> values;
        while (!eat(')')) {
            const std::string w = word();
            // 18 digits keep stoull from overflowing; payload_bytes rejects what is still too large.
            if (w.empty() || w.size() > 18 || w.find_first_not_of("0123456789") != std::string::npos)
                fail("bad shape");
            values.push_back(static_cast<std::size_t>(std::stoull(w)));
            if (!eat(',')) {
                expect(')');
                break;
            }
        }
        return values;
    }

private:
    const fs::path& m_path;
    std::string_view m_text;
    std::size_t m_pos = 0;
};

std::vector<std::size_t> parse_header(const fs::path& path, std::string_view text) {
    DictParser p(path, text);
    std::optional<std::string> descr;
    std::optional<bool> fortran;
    std::optional<std::vector<std::size_t>> shape;
    p.expect('{');
    while (!p.eat('}')) {
        const std::string key = p.string();
        p.expect(':');
        if (key == "descr") {
            descr = p.string();
        } else if (key == "fortran_order") {
            const std::string w = p.word();
            if (w != "True" && w != "False") p.fail("fortran_order is neither True nor False");
            fortran = w == "True";
        } else if (key == "shape") {
            shape = p.tuple();
        } else {
            p.fail("unknown key '" + key + "'");
        }
        if (!p.eat(',')) {
            p.expect('}');
            break;
        }
    }
    if (!descr || !fortran || !shape) p.fail("missing descr, fortran_order or shape");
    if (*descr != "<f4")
        fail_input(path, "", "unsupported dtype '" + *descr + "' (only little-endian float32 '<f4' is read)");
    if (*fortran) fail_input(path, "", "unsupported Fortran-order array (only C order is read)");
    return *shape;
}

// A .npy of 4-byte elements (float32 or int32, the same size) of the given dtype.
void write_npy4(const fs::path& path, const std::vector<std::size_t>& shape, const void* data, const char* descr) {
    std::size_t count = 0;
    const std::size_t bytes = payload_bytes(path, shape, count);
    const std::string header = make_header(path, shape, descr);
    AtomicFile file(path);
    const int fd = ::open(file.temp_path().c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
    if (fd < 0) fail_output(file.path(), "cannot open", errno);
    try {
        write_all(fd, file.path(), header.data(), header.size());
        if (bytes > 0) write_all(fd, file.path(), reinterpret_cast<const char*>(data), bytes);
    } catch (...) {
        ::close(fd);
        throw;
    }
    // close() is where some file systems (NFS) report a failed write.
    if (::close(fd) != 0) fail_output(file.path(), "cannot write", errno);
    file.commit();
}

}  // namespace

void write_npy(const fs::path& path, const std::vector<std::size_t>& shape, const float* data) {
    write_npy4(path, shape, data, "<f4");
}

void write_npy(const fs::path& path, const std::vector<std::size_t>& shape, const std::int32_t* data) {
    static_assert(sizeof(std::int32_t) == sizeof(float));
    write_npy4(path, shape, data, "<i4");
}

NpyMap::NpyMap(const fs::path& path, std::vector<std::size_t> shape) : m_file(path), m_shape(std::move(shape)) {
    const std::size_t bytes = payload_bytes(path, m_shape, m_size);
    const std::string header = make_header(path, m_shape);
    m_map_bytes = header.size() + bytes;
    const fs::path& temp = m_file.temp_path();
    const int fd = ::open(temp.c_str(), O_RDWR | O_CLOEXEC);
    if (fd < 0) fail_output(m_file.path(), "cannot open", errno);
    if (::ftruncate(fd, static_cast<off_t>(m_map_bytes)) != 0) {
        const int err = errno;
        ::close(fd);
        fail_output(m_file.path(), "cannot resize to " + std::to_string(m_map_bytes) + " bytes", err);
    }
    // Reserve the blocks now: writing through the mapping to a sparse file on a full disk would kill
    // the process with SIGBUS instead of reporting an error. (File systems that cannot preallocate
    // answer EOPNOTSUPP or EINVAL and stay sparse.)
    if (const int err = ::posix_fallocate(fd, 0, static_cast<off_t>(m_map_bytes));
        err != 0 && err != EOPNOTSUPP && err != EINVAL) {
        ::close(fd);
        fail_output(m_file.path(), "cannot reserve " + std::to_string(m_map_bytes) + " bytes", err);
    }
    void* map = ::mmap(nullptr, m_map_bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    const int err = errno;
    ::close(fd);  // the mapping keeps the file open
    if (map == MAP_FAILED) fail_output(m_file.path(), "cannot map " + std::to_string(m_map_bytes) + " bytes", err);
    m_map = map;
    std::memcpy(m_map, header.data(), header.size());
    m_data = reinterpret_cast<float*>(static_cast<char*>(m_map) + header.size());
}

NpyMap::~NpyMap() { unmap(); }

NpyMap::NpyMap(NpyMap&& other) noexcept
    : m_file(std::move(other.m_file)),
      m_shape(std::move(other.m_shape)),
      m_size(std::exchange(other.m_size, 0)),
      m_map(std::exchange(other.m_map, nullptr)),
      m_map_bytes(std::exchange(other.m_map_bytes, 0)),
      m_data(std::exchange(other.m_data, nullptr)) {}

NpyMap& NpyMap::operator=(NpyMap&& other) noexcept {
    if (this != &other) {
        unmap();
        m_file = std::move(other.m_file);
        m_shape = std::move(other.m_shape);
        m_size = std::exchange(other.m_size, 0);
        m_map = std::exchange(other.m_map, nullptr);
        m_map_bytes = std::exchange(other.m_map_bytes, 0);
        m_data = std::exchange(other.m_data, nullptr);
    }
    return *this;
}

void NpyMap::unmap() noexcept {
    if (m_map != nullptr) ::munmap(m_map, m_map_bytes);
    m_map = nullptr;
    m_data = nullptr;
}

void NpyMap::commit() {
    TPRF_CHECK(m_map != nullptr);
    if (::msync(m_map, m_map_bytes, MS_SYNC) != 0) fail_output(m_file.path(), "cannot write", errno);
    unmap();
    m_file.commit();
}

namespace {

// What a .npy header says: the shape, the element count and where the payload starts. Checks that the
// file holds exactly that payload.
struct NpyLayout {
    std::vector<std::size_t> shape;
    std::size_t count = 0;
    std::size_t offset = 0;
    std::size_t bytes = 0;
};

NpyLayout read_layout(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) fail_input(path, "", "cannot open");
    char prefix[kMagicSize + 2] = {};
    in.read(prefix, sizeof prefix);
    if (!in || std::memcmp(prefix, kMagic, kMagicSize) != 0) fail_input(path, "", "not a .npy file");
    const int major = static_cast<unsigned char>(prefix[kMagicSize]);
    const int minor = static_cast<unsigned char>(prefix[kMagicSize + 1]);
    if ((major != 1 && major != 2) || minor != 0)
        fail_input(path, "", "unsupported .npy format version " + std::to_string(major) + "." +
                                 std::to_string(minor) + " (only 1.0 and 2.0 are read)");
    // Version 2.0 differs only in a 4-byte header length, for headers beyond 64 KiB.
    unsigned char length_bytes[4] = {};
    const std::size_t length_size = major == 1 ? 2 : 4;
    in.read(reinterpret_cast<char*>(length_bytes), static_cast<std::streamsize>(length_size));
    std::size_t header_size = 0;
    for (std::size_t i = length_size; i-- > 0;) header_size = header_size << 8 | length_bytes[i];
    std::error_code ec;
    const std::uintmax_t file_size = fs::file_size(path, ec);
    if (!in || ec || header_size > file_size) fail_input(path, "", "truncated .npy header");
    std::string text(header_size, '\0');
    in.read(text.data(), static_cast<std::streamsize>(header_size));
    if (!in) fail_input(path, "", "truncated .npy header");

    NpyLayout layout;
    layout.shape = parse_header(path, text);
    layout.bytes = payload_bytes(path, layout.shape, layout.count);
    layout.offset = kMagicSize + 2 + length_size + header_size;
    if (file_size != layout.offset + layout.bytes)
        fail_input(path, "", "file size does not match the shape: expected " +
                                 std::to_string(layout.offset + layout.bytes) + " bytes, found " +
                                 std::to_string(file_size));
    return layout;
}

}  // namespace

NpyArray read_npy(const fs::path& path) {
    const NpyLayout layout = read_layout(path);
    std::ifstream in(path, std::ios::binary);
    in.seekg(static_cast<std::streamoff>(layout.offset));
    NpyArray array;
    array.shape = layout.shape;
    array.data.resize(layout.count);
    in.read(reinterpret_cast<char*>(array.data.data()), static_cast<std::streamsize>(layout.bytes));
    if (!in) fail_input(path, "", "cannot read the data");
    return array;
}

NpyView::NpyView(const fs::path& path) {
    const NpyLayout layout = read_layout(path);
    m_shape = layout.shape;
    m_size = layout.count;
    if (layout.offset % alignof(float) != 0) fail_input(path, "", "payload is not aligned for float32 access");
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail_errno(path, "cannot open", errno);
    m_map_bytes = layout.offset + layout.bytes;
    void* map = ::mmap(nullptr, m_map_bytes, PROT_READ, MAP_SHARED, fd, 0);
    const int err = errno;
    ::close(fd);
    if (map == MAP_FAILED) fail_errno(path, "cannot map", err);
    m_map = map;
    m_data = reinterpret_cast<const float*>(static_cast<const char*>(m_map) + layout.offset);
}

NpyView::~NpyView() {
    if (m_map != nullptr) ::munmap(m_map, m_map_bytes);
}

}  // namespace tprf
