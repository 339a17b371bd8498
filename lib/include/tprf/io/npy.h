#pragma once
/// NumPy .npy files of float32: the raw arrays of the output directory (transient.npy, steady.npy,
/// patch profiles), readable with numpy.load and numpy.load(mmap_mode='r').
///
/// Files are written as format version 1.0, dtype '<f4', C order, the header padded with spaces so
/// that the data starts at a multiple of 64 bytes (as numpy does), which keeps the payload aligned
/// for memory mapping. All files appear atomically under their final name (AtomicFile).

#include "tprf/io/atomic_file.h"

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace tprf {

/// Writes `data` (product(shape) floats, C order: the last index varies fastest) as a float32 .npy.
/// An empty `shape` writes a 0-d array of one element.
void write_npy(const std::filesystem::path& path, const std::vector<std::size_t>& shape, const float* data);
/// The same for int32 ('<i4'): labels such as the ground truth's object map.
void write_npy(const std::filesystem::path& path, const std::vector<std::size_t>& shape, const std::int32_t* data);

/// A float32 .npy of a fixed shape, filled in place through a shared memory mapping, so that arrays
/// larger than RAM (512 x 512 x 4096 x 3 floats = 12 GiB) are written without a copy in memory: the
/// kernel pages the data out to the file as it sees fit.
///
/// The file is created at a temporary name, sized and zero-filled (ftruncate), its blocks reserved
/// (posix_fallocate, so that a full disk is an error here rather than a SIGBUS while writing through
/// the mapping), and appears under its final name only on commit(); if the NpyMap is destroyed first,
/// the temporary is removed.
class NpyMap {
public:
    /// Creates and maps the temporary file for an array of `shape` (product(shape) floats, C order).
    NpyMap(const std::filesystem::path& path, std::vector<std::size_t> shape);
    /// Unmaps and removes the temporary unless commit() has succeeded.
    ~NpyMap();
    NpyMap(const NpyMap&) = delete;
    NpyMap& operator=(const NpyMap&) = delete;
    /// Moves the mapping and the temporary; the moved-from NpyMap owns nothing (data() is null).
    NpyMap(NpyMap&& other) noexcept;
    /// Abandons this map's own file (removed), then takes `other`'s.
    NpyMap& operator=(NpyMap&& other) noexcept;

    /// The mapped payload: size() floats, C order, 64-byte aligned, zero until written.
    [[nodiscard]] float* data() { return m_data; }
    /// The mapped payload, read-only.
    [[nodiscard]] const float* data() const { return m_data; }
    /// Number of elements, product(shape()).
    [[nodiscard]] std::size_t size() const { return m_size; }
    /// The array's shape.
    [[nodiscard]] const std::vector<std::size_t>& shape() const { return m_shape; }

    /// Flushes the mapping to disk, unmaps it and renames the file to its final name. data() is null
    /// afterwards.
    void commit();

private:
    void unmap() noexcept;

    AtomicFile m_file;
    std::vector<std::size_t> m_shape;
    std::size_t m_size = 0;
    void* m_map = nullptr;
    std::size_t m_map_bytes = 0;
    float* m_data = nullptr;
};

/// A float32 array read from a .npy file.
struct NpyArray {
    std::vector<std::size_t> shape;  ///< numpy's shape; empty for a 0-d array
    std::vector<float> data;         ///< product(shape) floats, C order
};

/// Reads a float32 C-order .npy (format versions 1.0 and 2.0). Any other dtype, Fortran order,
/// format version, or a truncated file throws tprf::Error naming the file and what is unsupported.
NpyArray read_npy(const std::filesystem::path& path);

/// A float32 C-order .npy mapped read-only (checked as read_npy), so that a cube larger than memory
/// can be read without a copy.
class NpyView {
public:
    explicit NpyView(const std::filesystem::path& path);
    ~NpyView();
    NpyView(const NpyView&) = delete;
    NpyView& operator=(const NpyView&) = delete;

    [[nodiscard]] const float* data() const { return m_data; }
    [[nodiscard]] std::size_t size() const { return m_size; }
    [[nodiscard]] const std::vector<std::size_t>& shape() const { return m_shape; }

private:
    std::vector<std::size_t> m_shape;
    std::size_t m_size = 0;
    void* m_map = nullptr;
    std::size_t m_map_bytes = 0;
    const float* m_data = nullptr;
};

}  // namespace tprf
