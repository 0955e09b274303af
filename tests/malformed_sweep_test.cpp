// End-to-end robustness sweep through the CLI: every committed scene fixture
// of every format, truncated at random offsets and with its counts corrupted,
// must make `rayforge info` either succeed or fail cleanly: exit status 1 and
// exactly one stderr line "rayforge: error: ..." (warnings aside). A crash,
// a hang, a sanitizer report or a multi-line message fails the test.
#include <gtest/gtest.h>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "cli_runner.h"
#include "test_paths.h"

namespace fs = std::filesystem;

namespace rf {
namespace {

void write_all(const fs::path& p, const std::string& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out << bytes;
}

struct Outcome {
    int exit_code = -1;
    std::vector<std::string> error_lines;  // stderr lines other than warnings and notes
};

Outcome run_info(const fs::path& scene) {
    // `timeout` turns a hang into a failure instead of a stuck test run.
    const test::CliResult r = test::run_cli("info '" + scene.string() + "'", "timeout 20");
    Outcome o;
    o.exit_code = r.exit_code;
    for (const std::string& line : test::lines_of(r.err))
        if (line.rfind("rayforge: warning: ", 0) != 0 && line.rfind("rayforge: note: ", 0) != 0)
            o.error_lines.push_back(line);
    return o;
}

void expect_clean(const Outcome& o, const std::string& what) {
    if (o.exit_code == 0) {
        EXPECT_TRUE(o.error_lines.empty()) << what << ": succeeded but printed " << o.error_lines.front();
        return;
    }
    EXPECT_EQ(o.exit_code, 1) << what << " (124 = hang, -1 = killed by a signal)";
    ASSERT_EQ(o.error_lines.size(), 1u) << what << ": expected one error line";
    EXPECT_EQ(o.error_lines[0].rfind("rayforge: error: ", 0), 0u) << what << ": " << o.error_lines[0];
}

// Replaces the k-th decimal number of the text by `replacement` (counts in
// headers, indices, accessor sizes, byte lengths...).
std::string corrupt_number(const std::string& text, size_t k, const std::string& replacement) {
    static const std::regex number(R"(\d+)");
    size_t i = 0;
    for (auto it = std::sregex_iterator(text.begin(), text.end(), number); it != std::sregex_iterator(); ++it, ++i) {
        if (i == k) return text.substr(0, it->position()) + replacement + text.substr(it->position() + it->length());
    }
    return text;
}

size_t count_numbers(const std::string& text) {
    static const std::regex number(R"(\d+)");
    return size_t(std::distance(std::sregex_iterator(text.begin(), text.end(), number), std::sregex_iterator()));
}

struct Fixture {
    std::string area;   // folder under tests/data; copied whole so references resolve
    std::string file;   // the file that is damaged
    std::string scene;  // the scene loaded (the file itself, or the one referencing it)
};

class MalformedSweep : public testing::TestWithParam<Fixture> {};

TEST_P(MalformedSweep, TruncatedAndCorruptedFilesFailCleanly) {
    const Fixture& f = GetParam();
    const fs::path source_dir = test::data_path(f.area);
    const fs::path scratch = test::temp_dir("sweep_" + f.area + "_" + fs::path(f.file).stem().string());
    for (const auto& entry : fs::directory_iterator(source_dir))
        if (entry.is_regular_file()) fs::copy_file(entry.path(), scratch / entry.path().filename());
    const fs::path target = scratch / f.file;
    const fs::path scene = scratch / f.scene;
    const std::string original = test::read_file(target.string());
    ASSERT_FALSE(original.empty());

    std::mt19937 rng(12345u + uint32_t(original.size()));
    // Truncations at seeded random offsets, plus the empty file.
    std::vector<size_t> cuts = {0};
    std::uniform_int_distribution<size_t> offset(1, original.size() - 1);
    for (int i = 0; i < 12; ++i) cuts.push_back(offset(rng));
    for (size_t cut : cuts) {
        write_all(target, original.substr(0, cut));
        expect_clean(run_info(scene), f.file + " cut at byte " + std::to_string(cut));
    }
    // Corrupted counts: numbers made huge, zero or negative (text formats and
    // the JSON chunk of a GLB both carry their counts as decimal text).
    const size_t numbers = count_numbers(original);
    if (numbers > 0) {
        std::uniform_int_distribution<size_t> which(0, numbers - 1);
        const char* replacements[] = {"4294967296000", "0", "-1", "99999999"};
        for (int i = 0; i < 12; ++i) {
            const size_t k = which(rng);
            const std::string replacement = replacements[i % 4];
            write_all(target, corrupt_number(original, k, replacement));
            expect_clean(run_info(scene),
                         f.file + " with number #" + std::to_string(k) + " set to " + replacement);
        }
    }
    write_all(target, original);
}

std::string fixture_name(const testing::TestParamInfo<Fixture>& info) {
    std::string name = info.param.area + "_" + info.param.file + "_in_" + info.param.scene;
    for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
    return name;
}

INSTANTIATE_TEST_SUITE_P(
    EveryFormat, MalformedSweep,
    testing::Values(Fixture{"obj", "cube.obj", "cube.obj"}, Fixture{"obj", "cube.mtl", "cube.obj"},
                    Fixture{"obj", "materials.obj", "materials.obj"}, Fixture{"obj", "polygon.obj", "polygon.obj"},
                    Fixture{"ply", "pyramid_ascii.ply", "pyramid_ascii.ply"},
                    Fixture{"ply", "pyramid_binary_le.ply", "pyramid_binary_le.ply"},
                    Fixture{"ply", "pyramid_binary_be.ply", "pyramid_binary_be.ply"},
                    Fixture{"gltf", "quad_external.gltf", "quad_external.gltf"},
                    Fixture{"gltf", "quad_external.bin", "quad_external.gltf"},
                    Fixture{"gltf", "embedded.gltf", "embedded.gltf"},
                    Fixture{"gltf", "hierarchy.gltf", "hierarchy.gltf"}, Fixture{"gltf", "cube.glb", "cube.glb"},
                    Fixture{"gltf", "checker.png", "hierarchy.gltf"}, Fixture{"json", "scene.json", "scene.json"},
                    Fixture{"json", "triangle.ply", "scene.json"}),
    fixture_name);

}  // namespace
}  // namespace rf
