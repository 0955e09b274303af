// The one in-memory scene representation shared by every loader and backend.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rayforge/math/affine.h"
#include "rayforge/scene/animation.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/light.h"
#include "rayforge/scene/material.h"
#include "rayforge/scene/mesh.h"
#include "rayforge/scene/texture.h"

namespace rf {

struct Instance {
    uint32_t mesh = 0;                        // index into Scene::meshes
    Affine3f transform = Affine3f::identity(); // object to world
    bool visible = true;                       // false: its triangles are kept, collapsed to one point
};

// Settings a scene file may carry; command-line options override them.
struct RenderSettings {
    std::optional<int> width, height, spp, max_depth, rr_depth, reflection_depth, refraction_depth;
    std::optional<std::string> integrator, light_sampling, shading;
    std::optional<float> ao_radius;
    std::optional<std::string> update;  // animated scenes: refit | adapt | rebuild | clusters | two-level
};

struct Scene {
    std::string source;                // file path or builtin name it came from
    std::vector<Mesh> meshes;
    std::vector<Instance> instances;   // what is rendered: every mesh appears through instances
    std::vector<Material> materials;   // Mesh::material_ids index this; never empty after loading
    std::vector<Texture> textures;
    std::vector<Light> lights;
    Environment environment;
    std::optional<Camera> camera;      // from the file; default_camera() otherwise
    RenderSettings render_settings;
    Animation animation;               // empty for a still scene
    float time = 0.0f;                 // the time the instances, meshes and camera were last evaluated at

    [[nodiscard]] size_t triangle_count() const;  // over instances
    [[nodiscard]] size_t vertex_count() const;    // over instances
    [[nodiscard]] Box3f bounds() const;           // world space, over instances
    [[nodiscard]] size_t memory_bytes() const;    // meshes + textures
    // A camera looking at the whole scene from the +z side when the file has none.
    [[nodiscard]] Camera camera_or_default() const;
    // The camera camera_or_default() makes for a scene bounded by `bounds`.
    [[nodiscard]] static Camera framing(const Box3f& bounds);
    // Adds a default material when there is none, instances each mesh once when
    // there are no instances, and validates every mesh and index; throws rf::Error.
    void finalize();
    // Every mesh's material ids, and every texture index of the materials and
    // the environment, in range; throws rf::Error (finalize() calls it).
    void validate_materials() const;
    // Evaluates the animation at time t (seconds) in place: instance
    // transforms and visibility, deformed meshes' positions and normals, and
    // the camera when it is animated. Returns what moved since the last
    // evaluation (everything animated on the first call). A still scene
    // returns an empty change. Triangle counts and order never change.
    GeometryChange set_time(float t);
    [[nodiscard]] bool animated() const { return !animation.empty(); }
};

}  // namespace rf
