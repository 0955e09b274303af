// A procedural HDR sky as an equirectangular environment map ("builtin:sky"),
// so environment lighting and its importance sampling can be rendered and
// tested without external files. The model is a simple analytic one (not
// Preetham or Hosek-Wilkie): see procedural_sky.cpp.
#pragma once

#include "rayforge/io/scene_io.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/texture.h"

namespace rf {

// The sun disk's angular radius (the real sun's is 0.27 degrees; a larger disk
// keeps it several texels wide at 512 x 256).
inline constexpr float kSkySunAngularRadiusDegrees = 1.5f;
// Irradiance of the sun disk on a horizontal plane over that of the rest of the
// sky (luminance), as on a clear day.
inline constexpr float kSkySunToSkyIrradiance = 3.0f;

// The map's direction convention (+y up): u = 0.5 + atan2(d.x, -d.z) / (2 pi),
// v = acos(d.y) / pi, row 0 = straight up. Returns the unit direction of (u, v).
Vec3f equirect_direction(float u, float v);

// Towards the sun: elevation above the horizon, azimuth from -z (the map's
// centre column) turning towards +x.
Vec3f sky_sun_direction(float elevation_deg, float azimuth_deg);

// make_sky_texture itself is public (rayforge/io/scene_io.h).

}  // namespace rf
