// Small scenes built in code for the renderer tests: quads, boxes and
// spheres with chosen materials, and the options and cameras to view them.
#pragma once

#include <cmath>
#include <memory>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "rayforge/world.h"

namespace rf {

inline constexpr float kPiF = 3.14159265358979f;

// A scene under construction (scene) and, once finished, the world made of
// a copy of it, which renders and answers queries.
struct TestScene {
    Scene scene;
    std::unique_ptr<World> world;

    uint32_t add_material(const Material& m) {
        scene.materials.push_back(m);
        return uint32_t(scene.materials.size() - 1);
    }
    // A rectangle centred at c spanning c +- u +- v; its normal is along cross(u, v).
    void add_quad(Vec3f c, Vec3f u, Vec3f v, uint32_t material) {
        Mesh mesh;
        mesh.name = "quad" + std::to_string(scene.meshes.size());
        mesh.positions = {c - u - v, c + u - v, c + u + v, c - u + v};
        mesh.indices = {0, 1, 2, 0, 2, 3};
        mesh.material_ids = {material, material};
        scene.meshes.push_back(mesh);
    }
    // An axis-aligned box of half size h around c, normals pointing outwards.
    void add_box(Vec3f c, float h, uint32_t material) {
        Vec3f x(h, 0, 0), y(0, h, 0), z(0, 0, h);
        add_quad(c + z, x, y, material);
        add_quad(c - z, y, x, material);
        add_quad(c + x, y, z, material);
        add_quad(c - x, z, y, material);
        add_quad(c + y, z, x, material);
        add_quad(c - y, x, z, material);
    }
    // A UV sphere with smooth vertex normals pointing outwards.
    void add_sphere(Vec3f c, float r, uint32_t material, int segments = 48) {
        Mesh mesh;
        mesh.name = "sphere" + std::to_string(scene.meshes.size());
        const int rings = segments / 2;
        for (int i = 0; i <= rings; ++i) {
            float theta = kPiF * float(i) / float(rings);
            for (int j = 0; j <= segments; ++j) {
                float phi = 2.0f * kPiF * float(j) / float(segments);
                Vec3f n(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
                mesh.positions.push_back(c + n * r);
                mesh.normals.push_back(n);
            }
        }
        const uint32_t row = uint32_t(segments + 1);
        for (int i = 0; i < rings; ++i) {
            for (int j = 0; j < segments; ++j) {
                uint32_t a = uint32_t(i) * row + uint32_t(j), b = a + row;
                if (i > 0) mesh.indices.insert(mesh.indices.end(), {a, a + 1, b});
                if (i + 1 < rings) mesh.indices.insert(mesh.indices.end(), {a + 1, b + 1, b});
            }
        }
        mesh.material_ids.assign(mesh.indices.size() / 3, material);
        scene.meshes.push_back(mesh);
    }
    void finish(Structure structure = Structure::BruteForce) {
        scene.finalize();
        WorldOptions options;
        options.build.structure = structure;
        world = make_world(scene, options);
    }
    [[nodiscard]] const SceneGeometry& geometry() const { return world->geometry(); }
    [[nodiscard]] const Accel& accel() const { return world->accel(); }
    Image render_with(const Camera& camera, const RenderOptions& options) const {
        return render(*world, camera, options);
    }
};

inline Material diffuse(Vec3f albedo) {
    Material m;
    m.base_color = albedo;
    return m;
}

inline Material emitter(Vec3f radiance) {
    Material m;
    m.base_color = Vec3f(0.0f);
    m.emission = radiance;
    return m;
}

// A polished metal quad at z = 0 facing +z, tinted `tint`, and behind a
// camera on the +z axis an emitting quad of radiance `sky` facing it: the
// mirror must show sky * tint. Finishes the scene.
inline void add_mirror_facing_sky(TestScene& t, Vec3f tint, Vec3f sky) {
    Material mirror;
    mirror.base_color = tint;
    mirror.metallic = 1.0f;
    mirror.roughness = 0.0f;
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(mirror));
    t.add_quad({0, 0, 10}, {0, 20, 0}, {20, 0, 0}, t.add_material(emitter(sky)));  // faces -z
    t.finish();
}

inline Camera looking_at(Vec3f eye, Vec3f target, float fov = 40.0f) {
    Camera c;
    c.eye = eye;
    c.target = target;
    c.up = std::fabs(target.x - eye.x) + std::fabs(target.z - eye.z) < 1e-6f ? Vec3f(0, 0, -1) : Vec3f(0, 1, 0);
    c.vfov_degrees = fov;
    return c;
}

inline RenderOptions options_for(IntegratorKind kind, int w = 9, int h = 9) {
    RenderOptions o;
    o.width = w;
    o.height = h;
    o.integrator = kind;
    return o;
}

}  // namespace rf
