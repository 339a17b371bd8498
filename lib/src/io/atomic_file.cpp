#include "tprf/io/atomic_file.h"

#include "tprf/core/error.h"

#include <atomic>
#include <cerrno>
#include <string>
#include <system_error>
#include <utility>

#include <fcntl.h>
#include <unistd.h>

namespace tprf {

namespace fs = std::filesystem;

namespace {

// Creates an empty file under a name no other process or thread uses: the pid separates processes,
// the counter separates threads and earlier files of this process, and O_EXCL catches a leftover
// from a crashed process that had the same pid (then the next counter value is tried). Returns 0,
// or the errno of the last attempt; `created` is the name created, or the name that failed.
int create_unique(const fs::path& dir, const std::string& stem, fs::path& created) {
    static std::atomic<unsigned long> counter{0};
    const std::string pid = std::to_string(static_cast<long>(::getpid()));
    for (int attempt = 0;; ++attempt) {
        created = dir / (stem + pid + "." + std::to_string(counter++));
        const int fd = ::open(created.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd >= 0) {
            ::close(fd);
            return 0;
        }
        if (errno != EEXIST || attempt >= 100) return errno;
    }
}

}  // namespace

AtomicFile::AtomicFile(fs::path final_path) : m_path(std::move(final_path)) {
    if (m_path.filename().empty()) throw Error(m_path.string() + ": cannot create: not a file name");
    // Appended rather than "." + name: GCC 12 -O3 warns falsely (-Wrestrict) on the operator+ form.
    std::string stem = ".";
    stem += m_path.filename().string();
    stem += ".tmp.";
    fs::path temp;
    if (const int err = create_unique(m_path.parent_path(), stem, temp))
        fail_output(m_path, "cannot create its temporary " + temp.filename().string(), err);
    m_temp = std::move(temp);
}

AtomicFile::~AtomicFile() { discard(); }

AtomicFile::AtomicFile(AtomicFile&& other) noexcept
    : m_path(std::move(other.m_path)),
      m_temp(std::exchange(other.m_temp, {})),
      m_committed(other.m_committed) {}

AtomicFile& AtomicFile::operator=(AtomicFile&& other) noexcept {
    if (this != &other) {
        discard();
        m_path = std::move(other.m_path);
        m_temp = std::exchange(other.m_temp, {});
        m_committed = other.m_committed;
    }
    return *this;
}

void AtomicFile::discard() noexcept {
    if (m_temp.empty() || m_committed) return;
    std::error_code ignored;  // nothing useful can be done about a temporary that will not go away
    fs::remove(m_temp, ignored);
    m_temp.clear();
}

void AtomicFile::commit() {
    TPRF_CHECK(!m_temp.empty() && !m_committed);
    // Without the fsync, a crash soon after the rename could leave the final name pointing at a
    // file whose data never reached the disk: exactly the truncated file that the rename avoids.
    const int fd = ::open(m_temp.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail_output(m_path, "cannot open", errno);
    if (::fsync(fd) != 0) {
        const int err = errno;
        ::close(fd);
        fail_output(m_path, "cannot flush", err);
    }
    ::close(fd);
    std::error_code ec;
    fs::rename(m_temp, m_path, ec);
    if (ec) fail_output(m_path, "cannot rename its temporary " + m_temp.filename().string() + " to it", ec.value());
    m_committed = true;
}

void check_output_dir(const fs::path& dir) {
    const fs::path where = dir.empty() ? fs::path(".") : dir;
    std::error_code ec;
    fs::create_directories(where, ec);
    if (ec) throw Error(dir.string() + ": cannot write: " + ec.message());
    if (!fs::is_directory(where, ec)) throw Error(dir.string() + ": cannot write: not a directory");
    fs::path probe;
    if (const int err = create_unique(where, ".tprf-probe.", probe))
        throw Error(dir.string() + ": cannot write: " + std::system_category().message(err));
    fs::remove(probe, ec);
}

void create_output_dir(const fs::path& dir) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) fail_output(dir, "cannot create the folder", ec.value());
}

void write_text_file(const fs::path& path, const std::string& text) {
    AtomicFile file(path);
    const int fd = ::open(file.temp_path().c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
    if (fd < 0) fail_output(file.path(), "cannot open", errno);
    const char* bytes = text.data();
    for (std::size_t left = text.size(); left > 0;) {
        const ssize_t n = ::write(fd, bytes, left);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) {
            const int err = errno;
            ::close(fd);
            fail_output(file.path(), "cannot write", err);
        }
        bytes += n;
        left -= std::size_t(n);
    }
    if (::close(fd) != 0) fail_output(file.path(), "cannot write", errno);
    file.commit();
}

}  // namespace tprf
