// Writes the seed corpus of fuzz/fuzz_pack.cpp: small paged scene files
// (each well under the fuzzer's -max_len of 16 KB) of every kind the format
// has, each twice: "<name>-raw.bin" (mode byte 0: the file as written, so
// checksums stop most mutations at the door) and "<name>-fix.bin" (mode
// 0x23: the harness recomputes every checksum and the file size, and
// renders with the file's camera, so mutations reach the structure checks
// and the traversal).
//
//   build/bin/rayforge-make-pack-fuzz-seeds tests/fuzz/pack
//
// Run it again whenever the file format changes (pack_format.h's kVersion).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "ooc/convert_scene.h"
#include "ooc/pack_writer.h"
#include "rayforge/core/error.h"
#include "rayforge/scene/scene.h"

namespace {

using namespace rf;

Mesh make_mesh(std::vector<Vec3f> positions, std::vector<uint32_t> indices, bool uvs) {
    Mesh m;
    m.positions = std::move(positions);
    m.indices = std::move(indices);
    if (uvs)
        for (const Vec3f& p : m.positions) m.uvs.push_back(Vec2f(p.x, p.y));
    m.material_ids.assign(m.triangle_count(), 0);
    m.compute_vertex_normals();
    return m;
}

Mesh quad(float z) { return make_mesh({{0, 0, z}, {1, 0, z}, {1, 1, z}, {0, 1, z}}, {0, 1, 2, 0, 2, 3}, true); }
Mesh lone_triangle() { return make_mesh({{2, 0, 0}, {3, 0, 0.5f}, {2, 1, 0}}, {0, 1, 2}, false); }
Mesh tetrahedron(const Vec3f& at) {
    return make_mesh({at, at + Vec3f(1, 0, 0), at + Vec3f(0, 1, 0), at + Vec3f(0, 0, 1)},
                     {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3}, false);
}
// A wavy n x n grid: 2 n^2 triangles, many pages at 64 quads a page.
Mesh wavy_grid(int n) {
    std::vector<Vec3f> p;
    std::vector<uint32_t> idx;
    for (int y = 0; y <= n; ++y)
        for (int x = 0; x <= n; ++x) p.push_back(Vec3f(float(x), float(y), 0.3f * float((x * 7 + y * 3) % 5)));
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            const uint32_t a = uint32_t(y * (n + 1) + x), b = a + 1, c = a + uint32_t(n + 1), d = c + 1;
            idx.insert(idx.end(), {a, b, d, a, d, c});
        }
    return make_mesh(std::move(p), std::move(idx), false);
}

Texture checker(int width, int height, int channels) {
    Texture t;
    t.name = "checker";
    t.width = width;
    t.height = height;
    t.channels = channels;
    t.encoding = TextureEncoding::Srgb8;
    t.texels8.resize(size_t(width) * size_t(height) * size_t(channels));
    for (size_t i = 0; i < t.texels8.size(); ++i) t.texels8[i] = uint8_t((i / size_t(channels)) % 7 * 40);
    return t;
}

Scene scene_of(std::vector<Mesh> meshes, std::vector<Texture> textures = {}) {
    Scene s;
    s.meshes = std::move(meshes);
    s.textures = std::move(textures);
    Material m;
    if (!s.textures.empty()) m.base_color_texture = 0;
    s.materials.push_back(m);
    if (s.textures.size() > 1) {
        Material second;
        second.base_color_texture = 1;
        s.materials.push_back(second);
        for (uint32_t& id : s.meshes.back().material_ids) id = 1;
    }
    s.finalize();
    return s;
}

void write_seeds(const std::string& dir, const std::string& name, const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    const std::vector<char> bytes{std::istreambuf_iterator<char>(in), {}};
    if (bytes.size() + 1 > 16384) throw Error(name + ": " + std::to_string(bytes.size()) + " bytes, over the fuzzer's 16 KB");
    for (const auto& [suffix, mode] : {std::pair<const char*, char>{"raw", 0x00}, {"fix", 0x23}}) {
        std::ofstream out(dir + "/" + name + "-" + suffix + ".bin", std::ios::binary);
        out.put(mode);
        out.write(bytes.data(), std::streamsize(bytes.size()));
    }
    std::printf("%s: %zu bytes\n", name.c_str(), bytes.size());
}

void convert(const std::string& dir, const std::string& name, const Scene& scene, pack::PackWriterOptions options) {
    const std::string file = dir + "/" + name + ".rfpack";
    options.threads = 1;
    pack::convert_scene(scene, file, options);
    write_seeds(dir, name, file);
    std::filesystem::remove(file);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s OUTPUT_DIR\n", argv[0]);
        return 2;
    }
    const std::string dir = argv[1];
    try {
        std::filesystem::create_directories(dir);
        using pack::AttributeFormat;
        using pack::Codec;
        using pack::PackWriterOptions;
        using pack::TopLevel;
        PackWriterOptions plain;  // the defaults: shared-vertex attributes, the meshopt codec
        convert(dir, "triangles", scene_of({quad(0.0f), lone_triangle()}), plain);
        PackWriterOptions full_raw = plain;
        full_raw.attribute_format = AttributeFormat::Full;
        full_raw.codec = Codec::None;
        convert(dir, "full-raw", scene_of({quad(0.0f), lone_triangle(), wavy_grid(6)}), full_raw);
        convert(dir, "shared-meshopt", scene_of({wavy_grid(12), tetrahedron(Vec3f(0, 0, 2))}), plain);
        PackWriterOptions grid = plain;
        grid.top_level = TopLevel::Grid;
        grid.grid_resolution = 4;
        convert(dir, "grid", scene_of({quad(0.0f), lone_triangle(), tetrahedron(Vec3f(0, 0, 2))}), grid);
        PackWriterOptions zstd = plain;
        zstd.codec = Codec::Zstd;
        convert(dir, "zstd", scene_of({tetrahedron(Vec3f(0.0f)), tetrahedron(Vec3f(3, 0, 0)), quad(1.0f)}), zstd);
        convert(dir, "texture", scene_of({quad(0.0f)}, {checker(2, 2, 3)}), plain);  // 4 KB a tile
        convert(dir, "textures-zstd", scene_of({quad(0.0f), quad(2.0f)}, {checker(8, 8, 4), checker(20, 12, 1)}), zstd);
        PackWriterOptions compact = plain;
        compact.attribute_format = AttributeFormat::Compact;
        convert(dir, "compact", scene_of({quad(0.0f), lone_triangle()}), compact);
        // A mesh placed four times (one mirrored) beside a unique one: instances.
        {
            Scene scene = scene_of({tetrahedron(Vec3f(0.0f)), quad(-1.0f)});
            scene.instances.clear();
            const Affine3f moves[4] = {Affine3f::identity(), Affine3f::translation(Vec3f(3, 0, 0)),
                                       Affine3f::translation(Vec3f(0, 3, 1)) * Affine3f::scale(Vec3f(2.0f)),
                                       Affine3f::scale(Vec3f(-1, 1, 1))};
            for (const Affine3f& m : moves) scene.instances.push_back({0, m, true});
            scene.instances.push_back({1, Affine3f::identity(), true});
            scene.finalize();
            convert(dir, "instances", scene, zstd);
            PackWriterOptions grid_instances = grid;
            convert(dir, "instances-grid", scene, grid_instances);
        }
        // Many small pages: a top BVH of several levels.
        PackWriterOptions pages = compact;
        pages.codec = Codec::Zstd;
        pages.quads_per_page = 64;
        convert(dir, "many-pages", scene_of({wavy_grid(16)}), pages);
        // Textures and no geometry at all.
        {
            const std::string file = dir + "/no-geometry.rfpack";
            PackWriterOptions options = plain;
            options.threads = 1;
            pack::PackWriter writer(file, options);
            writer.add_texture(checker(3, 2, 3));
            writer.add_material(ShadingMaterial::from(Material{}));
            writer.finish();
            write_seeds(dir, "no-geometry", file);
            std::filesystem::remove(file);
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "make-pack-fuzz-seeds: %s\n", e.what());
        return 1;
    }
    return 0;
}
