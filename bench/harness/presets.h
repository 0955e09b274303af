// Named configurations that reproduce the three papers' tables with
// whatever rayforge implements so far (../shared/docs/seeds/):
//  bogolepov: uniform grid vs proximity grid at 32^3, 64^3, 128^3, direct only
//             (primary + shadow) and with secondary (reflection) rays;
//  zlatuska2009 (Zlatuška 2009): grid vs kd-tree vs BVH for P, PS, PSR at
//             256^2 .. 1024^2, with steps and primitive tests per ray
//             (tables 5.9-5.11) and build time and memory (tables 5.3-5.6);
//  garanzha2014 (Garanzha 2014): BVH builders' build time and quality
//             (formula 4.2) on the dissertation's scenes (tables 4.1, 5.1).
// With `--device cuda` each preset's structures are also traced by the GPU
// kernels of the same structures (grid -> grid, grid-proximity ->
// grid-proximity, kdtree -> kd-short-stack and kd-restart, bvh -> aila-laine
// and cwbvh), built exactly as the preset's CPU candidates.
#pragma once

#include <string>
#include <vector>

#include "bench_runner.h"
#include "rayforge/backend/device.h"

namespace rf::bench {

struct Preset {
    std::string name;
    std::string description;
    std::vector<std::string> scenes;          // views.json names (used when views.json is found)
    std::vector<std::string> fallback_scenes; // builtin scenes otherwise
    std::vector<Resolution> resolutions;
    std::vector<RaySetKind> ray_sets;
    std::vector<std::string> candidates;      // labels, implemented or not
    std::vector<GpuKernel> gpu_kernels;       // the kernels of `--device cuda`, for the candidates' structures
    bool configuration_table = false;         // print P / PS / PSR sums
    bool stage_breakdown = false;             // print GridBvh / HLBVH2 build stages per scene
    std::vector<std::string> notes;           // printed and stored in the JSON
};

const std::vector<Preset>& presets();
const Preset& find_preset(const std::string& name);  // throws rf::Error for unknown names

}  // namespace rf::bench
