// Shared by the fuzz targets. The contract they check: a loader given any
// bytes either succeeds or throws rf::Error. Anything else escaping (another
// exception type), a crash, a sanitizer report, a hang (-timeout) or an
// allocation over -rss_limit_mb/-malloc_limit_mb is a bug.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf::fuzz {

// Small enough that the budget checks are exercised, large enough for real inputs.
constexpr size_t kFuzzMemoryBudget = size_t(256) << 20;

// A per-process scratch directory (tmpfs when there is one): the loaders take
// paths, and parallel fuzzing jobs must not share files.
inline const std::string& scratch_dir() {
    // Never destroyed: the atexit cleanup below runs after static destructors.
    static const std::string* dir = [] {
        const char* base = std::filesystem::is_directory("/dev/shm") ? "/dev/shm" : "/tmp";
        auto* d = new std::string(std::string(base) + "/rayforge-fuzz-" + std::to_string(::getpid()));
        std::filesystem::create_directories(*d);
        return d;
    }();
    return *dir;
}

inline std::string write_scratch(const std::string& name, const uint8_t* data, size_t size) {
    const std::string path = scratch_dir() + "/" + name;
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) std::abort();
    if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
    std::fclose(f);
    return path;
}

inline std::string write_scratch(const std::string& name, const std::string& text) {
    return write_scratch(name, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

// A 2x2 binary PPM, for the texture references of the scene formats.
inline void write_scratch_texture() {
    const std::string ppm = std::string("P6\n2 2\n255\n") + std::string(12, '\x80');
    write_scratch("t.ppm", ppm);
}

// Once per process: the low budget, warnings (std::cerr) silenced.
// Files a glTF input may reference by URI: buf.bin (a quad's floats and
// indices) and t.ppm, so buffer and image references can succeed. Once per process.
inline void write_scratch_gltf_files() {
    static const bool written = [] {
        write_scratch_texture();
        const float quad[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
        const uint16_t indices[] = {0, 1, 2, 0, 2, 3};
        std::string bin(reinterpret_cast<const char*>(quad), sizeof quad);
        bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
        write_scratch("buf.bin", bin);
        return true;
    }();
    (void)written;
}

inline void init_once() {
    static const bool done = [] {
        set_memory_budget(kFuzzMemoryBudget);
        std::cerr.rdbuf(nullptr);
        std::atexit([] {
            std::error_code ec;
            std::filesystem::remove_all(scratch_dir(), ec);
        });
        return true;
    }();
    (void)done;
}

// Runs one load: rf::Error is an accepted outcome; every other exception escapes
// to libFuzzer, which reports it as a crash.
template <class F>
void expect_success_or_rf_error(F&& load) {
    try {
        load();
    } catch (const rf::Error&) {
    }
}

}  // namespace rf::fuzz
