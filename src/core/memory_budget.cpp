#include "rayforge/core/memory_budget.h"

#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <mutex>
#include <string>

#include "rayforge/core/error.h"

namespace rf {

namespace {

constexpr const char* kEnvironmentVariable = "RAYFORGE_MEMORY_BUDGET";

// MemAvailable (what can be allocated without swapping), else physical memory.
size_t available_memory() {
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    unsigned long long kib = 0;
    std::string unit;
    while (meminfo >> key >> kib >> unit) {
        if (key == "MemAvailable:" && kib > 0) return size_t(kib) * 1024;
    }
    const long pages = ::sysconf(_SC_PHYS_PAGES);
    const long page_size = ::sysconf(_SC_PAGE_SIZE);
    if (pages > 0 && page_size > 0) return size_t(pages) * size_t(page_size);
    return std::numeric_limits<size_t>::max();
}

size_t default_budget() {
    if (const char* text = std::getenv(kEnvironmentVariable)) {
        if (std::optional<size_t> bytes = parse_memory_size(text)) return *bytes;
        throw Error(std::string(kEnvironmentVariable) + ": bad value '" + text +
                    "' (expected a byte count with an optional K, M, G or T suffix, e.g. 512M)");
    }
    return available_memory();
}

std::atomic<size_t> g_budget{0};  // 0 = not decided yet
std::mutex g_default_mutex;

}  // namespace

std::optional<size_t> parse_memory_size(std::string_view text) {
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
    size_t i = 0;
    unsigned long long value = 0;
    for (; i < text.size() && std::isdigit(static_cast<unsigned char>(text[i])); ++i) {
        if (value > (std::numeric_limits<unsigned long long>::max() - 9) / 10) return std::nullopt;
        value = value * 10 + unsigned(text[i] - '0');
    }
    if (i == 0) return std::nullopt;
    std::string suffix;
    for (; i < text.size(); ++i) suffix += char(std::toupper(static_cast<unsigned char>(text[i])));
    int shift = 0;
    if (!suffix.empty() && suffix != "B") {
        switch (suffix[0]) {
            case 'K': shift = 10; break;
            case 'M': shift = 20; break;
            case 'G': shift = 30; break;
            case 'T': shift = 40; break;
            default: return std::nullopt;
        }
        const std::string_view unit = std::string_view(suffix).substr(1);
        if (!unit.empty() && unit != "B" && unit != "IB") return std::nullopt;
    }
    if (value == 0 || value > (std::numeric_limits<size_t>::max() >> shift)) return std::nullopt;
    return size_t(value) << shift;
}

size_t memory_budget() {
    size_t budget = g_budget.load(std::memory_order_relaxed);
    if (budget != 0) return budget;
    std::lock_guard lock(g_default_mutex);
    budget = g_budget.load();
    if (budget == 0) {
        budget = default_budget();  // throws (and stays undecided) on a bad environment value
        g_budget.store(budget);
    }
    return budget;
}

size_t set_memory_budget(size_t bytes) {
    std::lock_guard lock(g_default_mutex);
    return g_budget.exchange(bytes);
}

size_t checked_array_bytes(std::string_view what, size_t count, size_t element_size) {
    if (element_size != 0 && count > std::numeric_limits<size_t>::max() / element_size)
        throw Error(std::string(what) + ": " + std::to_string(count) + " x " + std::to_string(element_size) +
                    " bytes overflows");
    const size_t bytes = count * element_size;
    const size_t budget = memory_budget();
    if (bytes > budget)
        throw Error(std::string(what) + ": " + std::to_string(bytes) + " bytes asked for, over the memory budget of " +
                    std::to_string(budget) + " bytes (set " + kEnvironmentVariable + " to change it)");
    return bytes;
}

uint32_t checked_index_count(std::string_view what, uint64_t count) {
    if (count > std::numeric_limits<uint32_t>::max())
        throw Error(std::string(what) + ": " + std::to_string(count) + " exceed 32-bit indices");
    return uint32_t(count);
}

}  // namespace rf
