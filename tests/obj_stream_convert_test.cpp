// The streaming OBJ converter (src/ooc/obj_stream_convert.h): its file is
// the in-core scene's up to quantisation, whatever the object size; missing
// normals are smoothed as the loader smooths them; lines cut by its read
// blocks, CRLF and polygons read as the loader reads them; bad input and bad
// budgets are one-line errors; the process stays within the budget.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "accel_test_rays.h"
#include "cli_runner.h"
#include "ooc/obj_stream_convert.h"
#include "ooc/pack_file.h"
#include "ooc/paged_engine.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "render/shading_triangles.h"
#include "test_paths.h"

namespace rf {
namespace {

using namespace rf::pack;

// The builtin spheres scene (instances flattened) as an OBJ file: shared
// vertices, a usemtl per material, with or without vertex normals.
void write_spheres_obj(const std::string& path, bool normals) {
    Scene scene = make_builtin_scene("spheres");
    scene.finalize();
    std::ofstream out(path);
    uint64_t base = 0;
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes[instance.mesh];
        for (const Vec3f& p : mesh.positions) {
            const Vec3f w = instance.transform.transform_point(p);
            out << "v " << w.x << ' ' << w.y << ' ' << w.z << '\n';
        }
        const bool with_normals = normals && !mesh.normals.empty();
        if (with_normals)
            for (const Vec3f& n : mesh.normals) {
                const Vec3f w = normalize(instance.transform.normal_matrix().transform_vector(n));
                out << "vn " << w.x << ' ' << w.y << ' ' << w.z << '\n';
            }
        uint32_t material = ~0u;
        for (size_t t = 0; t < mesh.triangle_count(); ++t) {
            if (mesh.material_ids[t] != material) out << "usemtl m" << (material = mesh.material_ids[t]) << '\n';
            out << 'f';
            for (int k = 0; k < 3; ++k) {
                const uint64_t v = base + mesh.indices[3 * t + size_t(k)] + 1;
                out << ' ' << v;
                if (with_normals) out << "//" << v;
            }
            out << '\n';
        }
        base += mesh.positions.size();
    }
}

StreamConvertResult stream(const std::string& obj, const std::string& out, uint64_t max_object = 0) {
    StreamConvertOptions s;
    s.memory_budget = kMinStreamBudget;
    s.max_object_triangles = max_object;
    PackWriterOptions w;
    w.quads_per_page = 256;
    return convert_obj_streaming(obj, out, w, s);
}

struct Agreement {
    double hit_or_miss = 0, same_surface = 0, same_normal = 0;
};

// Paged hits of `rfpack` against the in-core scene loaded from `obj`.
Agreement compare_with_in_core(const std::string& obj, const std::string& rfpack, float tolerance) {
    Scene scene = load_scene(obj);
    const SceneGeometry geometry = SceneGeometry::build(scene);
    const auto accel = build_accel(geometry);
    const std::vector<ShadingTriangle> in_core = build_shading_triangles(scene, geometry);
    auto file = std::make_shared<const PackFile>(rfpack);
    PagedEngine engine(file, {size_t(1) << 20, size_t(1) << 16}, 0);
    const std::vector<Ray> rays = test::make_rays(geometry, 4000, 5);
    std::vector<Hit> paged(rays.size()), exact(rays.size());
    engine.intersect(rays, paged);
    accel->intersect(rays, exact);
    std::vector<ShadingTriangle> records(rays.size());
    engine.fetch_shading(paged, records);
    size_t agree = 0, both = 0, surface = 0, normal = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        if (paged[i].found() != exact[i].found()) continue;
        ++agree;
        if (!exact[i].found()) continue;
        ++both;
        const Vec3f a = rays[i].org + rays[i].dir * paged[i].t, b = rays[i].org + rays[i].dir * exact[i].t;
        if (length(a - b) > tolerance) continue;
        const ShadingTriangle& want = in_core[exact[i].prim];
        if (records[i].material != want.material || dot(records[i].geometric_normal, want.geometric_normal) < 0.95f)
            continue;
        ++surface;
        const SurfaceHit got_s = shading_surface(records[i], rays[i], paged[i]);
        const SurfaceHit want_s = shading_surface(want, rays[i], exact[i]);
        if (dot(got_s.shading_normal, want_s.shading_normal) > 0.99f) ++normal;
    }
    return {double(agree) / double(rays.size()), double(surface) / double(std::max<size_t>(1, both)),
            double(normal) / double(std::max<size_t>(1, surface))};
}

TEST(ObjStreamConvert, StreamedFileHasTheInCoreHitsWhateverTheObjectSize) {
    const std::string dir = test::temp_dir("obj_stream_hits");
    write_spheres_obj(dir + "/spheres.obj", true);
    const uint64_t triangles = load_scene(dir + "/spheres.obj").triangle_count();
    for (uint64_t max_object : {uint64_t(0), uint64_t(5000), uint64_t(700)}) {
        const std::string out = dir + "/spheres-" + std::to_string(max_object) + ".rfpack";
        const StreamConvertResult r = stream(dir + "/spheres.obj", out, max_object);
        EXPECT_EQ(r.convert.summary.triangles, triangles);
        if (max_object > 0) EXPECT_GE(r.objects, triangles / max_object) << max_object;
        const float tolerance = 200.0f * float(r.convert.summary.max_quantisation_error);
        const Agreement a = compare_with_in_core(dir + "/spheres.obj", out, tolerance);
        EXPECT_GT(a.hit_or_miss, 0.995) << max_object;
        EXPECT_GT(a.same_surface, 0.99) << max_object;
        EXPECT_GT(a.same_normal, 0.99) << max_object;
    }
}

// Without vn lines, both paths smooth area-weighted face normals per vertex
// (the file has no uvs, so the loader's vertices are the file's positions).
TEST(ObjStreamConvert, MissingNormalsAreSmoothedAsTheLoaderSmoothsThem) {
    const std::string dir = test::temp_dir("obj_stream_normals");
    write_spheres_obj(dir + "/flat.obj", false);
    const StreamConvertResult r = stream(dir + "/flat.obj", dir + "/flat.rfpack", 3000);
    const Agreement a =
        compare_with_in_core(dir + "/flat.obj", dir + "/flat.rfpack", 200.0f * float(r.convert.summary.max_quantisation_error));
    EXPECT_GT(a.same_surface, 0.99);
    EXPECT_GT(a.same_normal, 0.99);
}

// A file read in 4 KiB blocks, with CRLF line ends, polygons, negative
// indices, a comment longer than a block and no final newline: the
// loader's triangles.
TEST(ObjStreamConvert, BlocksCrlfPolygonsAndNegativeIndicesReadAsTheLoaderReadsThem) {
    const std::string dir = test::temp_dir("obj_stream_blocks");
    std::ostringstream text;
    const int n = 120;  // a 120 x 120 grid of quads: about 600 KB of text
    text << "# " << std::string(10000, 'c') << "\r\n";
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) text << "v " << x * 0.01 << ' ' << y * 0.01 << ' ' << 0.001 * ((x * 7 + y * 3) % 11) << "\r\n";
    for (int y = 0; y + 1 < n; ++y)
        for (int x = 0; x + 1 < n; ++x) {
            const int v = y * n + x + 1;
            if ((x + y) % 3 == 0) text << "f -" << (n * n - v + 1) << " -" << (n * n - v) << ' ' << v + n + 1 << ' ' << v + n << "\r\n";
            else text << "f " << v << ' ' << v + 1 << ' ' << v + n + 1 << ' ' << v + n << "\r\n";
        }
    text << "f 1 2 " << n + 2;  // no final newline
    std::ofstream(dir + "/grid.obj", std::ios::binary) << text.str();
    const uint64_t triangles = load_scene(dir + "/grid.obj").triangle_count();
    StreamConvertOptions s;
    s.memory_budget = kMinStreamBudget;
    s.read_block_bytes = 4096;
    const StreamConvertResult r = convert_obj_streaming(dir + "/grid.obj", dir + "/grid.rfpack", {}, s);
    EXPECT_EQ(r.convert.summary.triangles, triangles);
    EXPECT_EQ(triangles, uint64_t(2 * (n - 1) * (n - 1) + 1));
    const Agreement a =
        compare_with_in_core(dir + "/grid.obj", dir + "/grid.rfpack", 200.0f * float(r.convert.summary.max_quantisation_error));
    EXPECT_GT(a.hit_or_miss, 0.995);
    EXPECT_GT(a.same_surface, 0.99);
}

TEST(ObjStreamConvert, BudgetPlanAndObjects) {
    EXPECT_THROW(plan_stream_budget(kMinStreamBudget - 1), Error);
    const StreamBudget small = plan_stream_budget(kMinStreamBudget), large = plan_stream_budget(size_t(8) << 30);
    EXPECT_GT(small.max_object_triangles, 1000u);
    EXPECT_GT(large.max_object_triangles, 50 * small.max_object_triangles);
    for (const StreamBudget& b : {small, large})
        EXPECT_LE(b.fixed_bytes + b.cache_bytes + b.max_object_triangles * kObjectBytesPerTriangle,
                  &b == &small ? kMinStreamBudget : size_t(8) << 30);
}

std::string stream_error(const std::string& dir, const std::string& name, const std::string& text,
                         const std::string& temp_dir = "") {
    std::ofstream(dir + "/" + name) << text;
    StreamConvertOptions s;
    s.memory_budget = kMinStreamBudget;
    s.temp_dir = temp_dir;
    try {
        convert_obj_streaming(dir + "/" + name, dir + "/out.rfpack", {}, s);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

TEST(ObjStreamConvert, BadInputIsAOneLineError) {
    const std::string dir = test::temp_dir("obj_stream_errors");
    const std::string tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    const std::string bad_number = stream_error(dir, "a.obj", tri + "v 1 x 0\nf 1 2 3\n");
    EXPECT_NE(bad_number.find("a.obj:4"), std::string::npos) << bad_number;
    EXPECT_NE(bad_number.find("bad number"), std::string::npos) << bad_number;
    EXPECT_NE(stream_error(dir, "b.obj", tri + "f 1 2 9\n").find("out of range"), std::string::npos);
    EXPECT_NE(stream_error(dir, "c.obj", tri + "f 0 1 2\n").find("index 0"), std::string::npos);
    EXPECT_NE(stream_error(dir, "d.obj", tri).find("no faces"), std::string::npos);
    EXPECT_NE(stream_error(dir, "e.obj", tri + "v nan 0 0\nf 1 2 3\n").find("non-finite"), std::string::npos);
    const std::string no_folder = stream_error(dir, "f.obj", tri + "f 1 2 3\n", dir + "/missing/folder");
    EXPECT_NE(no_folder.find("scratch file"), std::string::npos) << no_folder;
    EXPECT_NE(stream_error(dir, "missing.obj", "").find("no faces"), std::string::npos);
    for (const std::string& m : {bad_number, no_folder}) EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    // Blank lines at read-block boundaries still count (fuzz_obj_stream found them lost).
    std::ofstream(dir + "/g.obj") << tri << "\n\nf 1 2 x\n";
    for (size_t block : {size_t(1), size_t(3), size_t(25), size_t(4096)}) {
        StreamConvertOptions small_blocks;
        small_blocks.memory_budget = kMinStreamBudget;
        small_blocks.read_block_bytes = block;
        try {
            convert_obj_streaming(dir + "/g.obj", dir + "/out.rfpack", {}, small_blocks);
            ADD_FAILURE() << "no error";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("g.obj:6:"), std::string::npos) << e.what() << " block " << block;
        }
    }
    StreamConvertOptions tiny;
    tiny.memory_budget = size_t(8) << 20;
    EXPECT_THROW(convert_obj_streaming(dir + "/f.obj", dir + "/out.rfpack", {}, tiny), Error);
}

// A generated OBJ several times the budget's object size, converted by the
// CLI: the process's peak resident set stays under the budget.
TEST(ObjStreamConvert, CliConvertStaysWithinItsMemoryBudget) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    GTEST_SKIP() << "a sanitizer's shadow memory and quarantine make the resident set meaningless here";
#endif
    const std::string dir = test::temp_dir("obj_stream_cli");
    const test::CliResult generated =
        test::run_cli("generate terrain-statues --triangles 600K -o " + dir + "/big.obj -q");
    ASSERT_EQ(generated.exit_code, 0) << generated.err;
    const test::CliResult convert =
        test::run_cli("convert " + dir + "/big.obj -o " + dir + "/big.rfpack --memory-budget 96M -q");
    ASSERT_EQ(convert.exit_code, 0) << convert.err;
    const size_t at = convert.out.find("peak resident ");
    ASSERT_NE(at, std::string::npos) << convert.out;
    double value = 0;
    char unit[8] = {};
    ASSERT_EQ(std::sscanf(convert.out.c_str() + at, "peak resident %lf %7s", &value, unit), 2) << convert.out;
    const double mib = std::string(unit) == "GiB" ? value * 1024 : std::string(unit) == "MiB" ? value : value / 1024;
    EXPECT_LT(mib, 96.0) << convert.out;
    EXPECT_NE(convert.out.find("objects of at most"), std::string::npos);
    const test::CliResult small_budget =
        test::run_cli("convert " + dir + "/big.obj -o " + dir + "/x.rfpack --memory-budget 10M -q");
    EXPECT_EQ(small_budget.exit_code, 1);
    EXPECT_EQ(test::lines_of(small_budget.err).size(), 1u) << small_budget.err;
    const test::CliResult render = test::run_cli("render " + dir + "/big.rfpack -o " + dir + "/big.png --res 32x24 -q");
    EXPECT_EQ(render.exit_code, 0) << render.err;
}

}  // namespace
}  // namespace rf
