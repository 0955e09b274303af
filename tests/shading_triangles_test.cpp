// The packed per-triangle shading records against rf::surface_at, which
// interpolates the same attributes from the meshes.
#include <gtest/gtest.h>

#include <cmath>

#include "rayforge/io/scene_io.h"
#include "math/random.h"
#include "render/shading_triangles.h"

namespace rf {
namespace {

TEST(ShadingTriangles, OctahedralEncodingIsAccurateEverywhere) {
    RandomStream rng(1, 2, 3);
    float worst = 0.0f;
    for (int i = 0; i < 100000; ++i) {
        Vec3f n(rng.next() * 2 - 1, rng.next() * 2 - 1, rng.next() * 2 - 1);
        if (length(n) < 1e-3f) continue;
        n = normalize(n);
        Vec3f back = decode_octahedral(encode_octahedral(n));
        worst = std::fmax(worst, length(back - n));
    }
    EXPECT_LT(worst, 1e-4f);  // about 0.006 degrees
    for (Vec3f axis : {Vec3f(1, 0, 0), Vec3f(0, -1, 0), Vec3f(0, 0, 1), Vec3f(0, 0, -1)})
        EXPECT_LT(length(decode_octahedral(encode_octahedral(axis)) - axis), 1e-4f);
}

TEST(ShadingTriangles, AgreeWithSurfaceAt) {
    // Smooth normals and uvs (the furnace sphere), instanced copies with
    // rotations and non-uniform scales (builtin:instances), and a normal map.
    for (const char* name : {"builtin:furnace", "builtin:instances", "builtin:material-spheres"}) {
        Scene scene = load_scene(name);
        if (std::string(name) == "builtin:material-spheres") {
            Texture flat;
            flat.width = flat.height = 1;
            flat.channels = 3;
            flat.encoding = TextureEncoding::Linear8;
            flat.texels8 = {128, 128, 255};
            scene.textures.push_back(flat);
            for (Material& m : scene.materials) m.normal_texture = int32_t(scene.textures.size() - 1);
        }
        SceneGeometry geometry = SceneGeometry::build(scene);
        std::vector<ShadingTriangle> records = build_shading_triangles(scene, geometry);
        ASSERT_EQ(records.size(), geometry.size());
        RandomStream rng(7, 0, 0);
        for (int i = 0; i < 2000; ++i) {
            Hit hit;
            hit.prim = uint32_t(rng.next() * float(geometry.size())) % uint32_t(geometry.size());
            if (!(geometry.triangles[hit.prim].area() > 0.0f)) continue;
            hit.u = rng.next();
            hit.v = rng.next() * (1.0f - hit.u);
            hit.t = 2.0f;
            Ray ray;
            ray.org = Vec3f(0.1f, 0.2f, 0.3f);
            ray.dir = (geometry.triangles[hit.prim].centroid() - ray.org) * 0.5f;
            SurfaceHit expected = surface_at(scene, geometry, ray, hit);
            SurfaceHit actual = shading_surface(records[hit.prim], ray, hit);
            EXPECT_EQ(actual.material, expected.material);
            EXPECT_LT(length(actual.position - expected.position), 1e-5f);
            EXPECT_LT(length(actual.geometric_normal - expected.geometric_normal), 1e-5f);
            EXPECT_LT(length(actual.shading_normal - expected.shading_normal), 2e-3f) << name << " prim " << hit.prim;
            EXPECT_LT(std::fabs(actual.uv.x - expected.uv.x) + std::fabs(actual.uv.y - expected.uv.y), 1e-5f);
            EXPECT_NEAR(actual.uv_area_ratio, expected.uv_area_ratio, 1e-4f * expected.uv_area_ratio + 1e-9f);
            EXPECT_EQ(actual.tangent_sign, expected.tangent_sign) << name;
            if (expected.tangent_sign != 0.0f) EXPECT_LT(length(actual.tangent - expected.tangent), 1e-3f);
        }
    }
}

}  // namespace
}  // namespace rf
