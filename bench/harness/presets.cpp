#include "presets.h"

#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

std::vector<Preset> make_presets() {
    std::vector<Preset> all;
    {
        Preset p;
        p.name = "bogolepov";
        p.description = "uniform grid vs proximity-cloud grid at 32^3/64^3/128^3, direct only (P+S) and with "
                        "secondary rays (P+S+R); the paper's Lexus (~325k triangles, 512x512) is replaced by "
                        "scenes of similar size";
        p.scenes = {"conference", "sponza"};
        p.fallback_scenes = {"builtin:instances"};
        p.resolutions = {{512, 512}};
        p.ray_sets = {RaySetKind::Primary, RaySetKind::Shadow, RaySetKind::Reflection};
        for (const char* res : {"32", "64", "128"}) {
            p.candidates.push_back(std::string("grid/uniform-") + res + "/grid");
            p.candidates.push_back(std::string("grid-proximity/uniform-") + res + "/grid");
        }
        p.candidates.push_back("bvh/binned/bvh2");  // the reference every table is anchored to
        p.gpu_kernels = {GpuKernel::Grid, GpuKernel::ProximityGrid, GpuKernel::AilaLaine, GpuKernel::Cwbvh};
        p.configuration_table = true;
        p.notes = {"Bogolepov et al. report frames per second as direct / direct+secondary; here: P+S and P+S+R "
                   "trace ms"};
        all.push_back(p);
    }
    {
        Preset p;
        p.name = "zlatuska2009";
        p.description = "grid vs kd-tree vs BVH for P, PS, PSR at 256^2, 512^2, 1024^2 with steps and tests per "
                        "ray, build times and memory";
        p.scenes = {"bunny", "dragon", "buddha-res3", "conference", "bart-robots", "bart-museum", "bart-kitchen"};
        p.fallback_scenes = {"builtin:sphereflake", "builtin:terrain", "builtin:instances"};
        p.resolutions = {{256, 256}, {512, 512}, {1024, 1024}};
        p.ray_sets = {RaySetKind::Primary, RaySetKind::Shadow, RaySetKind::Reflection};
        p.candidates = {"grid/uniform-auto/grid", "kdtree/sah/short-stack", "kdtree/sah/restart",
                        "kdtree/sah/pushdown", "bvh/binned/bvh2"};
        p.gpu_kernels = {GpuKernel::Grid, GpuKernel::KdShortStack, GpuKernel::KdRestart, GpuKernel::AilaLaine,
                         GpuKernel::Cwbvh};
        p.configuration_table = true;
        p.notes = {"PSR here traces one reflection bounce per primary hit (the thesis allows up to 2)",
                   "single-object scenes use a fixed camera and light, not the thesis's 400-frame orbits",
                   "the thesis's Theatre and Office scenes are not in ../shared/scenes"};
        all.push_back(p);
    }
    {
        Preset p;
        p.name = "garanzha2014";
        p.description = "BVH builders: build time, SAH and formula-4.2 quality, trace speed on primary and "
                        "diffuse rays (dissertation tables 4.1, 4.2, 5.1, 5.2)";
        p.scenes = {"conference", "dragon", "sponza"};
        p.fallback_scenes = {"builtin:sphereflake", "builtin:terrain", "builtin:instances"};
        p.resolutions = {{1024, 768}};
        p.ray_sets = {RaySetKind::Primary, RaySetKind::Diffuse};
        p.candidates = {"bvh/binned/bvh2", "bvh/sweep/bvh2",  "bvh/sbvh/bvh2",         "bvh/lbvh30/bvh2",
                        "bvh/hlbvh2/bvh2", "bvh/gridbvh/bvh2", "bvh/gridbvh-split/bvh2", "bvh/ploc/bvh2",
                        "bvh/hploc/bvh2"};
        p.gpu_kernels = {GpuKernel::AilaLaine, GpuKernel::Cwbvh};
        p.stage_breakdown = true;
        p.notes = {"the dissertation's builds ran on a GTX 480; these are CPU builds on this machine",
                   "Fairy Forest, Turbine Blade and Power Plant are not in ../shared/scenes"};
        all.push_back(p);
    }
    return all;
}

}  // namespace

const std::vector<Preset>& presets() {
    static const std::vector<Preset> all = make_presets();
    return all;
}

const Preset& find_preset(const std::string& name) {
    std::string known;
    for (const Preset& p : presets()) {
        if (p.name == name) return p;
        known += (known.empty() ? "" : ", ") + p.name;
    }
    throw Error("unknown preset '" + name + "' (known: " + known + ")");
}

}  // namespace rf::bench
