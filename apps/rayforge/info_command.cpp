// `rayforge info SCENE`: what a scene holds and what it costs in memory;
// `rayforge info --devices`: the CUDA devices this build can use.
#include <chrono>
#include <cstdio>
#include <string>

#include "commands.h"
#include "rayforge/backend/device.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cli {
namespace {

double mib(size_t bytes) { return double(bytes) / (1024.0 * 1024.0); }

// "13.0" from the driver's 13000.
std::string cuda_version(int version) {
    return std::to_string(version / 1000) + "." + std::to_string((version % 1000) / 10);
}

void print_devices() {
    const DeviceListing listing = list_cuda_devices();
    if (listing.devices.empty()) {
        std::printf("CUDA devices: none (%s)\n", listing.error.c_str());
        return;
    }
    std::printf("CUDA devices: %zu\n", listing.devices.size());
    if (!listing.error.empty()) std::printf("  (not listed: %s)\n", listing.error.c_str());
    for (const DeviceInfo& d : listing.devices) {
        std::printf("cuda:%d  %s\n", d.index, d.name.c_str());
        std::printf("  compute capability %d.%d, %d SMs at %d MHz\n", d.compute_major, d.compute_minor,
                    d.multiprocessors, d.clock_mhz);
        std::printf("  memory %.0f MiB total, %.0f MiB free; L2 %.1f MiB; %d-bit memory bus\n", mib(d.total_memory),
                    mib(d.free_memory), mib(d.l2_bytes), d.memory_bus_bits);
        std::printf("  driver %s, runtime %s\n", cuda_version(d.driver_version).c_str(),
                    cuda_version(d.runtime_version).c_str());
    }
}

std::string format_vec(Vec3f v) {
    char buf[96];
    std::snprintf(buf, sizeof(buf), "(%g, %g, %g)", double(v.x), double(v.y), double(v.z));
    return buf;
}

}  // namespace

CLI::App* add_info_command(CLI::App& app, InfoArgs& args) {
    CLI::App* cmd = app.add_subcommand("info", "Print the contents and memory footprint of a scene");
    cmd->add_option("scene", args.scene, "Scene file (.obj, .gltf, .glb, .ply, .json) or builtin:NAME");
    cmd->add_flag("-v,--verbose", args.verbose, "Also list every material and texture");
    cmd->add_option("--animation", args.animation,
                    "glTF scenes with several animations: the one to describe, by name or 0-based index "
                    "(default: the first)");
    cmd->add_flag("--devices", args.devices,
                  "List the CUDA devices (name, compute capability, SMs, clock, memory, L2, driver and runtime); "
                  "the scene is then optional");
    // The scene is required unless --devices is given: a usage error otherwise.
    cmd->callback([&args] {
        if (args.scene.empty() && !args.devices) throw CLI::RequiredError("scene (or --devices)");
    });
    return cmd;
}

int run_info(const InfoArgs& args) {
    if (args.devices) {
        print_devices();
        if (args.scene.empty()) return 0;
        std::printf("\n");
    }
    if (is_paged_scene_file(args.scene)) return run_paged_info(args.scene, args.verbose);
    const auto start = std::chrono::steady_clock::now();
    LoadOptions load;
    load.animation = args.animation;
    Scene scene = load_scene(args.scene, load);
    check_animation_option(args.animation, scene);
    const double load_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    SceneGeometry geometry = SceneGeometry::build(scene);

    std::printf("scene:      %s\n", args.scene.c_str());
    std::printf("triangles:  %zu\n", scene.triangle_count());
    std::printf("vertices:   %zu\n", scene.vertex_count());
    std::printf("meshes:     %zu\n", scene.meshes.size());
    std::printf("instances:  %zu\n", scene.instances.size());
    Box3f b = scene.bounds();
    if (b.is_empty()) std::printf("bounds:     empty\n");
    else std::printf("bounds:     %s - %s\n", format_vec(b.lo).c_str(), format_vec(b.hi).c_str());

    std::printf("materials:  %zu\n", scene.materials.size());
    if (args.verbose) {
        for (size_t i = 0; i < scene.materials.size(); ++i) {
            const Material& m = scene.materials[i];
            std::printf("  [%zu] %-24s base %s metallic %g roughness %g", i,
                        m.name.empty() ? "(unnamed)" : m.name.c_str(), format_vec(m.base_color).c_str(),
                        double(m.metallic), double(m.roughness));
            if (m.transmission > 0.0f) std::printf(" transmission %g ior %g", double(m.transmission), double(m.ior));
            if (m.is_emissive()) std::printf(" emission %s", format_vec(m.emitted_radiance()).c_str());
            if (m.base_color_texture >= 0) std::printf(" texture %d", m.base_color_texture);
            std::printf("\n");
        }
    }

    size_t texture_bytes = 0;
    for (const Texture& t : scene.textures) texture_bytes += t.memory_bytes();
    std::printf("textures:   %zu (%.2f MiB)\n", scene.textures.size(), mib(texture_bytes));
    if (args.verbose) {
        for (size_t i = 0; i < scene.textures.size(); ++i) {
            const Texture& t = scene.textures[i];
            std::printf("  [%zu] %dx%d x%d %s\n", i, t.width, t.height, t.channels, t.name.c_str());
        }
    }

    size_t by_type[3] = {0, 0, 0};
    for (const Light& l : scene.lights) ++by_type[size_t(l.type)];
    std::printf("lights:     %zu point, %zu spot, %zu directional; %zu emissive triangles\n",
                by_type[size_t(LightType::Point)], by_type[size_t(LightType::Spot)],
                by_type[size_t(LightType::Directional)], geometry.emissive_triangles.size());

    Camera camera = scene.camera_or_default();
    std::printf("camera:     eye %s target %s up %s fov %g%s\n", format_vec(camera.eye).c_str(),
                format_vec(camera.target).c_str(), format_vec(camera.up).c_str(), double(camera.vfov_degrees),
                scene.camera ? "" : " (default)");
    if (scene.animated()) {
        const Animation& a = scene.animation;
        std::printf("animation:  %g to %g s, %d frames at %g fps; %zu moving instances, %zu deformed meshes "
                    "(%zu vertex-keyframed, %zu morphed, %zu skinned)%s\n",
                    double(a.start), double(a.end), a.frame_count(), double(a.frames_per_second),
                    a.instances.size(), a.vertex_keyframes.size() + a.morphs.size() + a.skins.size(),
                    a.vertex_keyframes.size(), a.morphs.size(), a.skins.size(), a.camera ? ", camera path" : "");
        if (a.clips.size() > 1) {
            std::string names;
            for (size_t i = 0; i < a.clips.size(); ++i)
                names += (i ? ", " : "") + std::to_string(i) + " '" + a.clips[i] + "'";
            std::printf("clips:      playing '%s' of %zu: %s (choose with --animation)\n", a.clip.c_str(),
                        a.clips.size(), names.c_str());
        }
    }
    std::printf("memory:     %.2f MiB scene (meshes + textures), %.2f MiB flattened geometry\n",
                mib(scene.memory_bytes()), mib(geometry.memory_bytes()));
    std::printf("load time:  %.1f ms (parsing, texture decoding, validation)\n", load_ms);
    return 0;
}

}  // namespace rf::cli
