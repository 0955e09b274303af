// The pieces of the module `rayforge._rayforge`, one function per file that
// adds its classes and functions, and the argument parsing they share.
#pragma once

#include <pybind11/pybind11.h>

#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/world.h"

namespace rf::py {

namespace pyb = pybind11;

void bind_camera(pyb::module_& m);             // world_bindings.cpp
void bind_world(pyb::module_& m);              // world_bindings.cpp
void bind_render(pyb::module_& m);             // render_bindings.cpp
void bind_raycasting_scene(pyb::module_& m);   // raycasting_scene.cpp

// An engine name parsed for argument `arg`: its rf::Error becomes a
// ValueError naming the argument.
template <class F>
auto parsed(const char* arg, F&& parse) {
    try {
        return parse();
    } catch (const Error& e) {
        throw pyb::value_error(std::string(arg) + ": " + e.what());
    }
}

// The world options of the keyword arguments every world-making call takes
// (device, structure, builder, layout, gpu_kernel, update, threads,
// memory_budget); names are the CLI's.
WorldOptions world_options(const std::string& device, const std::string& structure, const std::string& builder,
                           const std::string& layout, const std::optional<std::string>& gpu_kernel,
                           const std::optional<std::string>& update, int threads,
                           const std::optional<std::string>& memory_budget);

// Where per-hit outputs go (normals and triangle_ids may be null).
struct HitOutputs {
    float* t;                 // inf on a miss
    uint32_t* geometry_ids;   // the instance (paged: the file's instance); kInvalidId on a miss
    uint32_t* primitive_ids;  // the triangle of its mesh
    float* uvs;               // 2 per hit
    float* normals;           // 3 per hit: the unit geometric normal
    uint32_t* triangle_ids;   // the world's flat triangle index
};

// Fills `out` from the world's hits, in parallel (call without the GIL). A
// paged world's hits carry the paged triangle id (page * 8192 + slot) and
// no geometry in memory to map it back: their geometry ids are the file's
// instances (`paged_instances`, from PagedScene::intersect; kInvalidId for a
// world-space page), primitive ids kInvalidId and normals NaN (documented in
// docs/python.md).
void fill_hit_outputs(const World& world, std::span<const Hit> hits, const HitOutputs& out,
                      std::span<const uint32_t> paged_instances = {});

}  // namespace rf::py
