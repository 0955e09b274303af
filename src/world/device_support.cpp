#include "world/device_support.h"

#include "accel/device_structure.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

// The device of a world is WorldOptions::device; a device also named in
// BuildOptions would be a second, silently ignored, answer.
void check_single_device(const WorldOptions& options) {
    if (options.build.device != Device{} && options.build.device != options.device)
        throw Error("world options: the device is WorldOptions::device (" + to_string(options.device) +
                    "), not WorldOptions::build.device (" + to_string(options.build.device) + ")");
}

// Why the world cannot run `method` as asked ("" when it can): CPU-only
// methods on a CUDA device, any method but rebuild for a structure that is
// not a BVH.
std::string unserved_method(UpdateMethod method, const BuildOptions& build) {
    if (build.device.is_cuda() && !update_runs_on_device(method))
        return to_string(method) + " runs on the CPU only (on " + to_string(build.device) +
               ": refit, rebuild or two-level)";
    if (build.structure != Structure::Bvh && method != UpdateMethod::Rebuild)
        return to_string(method) + " updates BVHs, and a " + to_string(build.structure) + " is rebuilt every frame";
    return "";
}

}  // namespace

bool renders_paged_scenes(const Device& device) { return !device.is_cuda(); }

WorldPlan plan_world(const WorldOptions& options, WorldKind kind, const std::optional<std::string>& scene_update) {
    if (kind == WorldKind::Paged && !renders_paged_scenes(options.device))
        throw Error("paged scenes render on the CPU in this version (device cpu, not " + to_string(options.device) +
                    ")");
    check_single_device(options);
    WorldPlan plan;
    plan.build = options.build;
    plan.build.device = options.device;
    plan.build = with_device_structure(plan.build);
    validate_build_options(plan.build);
    validate_update_options(options.update);
    plan.update = options.update;
    if (options.update.method) {  // asked for: refused when it cannot be served
        const std::string why = unserved_method(*options.update.method, plan.build);
        if (!why.empty()) throw Error("update method " + why);
    } else if (kind == WorldKind::Animated && scene_update) {  // the scene's own: replaced, with a note
        const UpdateMethod from_file = parse_update_method(*scene_update);
        const std::string why = unserved_method(from_file, plan.build);
        plan.update.method = why.empty() ? from_file : kDefaultUpdateMethod;
        if (!why.empty())
            plan.notes.push_back("the scene's update method " + why + "; " + to_string(kDefaultUpdateMethod) +
                                 " instead");
    }
    if (!plan.update.method) plan.update.method = kDefaultUpdateMethod;
    // An animated BVH follows the motion by its method; a still one named a
    // method follows geometry_replaced by it (e.g. refit for moving vertices).
    const bool follows = kind == WorldKind::Animated || (kind == WorldKind::Still && options.update.method);
    plan.dynamic_bvh = follows && plan.build.structure == Structure::Bvh;
    return plan;
}

void check_world_options(const WorldOptions& options, const std::string& path_or_builtin) {
    const bool paged = !path_or_builtin.empty() && is_paged_scene_file(path_or_builtin);
    (void)plan_world(options, paged ? WorldKind::Paged : WorldKind::Still, std::nullopt);
    require_device(options.device);
}

}  // namespace rf
