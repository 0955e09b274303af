// RenderOptions as text and as checked values: validate_render_options and
// the names of integrators, light sampling and Whitted shading. Apart from
// the renderers, so that whatever parses options (the CLI, the viewer and
// its fuzz target) needs no backend.
#include <cmath>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/render/render.h"
#include "render/integrators/whitted.h"

namespace rf {

namespace {

constexpr int kMaxImageSide = 65536;
constexpr size_t kMaxImageBytes = size_t(4) << 30;  // the float RGB film
constexpr int kMaxSpp = 1 << 20;
constexpr int kMaxAoSamples = 1 << 16;
constexpr int kMaxPathDepth = 1024;


}  // namespace

void validate_render_options(const RenderOptions& o) {
    auto in_range = [](int v, int lo, int hi) { return v >= lo && v <= hi; };
    if (!in_range(o.width, 1, kMaxImageSide) || !in_range(o.height, 1, kMaxImageSide))
        throw Error("render: image size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                    " is outside 1.." + std::to_string(kMaxImageSide));
    const int films = o.aovs ? 4 : 1;  // colour, and albedo, normal, depth
    size_t bytes = size_t(o.width) * size_t(o.height) * sizeof(Vec3f) * size_t(films);
    if (bytes > kMaxImageBytes)
        throw Error("render: a " + std::to_string(o.width) + "x" + std::to_string(o.height) + " film needs " +
                    std::to_string(bytes >> 20) + " MiB, more than the " +
                    std::to_string(kMaxImageBytes >> 20) + " MiB allowed");
    checked_array_bytes("render: " + std::to_string(o.width) + "x" + std::to_string(o.height) + " film",
                        size_t(o.width) * size_t(o.height) * size_t(films), sizeof(Vec3f));
    if (!in_range(o.spp, 1, kMaxSpp))
        throw Error("render: spp must be in 1.." + std::to_string(kMaxSpp) + ", got " + std::to_string(o.spp));
    if (o.threads < 0) throw Error("render: threads must be >= 0, got " + std::to_string(o.threads));
    if (!std::isfinite(o.time_budget_s) || o.time_budget_s < 0.0)
        throw Error("render: time budget must be finite and >= 0");
    if (!in_range(o.max_depth, 0, kMaxPathDepth))
        throw Error("render: max_depth must be in 0.." + std::to_string(kMaxPathDepth) + ", got " +
                    std::to_string(o.max_depth));
    if (!in_range(o.rr_depth, 0, kMaxPathDepth))
        throw Error("render: rr_depth must be in 0.." + std::to_string(kMaxPathDepth) + ", got " +
                    std::to_string(o.rr_depth));
    if (!in_range(o.reflection_depth, 0, kWhittedMaxDepth) || !in_range(o.refraction_depth, 0, kWhittedMaxDepth))
        throw Error("render: reflection and refraction depths must be in 0.." + std::to_string(kWhittedMaxDepth) +
                    ", got " + std::to_string(o.reflection_depth) + " and " + std::to_string(o.refraction_depth));
    if (!std::isfinite(o.max_sample_value) || o.max_sample_value < 0.0f)
        throw Error("render: max_sample_value must be finite and >= 0 (0 = no clamp)");
    if (!in_range(o.ao_samples, 1, kMaxAoSamples))
        throw Error("render: ao_samples must be in 1.." + std::to_string(kMaxAoSamples) + ", got " +
                    std::to_string(o.ao_samples));
    if (!std::isfinite(o.ao_radius) || o.ao_radius < 0.0f)
        throw Error("render: ao_radius must be finite and >= 0");
}

IntegratorKind parse_integrator(const std::string& name) {
    if (name == "normals") return IntegratorKind::Normals;
    if (name == "ao") return IntegratorKind::AmbientOcclusion;
    if (name == "whitted") return IntegratorKind::Whitted;
    if (name == "path") return IntegratorKind::Path;
    throw Error("unknown integrator '" + name + "' (expected normals, ao, whitted or path)");
}

std::string integrator_name(IntegratorKind kind) {
    switch (kind) {
        case IntegratorKind::Normals: return "normals";
        case IntegratorKind::AmbientOcclusion: return "ao";
        case IntegratorKind::Whitted: return "whitted";
        case IntegratorKind::Path: return "path";
    }
    return "unknown";
}

LightSampling parse_light_sampling(const std::string& name) {
    if (name == "mis") return LightSampling::Mis;
    if (name == "nee") return LightSampling::Nee;
    if (name == "bsdf") return LightSampling::Bsdf;
    throw Error("unknown light sampling '" + name + "' (expected mis, nee or bsdf)");
}

std::string to_string(LightSampling sampling) {
    switch (sampling) {
        case LightSampling::Mis: return "mis";
        case LightSampling::Nee: return "nee";
        case LightSampling::Bsdf: return "bsdf";
    }
    return "unknown";
}

WhittedShading parse_whitted_shading(const std::string& name) {
    if (name == "lambert") return WhittedShading::Lambert;
    if (name == "phong") return WhittedShading::Phong;
    if (name == "blinn") return WhittedShading::Blinn;
    throw Error("unknown whitted shading '" + name + "' (expected lambert, phong or blinn)");
}

std::string to_string(WhittedShading shading) {
    switch (shading) {
        case WhittedShading::Lambert: return "lambert";
        case WhittedShading::Phong: return "phong";
        case WhittedShading::Blinn: return "blinn";
    }
    return "unknown";
}

}  // namespace rf
