// The CUDA backend's public face. Available when rayforge was built with nvcc
// (target rayforge::rayforge_cuda); no CUDA header is needed to use it.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

struct DeviceInfo {
    int index = 0;
    std::string name;
    size_t total_memory = 0;
    int compute_major = 0, compute_minor = 0;
    int multiprocessors = 0;
};

// Devices the driver reports; empty (no error) when there is no driver or device.
std::vector<DeviceInfo> list_devices();
// Why list_devices() is empty, e.g. "no CUDA-capable device is detected"; "" when devices exist.
std::string device_unavailable_reason();

// Traces rays on the GPU against a canonical BVH through the same per-ray
// traversal code as the CPU backend. Throws rf::Error on any CUDA failure
// (with file, line and the CUDA error string; out-of-memory names the buffer).
class BvhTracer {
public:
    BvhTracer(const Bvh& bvh, std::span<const Triangle> triangles, int device = 0);
    ~BvhTracer();
    BvhTracer(const BvhTracer&) = delete;
    BvhTracer& operator=(const BvhTracer&) = delete;

    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    [[nodiscard]] size_t device_bytes() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace rf::cuda
