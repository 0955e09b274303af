// Inputs found by the fuzzers (fuzz/, scripts/fuzz.sh) that once crashed a
// loader or let another exception type escape. Each file under
// tests/data/<area>/regressions/ must now load or throw rf::Error, nothing else.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"
#include "test_paths.h"
#include "../fuzz/fuzz_animation.h"

namespace rf {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> regression_files(const std::string& area) {
    std::vector<std::string> files;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(test::data_path(area + "/regressions"), ec))
        if (entry.is_regular_file() && entry.path().extension() != ".py") files.push_back(entry.path().string());
    std::sort(files.begin(), files.end());
    return files;
}

// The loader the fuzz target for this file used.
void load_like_the_fuzzer(const std::string& area, const std::string& path) {
    if (area == "textures") {
        std::ifstream in(path, std::ios::binary);
        std::vector<unsigned char> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        (void)load_texture_from_memory(bytes.data(), bytes.size(), path);
    } else {
        (void)load_scene(path);
    }
}

// "" when the file loaded or threw rf::Error; otherwise what escaped.
std::string other_exception(const std::string& area, const std::string& path) {
    try {
        load_like_the_fuzzer(area, path);
    } catch (const Error&) {
    } catch (const std::exception& e) {
        return std::string("std::exception: ") + e.what();
    } catch (...) {
        return "unknown exception";
    }
    return "";
}

class FuzzRegressions : public testing::TestWithParam<const char*> {};

TEST_P(FuzzRegressions, LoadOrThrowRfErrorOnly) {
    const std::string area = GetParam();
    // The fuzzers run with this budget; some regressions are about it.
    const size_t previous = set_memory_budget(size_t(256) << 20);
    for (const std::string& path : regression_files(area)) EXPECT_EQ(other_exception(area, path), "") << path;
    set_memory_budget(previous);
}

INSTANTIATE_TEST_SUITE_P(Areas, FuzzRegressions, testing::Values("obj", "ply", "gltf", "json", "textures"));

// Found while writing fuzz_json_scene: a file name longer than NAME_MAX made
// std::filesystem::is_regular_file throw filesystem_error.
TEST(FuzzRegressionsJson, OverlongFileNamesAreNotFound) {
    for (const char* name : {"json/regressions/long_mesh_file_name.json", "json/regressions/long_texture_file_name.json"}) {
        try {
            load_json_scene(test::data_path(name));
            FAIL() << name << " loaded";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("not found"), std::string::npos) << e.what();
        }
    }
}

// Found by fuzz_json_scene: a number beyond double's range ("3e308") made
// nlohmann::json throw out_of_range, which escaped as a non-rf::Error.
TEST(FuzzRegressionsJson, NumberOverflowIsAnRfError) {
    for (const char* name : {"json/regressions/number_overflow.json", "json/regressions/number_overflow_fuzzed.json"}) {
        try {
            load_json_scene(test::data_path(name));
            FAIL() << name << " loaded";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
        }
    }
}

// Found by fuzz_exr: tinyexr's PIZ decoder read past the end of the buffer
// (heap-buffer-overflow under ASan); PIZ files are now refused.
TEST(FuzzRegressionsTextures, PizExrIsRefused) {
    const std::string path = test::data_path("textures/regressions/exr_piz_out_of_bounds_read.exr");
    try {
        load_texture(path);
        FAIL() << "loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("PIZ compression is not supported"), std::string::npos) << e.what();
    }
}

// Found by fuzz_texture: a PNG whose IDAT chunk declares about 1 GB in a
// 70-byte file made stb_image grow its buffer to 2 GB before reading it.
// Chunk lengths are now checked against the file first.
TEST(FuzzRegressionsTextures, PngChunkLongerThanTheFileIsRefusedBeforeAllocating) {
    const std::string path = test::data_path("textures/regressions/png_idat_length_oom.png");
    try {
        load_texture(path);
        FAIL() << "loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("PNG chunk declares"), std::string::npos) << e.what();
    }
}

// Found by fuzz_exr: tinyexr read 9 bytes from a shorter "tiles" attribute.
TEST(FuzzRegressionsTextures, ShortTilesAttributeIsRefused) {
    const std::string path = test::data_path("textures/regressions/exr_header_out_of_bounds_read.exr");
    try {
        load_texture(path);
        FAIL() << "loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("malformed 'tiles' or 'compression' attribute"), std::string::npos)
            << e.what();
    }
}

std::string gltf_error(const std::string& name) {
    try {
        load_gltf(test::data_path("gltf/regressions/" + name));
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

// Nodes shared by several parents are visited once per path: 40 levels of
// "two children, the same node" made 2^40 visits (a hang).
TEST(FuzzRegressionsGltf, SharedNodesCannotMultiplyWithoutBound) {
    EXPECT_NE(gltf_error("shared_node_explosion.gltf").find("node hierarchy expands to more than"), std::string::npos);
}

// One recursion level per node: a long chain overflowed the stack.
TEST(FuzzRegressionsGltf, NodeChainDepthIsLimited) {
    EXPECT_NE(gltf_error("deep_node_chain.gltf").find("levels deep"), std::string::npos);
}

// A file that names a FIFO (a texture, a glTF buffer) must fail at once, not
// wait for a writer: opening a FIFO for reading blocks.
TEST(FuzzRegressionsFiles, FifoIsNotARegularFile) {
    const std::string dir = test::temp_dir("fuzz_fifo");
    const std::string fifo = dir + "/pipe.png";
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    EXPECT_THROW(load_texture(fifo), Error);

    const std::string gltf = dir + "/pipe.gltf";
    std::ofstream(gltf) << R"({"asset": {"version": "2.0"}, "buffers": [{"uri": "pipe.png", "byteLength": 4}]})";
    EXPECT_THROW(load_gltf(gltf), Error);
}

// ---- animation: tests/data/fuzz_repro/{aff,json_scene,gltf,glb}_*.{aff,json,gltf,glb} ----
// Inputs of the scene-format fuzz targets, replayed as the harness runs them:
// next to the harness's scratch files, loaded (rf::Error is an accepted
// outcome), then animated under fuzz/fuzz_animation.h's checks.

// The files the harnesses write next to the input (fuzz_common.h, fuzz_json_scene.cpp).
void write_harness_files(const std::string& dir) {
    auto write = [&](const std::string& name, const std::string& bytes) {
        std::ofstream(dir + "/" + name, std::ios::binary) << bytes;
    };
    write("t.ppm", std::string("P6\n2 2\n255\n") + std::string(12, '\x80'));
    const float quad[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const uint16_t indices[] = {0, 1, 2, 0, 2, 3};
    write("buf.bin", std::string(reinterpret_cast<const char*>(quad), sizeof quad) +
                         std::string(reinterpret_cast<const char*>(indices), sizeof indices));
    write("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write("m.ply",
          "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
          "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
}

struct AnimationRepro {
    std::string path, target;  // target: aff, json_scene, gltf or glb (the file name's prefix)
};

std::vector<AnimationRepro> animation_repros() {
    std::vector<AnimationRepro> out;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(test::data_path("fuzz_repro"), ec)) {
        const std::string name = entry.path().filename().string();
        for (const char* target : {"aff_", "json_scene_", "gltf_", "glb_"})
            if (name.rfind(target, 0) == 0) out.push_back({entry.path().string(), std::string(target, std::strlen(target) - 1)});
    }
    std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.path < b.path; });
    return out;
}

// "" when the reproducer loads and animates consistently or throws rf::Error while loading.
std::string replay_animation_repro(const AnimationRepro& repro, const std::string& dir) {
    write_harness_files(dir);
    const std::string input = dir + "/input" + fs::path(repro.path).extension().string();
    fs::copy_file(repro.path, input, fs::copy_options::overwrite_existing);
    Scene scene;
    try {
        if (repro.target == "aff") scene = load_aff(input), scene.finalize();
        else if (repro.target == "json_scene") scene = load_json_scene(input), scene.finalize();
        else scene = load_gltf(input);
    } catch (const Error&) {
        return "";
    } catch (const std::exception& e) {
        return std::string("std::exception: ") + e.what();
    }
    try {
        return fuzz::check_animation(scene);
    } catch (const std::exception& e) {
        return std::string("escaped the animation: ") + e.what();
    }
}

TEST(FuzzRegressionsAnimation, ReproducersLoadOrThrowAndAnimateConsistently) {
    const std::vector<AnimationRepro> repros = animation_repros();
    ASSERT_FALSE(repros.empty()) << "no tests/data/fuzz_repro/{aff,json_scene,gltf,glb}_* reproducers";
    const size_t previous = set_memory_budget(size_t(256) << 20);
    const std::string dir = test::temp_dir("fuzz_animation_repro");
    for (const AnimationRepro& repro : repros) EXPECT_EQ(replay_animation_repro(repro, dir), "") << repro.path;
    set_memory_budget(previous);
}

// Sets the memory budget for one scope.
struct BudgetScope {
    size_t previous;
    explicit BudgetScope(size_t bytes) : previous(set_memory_budget(bytes)) {}
    ~BudgetScope() { set_memory_budget(previous); }
};

// Found while fuzzing the animation (crafted inputs, make_animation_repros.py):
// a deformed glTF mesh is copied per node using it (with all its morph
// targets), and an AFF `k` block's keys per `x` block of its name, so a
// small file asked for gigabytes in allocations each under the budget. Both
// loaders now count these copies together against the budget.
TEST(FuzzRegressionsAnimation, CopiesPerNodeCountAgainstTheBudget) {
    const BudgetScope budget(size_t(16) << 20);  // the files need about 20 MB and 17 MB
    const std::pair<const char*, const char*> cases[] = {
        {"fuzz_repro/gltf_morph_targets_copied_per_node.gltf", "animation data (tracks per channel, deformed meshes"},
        {"fuzz_repro/aff_keyframes_copied_per_transform_block.aff", "AFF geometry and keyframes"}};
    for (const auto& [name, expected] : cases) {
        try {
            (void)load_scene(test::data_path(name));
            ADD_FAILURE() << name << " loaded under a 16 MiB budget";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
        }
    }
}

// Under the fuzzers' budget the same files load and animate.
TEST(FuzzRegressionsAnimation, CopiesPerNodeLoadUnderTheFuzzBudget) {
    const BudgetScope budget(size_t(256) << 20);
    Scene gltf = load_scene(test::data_path("fuzz_repro/gltf_morph_targets_copied_per_node.gltf"));
    EXPECT_EQ(gltf.animation.morphs.size(), 120u);
    EXPECT_EQ(fuzz::check_animation(gltf), "");
    Scene aff = load_scene(test::data_path("fuzz_repro/aff_keyframes_copied_per_transform_block.aff"));
    EXPECT_EQ(aff.animation.nodes.size(), 1501u);
    EXPECT_EQ(fuzz::check_animation(aff), "");
}

}  // namespace
}  // namespace rf
