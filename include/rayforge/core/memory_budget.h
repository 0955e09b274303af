// The memory budget: a process-wide cap on any single allocation whose size
// comes from input (a file's vertex count, an image header's width, a render
// resolution). A count that is plausible to parse but absurd to allocate then
// fails with a one-line rf::Error naming the object, instead of a
// std::bad_alloc or the OOM killer.
//
// The default is the machine's available memory (MemAvailable from
// /proc/meminfo, else physical memory). RAYFORGE_MEMORY_BUDGET ("512M", "4G",
// "1073741824") overrides it; it is read once, at first use.
// rf::set_memory_budget overrides both.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

namespace rf {

// The budget in bytes.
[[nodiscard]] size_t memory_budget();
// Sets the budget (bytes > 0) and returns the previous one, so a caller can
// restore it; 0 goes back to the default (environment, then available memory).
size_t set_memory_budget(size_t bytes);

// "4096", "512K", "512M", "4G", "1T" (binary multiples; "MB", "MiB" and lower
// case are accepted too). nullopt when the text is not such a size or is 0.
[[nodiscard]] std::optional<size_t> parse_memory_size(std::string_view text);

// count * element_size, checked: throws rf::Error "WHAT: N x S bytes overflows"
// when the product does not fit in size_t, or "WHAT: B bytes asked for, over
// the memory budget of M bytes (...)" when it exceeds the budget.
size_t checked_array_bytes(std::string_view what, size_t count, size_t element_size);

// Counts that become 32-bit indices (vertices, triangles, primitives):
// throws rf::Error "WHAT: N exceed 32-bit indices" above 2^32-1.
uint32_t checked_index_count(std::string_view what, uint64_t count);

// std::vector resize/reserve after checked_array_bytes.
template <class T>
void budgeted_resize(std::vector<T>& v, size_t count, std::string_view what) {
    checked_array_bytes(what, count, sizeof(T));
    v.resize(count);
}
template <class T>
void budgeted_reserve(std::vector<T>& v, size_t count, std::string_view what) {
    checked_array_bytes(what, count, sizeof(T));
    v.reserve(count);
}
// push_back for arrays that grow with the input (text formats): the budget is
// checked only when the vector reallocates, i.e. when its capacity doubles.
template <class T, class U>
void budgeted_push_back(std::vector<T>& v, U&& value, std::string_view what) {
    if (v.size() == v.capacity()) budgeted_reserve(v, std::max<size_t>(16, 2 * v.capacity()), what);
    v.push_back(std::forward<U>(value));
}

}  // namespace rf
