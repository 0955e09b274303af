// Scratch arrays for the Morton-ordered BVH builders. std::vector writes
// every element once when it is sized (zeros, or an empty box for Box3f);
// the builders overwrite every element anyway, so these arrays start
// uninitialised, which saves one pass over memory per array and build.
#pragma once

#include <cstddef>
#include <memory>
#include <new>
#include <string_view>
#include <type_traits>
#include <utility>

#include "rayforge/core/memory_budget.h"

namespace rf::morton {

// A fixed-size array of trivially copyable T (Box3f, integers, ...), checked
// against the memory budget, whose elements start uninitialised.
template <class T>
class Buffer {
    static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

public:
    Buffer() = default;
    Buffer(size_t count, std::string_view what) { allocate(count, what); }

    // Replaces the contents by `count` uninitialised elements.
    void allocate(size_t count, std::string_view what) {
        checked_array_bytes(what, count, sizeof(T));
        data_.reset(count ? static_cast<T*>(::operator new(count * sizeof(T), std::align_val_t{kAlign})) : nullptr);
        size_ = count;
    }
    void clear() {
        data_.reset();
        size_ = 0;
    }
    void swap(Buffer& other) noexcept {
        data_.swap(other.data_);
        std::swap(size_, other.size_);
    }

    T& operator[](size_t i) { return data_.get()[i]; }
    const T& operator[](size_t i) const { return data_.get()[i]; }
    T* data() { return data_.get(); }
    const T* data() const { return data_.get(); }
    [[nodiscard]] size_t size() const { return size_; }
    [[nodiscard]] bool empty() const { return size_ == 0; }

private:
    static constexpr size_t kAlign = 64;
    struct Free {
        void operator()(T* p) const { ::operator delete(p, std::align_val_t{kAlign}); }
    };
    std::unique_ptr<T, Free> data_;
    size_t size_ = 0;
};

}  // namespace rf::morton
