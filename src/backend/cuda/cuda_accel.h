// The CUDA backend's rf::Accel: a DeviceTracer (a structure and its
// traversal kernel on one device) behind the interface every structure
// answers through. Batches of host rays are copied to the device and the
// answers back; a single ray is a batch of one (correct, but a GPU is for
// batches); batches already in device memory are traced in place. The CUDA
// renderer takes its structure from here.
#pragma once

#include <memory>
#include <vector>

#include "backend/cuda/device_tracer.h"
#include "rayforge/accel/accel.h"

namespace rf::cuda {

class CudaAccel final : public Accel {
public:
    CudaAccel(const SceneGeometry& geometry, const BuildOptions& options, Refittable refittable = Refittable::No)
        : tracer_(geometry, options, refittable) {}
    // Over a two-level structure that its owner keeps current through tracer().two_level().
    CudaAccel(std::unique_ptr<DeviceTwoLevel> two_level, AccelStats stats) : tracer_(std::move(two_level), std::move(stats)) {}

    [[nodiscard]] Hit intersect(const Ray& ray) const override;
    [[nodiscard]] bool occluded(const Ray& ray) const override;
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override { tracer_.intersect(rays, hits); }
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
        tracer_.occluded(rays, occluded);
    }
    void intersect_on_device(const Ray* rays, Hit* hits, size_t count, void* stream) const override {
        tracer_.trace_on_device(rays, hits, nullptr, count, stream);
    }
    void occluded_on_device(const Ray* rays, uint8_t* occluded, size_t count, void* stream) const override {
        tracer_.trace_on_device(rays, nullptr, occluded, count, stream);
    }
    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override {
        tracer_.count_traversal(rays, any_hit, totals);
        return true;
    }
    std::vector<double> time_traversal(std::span<const Ray> rays, bool any_hit, int runs, std::span<Hit> hits,
                                       std::span<uint8_t> occluded) const override;
    [[nodiscard]] AccelStats stats() const override { return tracer_.stats(); }
    [[nodiscard]] Device device() const override { return {Device::Kind::Cuda, tracer_.device()}; }
    [[nodiscard]] BuildReport build_report() const override {
        return describe_device_build(tracer_.build_stages(), device());
    }

    [[nodiscard]] const DeviceTracer& tracer() const { return tracer_; }
    [[nodiscard]] DeviceTracer& tracer() { return tracer_; }

private:
    // time_traversal's resident-ray buffers are scratch space a const query
    // may reuse (the bench runs it alone); the batches have their own scratch.
    mutable DeviceTracer tracer_;
};

}  // namespace rf::cuda
