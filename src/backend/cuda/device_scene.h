// A scene's shading data on the device: every table of a SceneTables
// (materials, shading records, texture mip levels and their decode tables,
// light lists, emitter and environment sampling tables) copied once, and a
// SceneView whose pointers are the copies: the integrators read it exactly
// as they read the host's.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "backend/cuda/device_buffer.h"
#include "render/scene_view.h"

namespace rf::cuda {

class DeviceScene {
public:
    // Uploads to the current device; `host` is not kept.
    explicit DeviceScene(const SceneTables& host);

    [[nodiscard]] const SceneView& view() const { return view_; }
    [[nodiscard]] size_t device_bytes() const;

private:
    // Copies `count` elements to a new device buffer named `what`; null for none.
    template <class T>
    const T* copy(const T* host, size_t count, const std::string& what);
    // A texture view with its texels and decode table on the device.
    TextureView copy_texture(const TextureView& host, const std::string& what);

    std::vector<DeviceBuffer<unsigned char>> buffers_;
    std::vector<std::pair<const float*, const float*>> decode_tables_;  // host table -> device copy
    SceneView view_;
};

}  // namespace rf::cuda
