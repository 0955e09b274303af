// Umbrella header: the public C++ API of rayforge, everything a program
// needs to open a scene as a world on a device (rf::World, rf::Device: the
// CPU or a CUDA device), move it through time, trace rays, render
// progressively and write images; and the lower floors: structures built
// over flat triangles (rf::build_accel, rf::build_bvh) and paged files.
#pragma once

#include "rayforge/accel/accel.h"
#include "rayforge/accel/build_report.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/accel/mesh_queries.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/math/affine.h"
#include "rayforge/math/box.h"
#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"
#include "rayforge/render/image.h"
#include "rayforge/render/integrators.h"
#include "rayforge/render/render.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "rayforge/world.h"
