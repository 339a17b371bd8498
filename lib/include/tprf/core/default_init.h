#pragma once
/// An allocator for large arrays that are filled right after they are made: a vector's resize(n) leaves
/// trivial elements uninitialised (as new T[n] does), so that the threads that fill it touch its pages
/// first instead of one thread zeroing them all before (87 MB of packed links for the flat 4k Cornell
/// box: 30 ms). Pass a value (vector(n, value), resize(n, value)) to set the elements.

#include <memory>
#include <new>
#include <type_traits>
#include <utility>

namespace tprf {

template <class T>
struct DefaultInitAllocator : std::allocator<T> {
    using value_type = T;
    template <class U>
    struct rebind {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() = default;
    template <class U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;  // default-initialised
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

}  // namespace tprf
