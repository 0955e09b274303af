// The integrators and their choices, as enums that both backends' per-sample
// code takes directly (no header here needs more than <cstdint> and
// <string>, so CUDA device code includes it as it is).
#pragma once

#include <cstdint>
#include <string>

namespace rf {

enum class IntegratorKind : uint8_t { Normals, AmbientOcclusion, Whitted, Path };

// How the path tracer estimates direct light: both strategies combined by
// multiple importance sampling (the default), next-event estimation only, or
// BSDF sampling only (emitters found by chance). All three converge to the same image.
enum class LightSampling : uint8_t { Mis, Nee, Bsdf };

// Whitted's local shading: Lambert, or Phong / Blinn-Phong highlights.
enum class WhittedShading : uint8_t { Lambert, Phong, Blinn };

// Names for the CLI and scene files; parse_* throw rf::Error when unknown.
IntegratorKind parse_integrator(const std::string& name);  // normals | ao | whitted | path
std::string integrator_name(IntegratorKind kind);
LightSampling parse_light_sampling(const std::string& name);  // mis | nee | bsdf
std::string to_string(LightSampling sampling);
WhittedShading parse_whitted_shading(const std::string& name);  // lambert | phong | blinn
std::string to_string(WhittedShading shading);

}  // namespace rf
