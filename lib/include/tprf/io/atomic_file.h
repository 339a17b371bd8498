#pragma once
/// Atomic output files: write under a temporary name, then rename over the final name.
///
/// A render that is interrupted (Ctrl-C, out of memory, a crash) must never leave a truncated file
/// under a final name (docs/outputs.md). rename(2) within one directory is atomic, so a
/// reader sees either the old file, or no file, or the complete new one.

#include <filesystem>
#include <string>

namespace tprf {

/// A file that appears under its final name only when commit() is called.
///
/// The constructor creates an empty temporary file `.NAME.tmp.PID.COUNTER` in the final file's
/// directory (the same file system, so that the rename is atomic); a writer then opens temp_path()
/// and fills it. commit() flushes the temporary to disk and renames it to the final name; an
/// AtomicFile destroyed without commit() removes its temporary. Errors throw tprf::OutputError naming
/// the path and the system's reason.
class AtomicFile {
public:
    /// Creates the temporary file next to `final_path` (the directory must exist).
    explicit AtomicFile(std::filesystem::path final_path);
    /// Removes the temporary file unless commit() has succeeded.
    ~AtomicFile();
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;
    /// Moves the ownership of the temporary; the moved-from object owns nothing.
    AtomicFile(AtomicFile&& other) noexcept;
    /// Abandons this object's own temporary (removed), then takes `other`'s.
    AtomicFile& operator=(AtomicFile&& other) noexcept;

    /// The name the file gets on commit().
    [[nodiscard]] const std::filesystem::path& path() const { return m_path; }
    /// The temporary name to write to; unique among processes and threads.
    [[nodiscard]] const std::filesystem::path& temp_path() const { return m_temp; }
    /// True once commit() has succeeded.
    [[nodiscard]] bool committed() const { return m_committed; }

    /// Flushes the temporary to disk (fsync) and renames it to path(), replacing any file there.
    /// The writer must have closed the temporary first.
    void commit();

private:
    void discard() noexcept;

    std::filesystem::path m_path;
    std::filesystem::path m_temp;
    bool m_committed = false;
};

/// Creates `dir` (and its parents) if missing and checks that a file can be created in it, so that
/// an unwritable output directory is reported before minutes of rendering rather than after.
/// Throws tprf::Error "DIR: cannot write: REASON".
void check_output_dir(const std::filesystem::path& dir);

/// Creates the folder `dir` of an output (and its parents). Throws tprf::OutputError naming it when
/// the system refuses (a full disk, a vanished parent).
void create_output_dir(const std::filesystem::path& dir);

/// Writes `text` to `path` atomically (through an AtomicFile). Throws tprf::OutputError when it cannot.
void write_text_file(const std::filesystem::path& path, const std::string& text);

}  // namespace tprf
