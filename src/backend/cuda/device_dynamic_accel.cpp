// Dynamic structures on a CUDA device (the seam's cuda::build_dynamic_accel):
// what rf::build_dynamic_accel makes for --device cuda. Each is a CudaAccel
// kept current frame by frame; the CUDA renderer binds to it (current()).
//   rebuild    the device builder (BuildOptions::builder, e.g. hlbvh2) from
//              scratch every frame, laid out for the kernel there;
//   refit      the tree built once, its canonical nodes kept on the device
//              and refitted there every frame (bvh_refit.cu, one thread per
//              leaf climbing with arrival counters); the bvh2 kernel traces
//              the refitted nodes in place, node pairs and CWBVH are
//              converted again from them (DeviceTracer::refit);
//   two-level  the host's two-level structure (accel/update/two_level_accel.cpp:
//              bottom levels refitted where a mesh deformed, the top level
//              rebuilt over the instances' world boxes) copied each frame, the
//              changed meshes and the top level only, and traced on the device
//              through the instances' inverse transforms (two_level_trace.cu).
// adapt and clusters restructure the tree on the host; they are CPU-only.
#include <chrono>
#include <limits>
#include <utility>

#include "accel/update/two_level_accel.h"
#include "backend/backends.h"
#include "backend/cuda/cuda_accel.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Queries, stats and the renderer's binding go to the CudaAccel a method keeps current.
class DeviceDynamicAccel : public DynamicAccel {
public:
    [[nodiscard]] double initial_build_ms() const override { return initial_build_ms_; }
    [[nodiscard]] const Accel& current() const override { return *accel_; }
    [[nodiscard]] Hit intersect(const Ray& ray) const override { return accel_->intersect(ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const override { return accel_->occluded(ray); }
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override { accel_->intersect(rays, hits); }
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
        accel_->occluded(rays, occluded);
    }
    [[nodiscard]] AccelStats stats() const override { return accel_->stats(); }
    [[nodiscard]] Device device() const override { return accel_->device(); }
    [[nodiscard]] BuildReport build_report() const override { return accel_->build_report(); }
    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override {
        return accel_->count_traversal(rays, any_hit, totals);
    }
    std::vector<double> time_traversal(std::span<const Ray> rays, bool any_hit, int runs, std::span<Hit> hits,
                                       std::span<uint8_t> occluded) const override {
        return accel_->time_traversal(rays, any_hit, runs, hits, occluded);
    }

protected:
    std::unique_ptr<CudaAccel> accel_;
    double initial_build_ms_ = 0.0;
};

class DeviceRebuildAccel final : public DeviceDynamicAccel {
public:
    DeviceRebuildAccel(const SceneGeometry& geometry, const BuildOptions& build) : geometry_(geometry), build_(build) {
        const auto start = Clock::now();
        accel_ = std::make_unique<CudaAccel>(geometry_, build_);
        initial_build_ms_ = ms_since(start);
    }
    UpdateStats update(const GeometryChange& change) override {
        UpdateStats stats;
        if (change.geometry()) {  // else nothing moved: nothing to do
            const auto start = Clock::now();
            accel_.reset();  // the old tree's device memory goes before the new one is built
            accel_ = std::make_unique<CudaAccel>(geometry_, build_);
            stats.update_ms = ms_since(start);
        }
        stats.layout_ms = accel_->stats().layout_ms;
        stats.sah_cost = accel_->stats().sah_cost;
        return stats;
    }
    [[nodiscard]] UpdateMethod method() const override { return UpdateMethod::Rebuild; }

private:
    const SceneGeometry& geometry_;
    BuildOptions build_;
};

class DeviceRefitAccel final : public DeviceDynamicAccel {
public:
    DeviceRefitAccel(const SceneGeometry& geometry, const BuildOptions& build) : geometry_(geometry) {
        const auto start = Clock::now();
        accel_ = std::make_unique<CudaAccel>(geometry_, build, Refittable::Yes);
        initial_build_ms_ = ms_since(start);
        AccelStats s = accel_->stats();
        s.name = "refit/" + s.name;
        accel_->tracer().set_stats(s);
    }
    // The refitted tree's SAH cost is not computed: its nodes stay on the device.
    UpdateStats update(const GeometryChange& change) override {
        UpdateStats stats;
        stats.sah_cost = std::numeric_limits<double>::quiet_NaN();
        if (!change.geometry()) return stats;
        const auto start = Clock::now();
        (void)accel_->tracer().refit(geometry_.triangles);
        stats.update_ms = ms_since(start);
        AccelStats s = accel_->stats();
        stats.layout_ms = s.layout_ms;
        s.build_ms = stats.update_ms;
        s.sah_cost = s.quality_cost = std::numeric_limits<double>::quiet_NaN();
        accel_->tracer().set_stats(s);
        return stats;
    }
    [[nodiscard]] UpdateMethod method() const override { return UpdateMethod::Refit; }

private:
    const SceneGeometry& geometry_;
};

class DeviceTwoLevelAccel final : public DeviceDynamicAccel {
public:
    DeviceTwoLevelAccel(const Scene& scene, const SceneGeometry& geometry, const BuildOptions& build) {
        const auto start = Clock::now();
        host_ = make_two_level_host(scene, geometry, build);
        auto device = std::make_unique<DeviceTwoLevel>(build.device.index, host_->mesh_count());
        for (uint32_t m = 0; m < host_->mesh_count(); ++m) {
            if (!host_->blas(m).nodes.empty()) device->set_mesh(m, host_->blas(m), host_->blas_triangles(m));
        }
        device->set_top(host_->top(), host_->instances());
        accel_ = std::make_unique<CudaAccel>(std::move(device), named_stats(0.0));
        initial_build_ms_ = ms_since(start);
        accel_->tracer().set_stats(named_stats(initial_build_ms_));
    }
    UpdateStats update(const GeometryChange& change) override {
        const auto start = Clock::now();
        UpdateStats stats = host_->update(change);
        DeviceTwoLevel& device = *accel_->tracer().two_level();
        for (uint32_t m : host_->updated_meshes()) device.set_mesh(m, host_->blas(m), host_->blas_triangles(m));
        device.set_top(host_->top(), host_->instances());
        stats.update_ms = ms_since(start);
        accel_->tracer().set_stats(named_stats(stats.update_ms));
        return stats;
    }
    [[nodiscard]] UpdateMethod method() const override { return UpdateMethod::TwoLevel; }

private:
    [[nodiscard]] AccelStats named_stats(double build_ms) const {
        AccelStats s = host_->stats();
        s.name = "cuda/" + s.name;
        s.build_ms = build_ms;
        s.device_bytes = accel_ ? accel_->tracer().two_level()->bytes() : 0;
        return s;
    }
    std::unique_ptr<TwoLevelHost> host_;
};

}  // namespace

std::unique_ptr<DynamicAccel> build_dynamic_accel(const Scene& scene, const SceneGeometry& geometry,
                                                  const BuildOptions& build, const UpdateOptions& update) {
    require_device(build.device.index);
    const UpdateMethod method = update.method.value_or(kDefaultUpdateMethod);
    switch (method) {
        case UpdateMethod::Rebuild: return std::make_unique<DeviceRebuildAccel>(geometry, build);
        case UpdateMethod::Refit: return std::make_unique<DeviceRefitAccel>(geometry, build);
        case UpdateMethod::TwoLevel: return std::make_unique<DeviceTwoLevelAccel>(scene, geometry, build);
        case UpdateMethod::Adapt:
        case UpdateMethod::Clusters: break;
    }
    throw Error("dynamic accel: update method " + to_string(method) +
                " runs on the CPU only; on a CUDA device use refit, rebuild or two-level");
}

}  // namespace rf::cuda
