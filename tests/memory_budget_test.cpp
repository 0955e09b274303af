// The memory budget (rf::checked_array_bytes and friends): overflow, over
// budget, RAYFORGE_MEMORY_BUDGET parsing, and every loader failing cleanly,
// naming the file and the array, when a plausible count exceeds a tiny budget.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

// Sets a budget for one test and restores the previous one.
class ScopedBudget {
public:
    explicit ScopedBudget(size_t bytes) : previous_(set_memory_budget(bytes)) {}
    ~ScopedBudget() { set_memory_budget(previous_); }
    ScopedBudget(const ScopedBudget&) = delete;
    ScopedBudget& operator=(const ScopedBudget&) = delete;

private:
    size_t previous_;
};

// Runs `load` and returns the rf::Error message ("" when it did not throw).
template <class F>
std::string error_of(F&& load) {
    try {
        load();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

void expect_contains(const std::string& message, const std::string& fragment) {
    EXPECT_NE(message.find(fragment), std::string::npos) << "'" << fragment << "' not in: " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

TEST(MemoryBudget, DefaultIsPositive) { EXPECT_GT(memory_budget(), size_t(1) << 20); }

TEST(MemoryBudget, OverflowIsReported) {
    const size_t huge = std::numeric_limits<size_t>::max() / 4;
    std::string message = error_of([&] { (void)checked_array_bytes("PLY vertex array", huge, 12); });
    expect_contains(message, "PLY vertex array: " + std::to_string(huge) + " x 12 bytes overflows");
}

TEST(MemoryBudget, OverBudgetIsReportedAndUnderBudgetPasses) {
    ScopedBudget budget(1000);
    EXPECT_EQ(checked_array_bytes("small", 10, 100), 1000u);
    std::string message = error_of([] { (void)checked_array_bytes("texture 'foo.png'", 1001, 1); });
    expect_contains(message, "texture 'foo.png': 1001 bytes asked for, over the memory budget of 1000 bytes");
    expect_contains(message, "RAYFORGE_MEMORY_BUDGET");
}

TEST(MemoryBudget, SetReturnsThePreviousBudget) {
    const size_t before = memory_budget();
    const size_t previous = set_memory_budget(12345);
    EXPECT_EQ(memory_budget(), 12345u);
    EXPECT_EQ(set_memory_budget(previous), 12345u);
    EXPECT_EQ(memory_budget(), before);
}

TEST(MemoryBudget, BudgetedResizeChecksBeforeAllocating) {
    ScopedBudget budget(64);
    std::vector<float> v;
    budgeted_resize(v, 16, "floats");
    EXPECT_EQ(v.size(), 16u);
    expect_contains(error_of([&] { budgeted_resize(v, 17, "floats"); }), "floats: 68 bytes asked for");
    EXPECT_EQ(v.size(), 16u);
    std::vector<double> w;
    expect_contains(error_of([&] { budgeted_reserve(w, 1u << 20, "doubles"); }), "doubles: 8388608 bytes");
    EXPECT_EQ(w.capacity(), 0u);
    std::string grown = error_of([&] {
        for (int i = 0; i < 1000; ++i) budgeted_push_back(w, 1.0, "growing doubles");
    });
    expect_contains(grown, "growing doubles: ");
    EXPECT_LE(w.size() * sizeof(double), 64u);
}

TEST(MemoryBudget, IndexCountOverflow) {
    EXPECT_EQ(checked_index_count("vertices", 0xFFFFFFFFull), 0xFFFFFFFFu);
    expect_contains(error_of([] { (void)checked_index_count("x.ply: PLY vertex count", 0x100000000ull); }),
                    "x.ply: PLY vertex count: 4294967296 exceed 32-bit indices");
}

TEST(MemoryBudget, ParsesSizes) {
    EXPECT_EQ(parse_memory_size("4096"), size_t(4096));
    EXPECT_EQ(parse_memory_size("512K"), size_t(512) << 10);
    EXPECT_EQ(parse_memory_size("512M"), size_t(512) << 20);
    EXPECT_EQ(parse_memory_size("512m"), size_t(512) << 20);
    EXPECT_EQ(parse_memory_size("4G"), size_t(4) << 30);
    EXPECT_EQ(parse_memory_size(" 4GiB "), size_t(4) << 30);
    EXPECT_EQ(parse_memory_size("2GB"), size_t(2) << 30);
    EXPECT_EQ(parse_memory_size("1T"), size_t(1) << 40);
    EXPECT_EQ(parse_memory_size("100B"), size_t(100));
    for (const char* bad : {"", "0", "G", "-1", "1.5G", "4X", "4GG", "4 G B", "99999999999999999999999"})
        EXPECT_FALSE(parse_memory_size(bad).has_value()) << bad;
    EXPECT_FALSE(parse_memory_size("16777216T").has_value());  // 2^64: overflows
}

TEST(MemoryBudget, ReadsTheEnvironmentVariable) {
    const char* saved = std::getenv("RAYFORGE_MEMORY_BUDGET");
    const std::string saved_value = saved ? saved : "";
    const size_t previous = set_memory_budget(0);  // 0: back to the default, read again

    ::setenv("RAYFORGE_MEMORY_BUDGET", "3M", 1);
    set_memory_budget(0);
    EXPECT_EQ(memory_budget(), size_t(3) << 20);

    ::setenv("RAYFORGE_MEMORY_BUDGET", "lots", 1);
    set_memory_budget(0);
    expect_contains(error_of([] { (void)memory_budget(); }), "RAYFORGE_MEMORY_BUDGET: bad value 'lots'");

    if (saved) ::setenv("RAYFORGE_MEMORY_BUDGET", saved_value.c_str(), 1);
    else ::unsetenv("RAYFORGE_MEMORY_BUDGET");
    set_memory_budget(previous);
}

// --- Loaders: plausible counts over a tiny budget -----------------------------

std::string write_file(const std::string& dir, const std::string& name, const std::string& bytes) {
    const std::string path = dir + "/" + name;
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
}

// 10000 vertices (120 KB as floats) and one face, well within the file size check.
TEST(MemoryBudget, PlyVertexCountOverBudget) {
    std::string ply = "ply\nformat ascii 1.0\nelement vertex 10000\nproperty float x\nproperty float y\n"
                      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    for (int i = 0; i < 10000; ++i) ply += "0 0 0\n";
    ply += "3 0 1 2\n";
    const std::string path = write_file(test::temp_dir("budget_ply"), "many.ply", ply);
    EXPECT_NO_THROW(load_ply(path));
    ScopedBudget budget(64 << 10);
    expect_contains(error_of([&] { load_ply(path); }),
                    path + ": PLY vertex array: 120000 bytes asked for, over the memory budget of 65536 bytes");
}

TEST(MemoryBudget, ObjVertexArrayOverBudget) {
    std::string obj;
    for (int i = 0; i < 10000; ++i) obj += "v 0 0 0\n";
    obj += "f 1 2 3\n";
    const std::string path = write_file(test::temp_dir("budget_obj"), "many.obj", obj);
    EXPECT_NO_THROW(load_obj(path));
    ScopedBudget budget(64 << 10);
    expect_contains(error_of([&] { load_obj(path); }), path + ": OBJ vertex array: ");
}

// A PPM header alone: the budget is checked before the decoder allocates.
TEST(MemoryBudget, TextureHeaderOverBudget) {
    const std::string path = write_file(test::temp_dir("budget_texture"), "big.ppm", "P6\n4096 4096\n255\n");
    ScopedBudget budget(16 << 20);
    expect_contains(error_of([&] { load_texture(path); }),
                    "texture '" + path + "': 100663296 bytes asked for, over the memory budget of 16777216 bytes");
}

TEST(MemoryBudget, ExrOverBudget) {
    const std::string path = test::data_path("textures/tiny.exr");
    EXPECT_NO_THROW(load_texture(path));
    ScopedBudget budget(16);
    expect_contains(error_of([&] { load_texture(path); }), "texture '" + path + "': ");
}

TEST(MemoryBudget, GltfAccessorOverBudget) {
    const std::string path = test::data_path("gltf/cube.glb");
    ScopedBudget budget(64);
    expect_contains(error_of([&] { load_gltf(path); }), path + ": POSITION accessor ");
}

// Errors from a referenced file surface through the JSON scene loader.
TEST(MemoryBudget, JsonSceneReferencingOverBudgetFile) {
    const std::string path = test::data_path("json/scene.json");
    ScopedBudget budget(64);
    std::string message = error_of([&] { load_json_scene(path); });
    expect_contains(message, "bytes asked for, over the memory budget of 64 bytes");
}

}  // namespace
}  // namespace rf
