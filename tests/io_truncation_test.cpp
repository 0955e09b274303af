// Robustness sweep: every committed OBJ/MTL, PLY and texture fixture, cut at
// many lengths, must either load or throw rf::Error (never crash or hang).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace fs = std::filesystem;

namespace rf {
namespace {

std::string read_bytes(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Cuts by truncate() and restores by appending: rewriting a file from
// scratch thousands of times makes ext4 flush it to disk on every close.
void restore_tail(const fs::path& path, const std::string& original, size_t length) {
    std::ofstream(path, std::ios::binary | std::ios::app) << original.substr(length);
}

// Loads what `changed` affects: itself, or for MTL files and OBJ textures
// every OBJ of the fixture folder `root`.
void load_affected(const fs::path& changed, const fs::path& root) {
    auto attempt = [](auto&& load) {
        try {
            load();
        } catch (const Error&) {
            // A clean rejection is a pass.
        }
    };
    const std::string ext = changed.extension().string();
    if (ext == ".ply") return attempt([&] { load_ply(changed.string()); });
    if (ext == ".obj") return attempt([&] { load_obj(changed.string()); });
    if (root.filename() == "textures") return attempt([&] { load_texture(changed.string()); });
    for (const auto& entry : fs::directory_iterator(root))
        if (entry.path().extension() == ".obj") attempt([&] { load_obj(entry.path().string()); });
}

// Cuts at every length for small files, at 64 spread lengths for larger ones.
std::vector<size_t> cut_lengths(size_t size) {
    std::vector<size_t> lengths;
    if (size <= 1200) {
        for (size_t n = 0; n < size; ++n) lengths.push_back(n);
    } else {
        for (size_t k = 0; k < 64; ++k) lengths.push_back(size * k / 64);
        lengths.push_back(size - 1);
    }
    return lengths;
}

void sweep(const std::string& area) {
    const fs::path work = fs::path(test::temp_dir("truncation_" + area)) / area;
    fs::copy(test::data_path(area), work, fs::copy_options::recursive);
    std::vector<fs::path> files;
    for (const auto& entry : fs::recursive_directory_iterator(work))
        if (entry.is_regular_file() && entry.path().extension() != ".py") files.push_back(entry.path());
    ASSERT_FALSE(files.empty());

    ::testing::internal::CaptureStderr();  // missing-texture warnings are expected here
    for (const fs::path& file : files) {
        const std::string original = read_bytes(file);
        for (size_t length : cut_lengths(original.size())) {
            SCOPED_TRACE(file.string() + " cut to " + std::to_string(length) + " bytes");
            fs::resize_file(file, length);
            load_affected(file, work);
            restore_tail(file, original, length);
        }
    }
    ::testing::internal::GetCapturedStderr();
}

TEST(IoTruncation, ObjFixturesLoadOrThrow) { sweep("obj"); }
TEST(IoTruncation, PlyFixturesLoadOrThrow) { sweep("ply"); }
TEST(IoTruncation, TextureFixturesLoadOrThrow) { sweep("textures"); }

}  // namespace
}  // namespace rf
