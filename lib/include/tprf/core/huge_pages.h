#pragma once
/// Large working arrays on transparent huge pages (2 MiB) where the system offers them.
//
// The march's rings are read at scattered places (each link a window of its source's ring, a few
// hundred links a receiver), so on 4 KiB pages a ring array larger than the TLB covers (about 12 MB
// here) costs a page walk for many of its reads: a ring array of 24 MB read that way took 10% longer on
// 4 KiB pages than on 2 MiB ones (bench/RESULTS.md, 2026-11-28). Allocations of at least
// kHugePageMinBytes are aligned to 2 MiB and advised (madvise MADV_HUGEPAGE), which Linux honours
// when transparent huge pages are "always" or "madvise"; elsewhere they are ordinary allocations.
// Nothing about the values changes, only where they live.

#include <cstddef>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>

namespace tprf::detail {

constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;
constexpr std::size_t kHugePageMinBytes = std::size_t(4) << 20;

/// At least `bytes` bytes, 2 MiB aligned and advised for huge pages (rounded up to whole pages);
/// throws std::bad_alloc. Free with free_huge(p, bytes).
void* allocate_huge(std::size_t bytes);
void free_huge(void* p, std::size_t bytes) noexcept;

/// A std::allocator that puts allocations of kHugePageMinBytes or more on huge pages. Unlike
/// std::allocator, a vector's resize(n) leaves trivial elements uninitialised (as new T[n] does): a
/// large array that is filled in parallel right after is then first touched by the threads that fill
/// it, not zeroed by one thread first. Pass a value (vector(n, value), resize(n, value)) to set them.
template <class T>
struct HugePageAllocator {
    using value_type = T;
    HugePageAllocator() = default;
    template <class U>
    HugePageAllocator(const HugePageAllocator<U>&) noexcept {}
    T* allocate(std::size_t n) {
        if (n > std::size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
        if (n * sizeof(T) < kHugePageMinBytes) return std::allocator<T>().allocate(n);
        return static_cast<T*>(allocate_huge(n * sizeof(T)));
    }
    void deallocate(T* p, std::size_t n) noexcept {
        if (n * sizeof(T) < kHugePageMinBytes) return std::allocator<T>().deallocate(p, n);
        free_huge(p, n * sizeof(T));
    }
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;  // default-initialised
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
    template <class U>
    bool operator==(const HugePageAllocator<U>&) const noexcept { return true; }
};

}  // namespace tprf::detail
