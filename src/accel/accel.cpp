// build_accel and build_bvh: dispatch by device; the batched queries every
// Accel inherits. (The options, their checks and names: build_options.cpp.)
#include "backend/cpu/ray_batches.h"
#include "rayforge/accel/accel.h"
#include "core/parallel.h"

#include <cmath>
#include <utility>

#include <chrono>

#include "accel/accel_factories.h"
#include "accel/brute_force.h"
#include "accel/device_structure.h"
#include "backend/backends.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/bvh_accel.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

constexpr size_t kMaxTriangles = 0x7FFFFFFF;

}  // namespace

std::unique_ptr<Accel> cpu::build_accel(const SceneGeometry& geometry, const BuildOptions& options,
                                        const ProgressCallback& progress) {
    // Node indices are 32-bit and a BVH over n triangles may need 2n - 1 nodes.
    if (geometry.triangles.size() > kMaxTriangles) {
        throw Error("build_accel: " + std::to_string(geometry.triangles.size()) +
                    " triangles exceed the limit of " + std::to_string(kMaxTriangles));
    }
    switch (options.structure) {
        case Structure::Bvh: {
            const auto start = std::chrono::steady_clock::now();
            // The tree is most of the work; the layout conversion is the rest.
            // Nobody asked: the builder's leaves count nothing.
            ProgressMeter meter(progress, double(geometry.triangles.size()), 0.0, 0.9);
            Bvh bvh = build_bvh_on_cpu(geometry.triangles, options, progress ? &meter : nullptr);  // on options.threads threads
            meter.finish();
            const double build_ms =
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
            std::string name = "bvh/" + to_string(options.builder) + (options.treelets.enabled ? "+treelets" : "") +
                               (options.reinsertion.enabled ? "+opt" : "") +
                               "/" + to_string(options.layout);
            if (options.layout == Layout::Bvh2)
                return std::make_unique<BvhAccel>(geometry, std::move(bvh), std::move(name), build_ms);
            return make_wide_bvh_accel(geometry, std::move(bvh), options, build_ms, std::move(name));
        }
        case Structure::Grid:
        case Structure::ProximityGrid: return make_grid_accel(geometry, options);
        case Structure::KdTree: return make_kdtree_accel(geometry, options);
        case Structure::BruteForce: return std::make_unique<BruteForceAccel>(geometry);
    }
    throw Error("build options: unknown structure");
}

std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& requested,
                                   const ProgressCallback& progress) {
    const BuildOptions options = with_device_structure(requested);
    validate_build_options(options);
    if (progress) progress(0.0);
    std::unique_ptr<Accel> accel = options.device.is_cuda() ? cuda::build_accel(geometry, options)
                                                            : cpu::build_accel(geometry, options, progress);
    if (progress) progress(1.0);
    return accel;
}

Bvh build_bvh(std::span<const Triangle> triangles, const BuildOptions& options, BuildReport* report) {
    validate_build_options(options);
    if (options.device.is_cuda()) return cuda::build_bvh(triangles, options, report);
    if (report) *report = BuildReport{};
    return parallel::with_threads(options.threads, [&] { return build_bvh_on_cpu(triangles, options); });
}

std::vector<double> Accel::time_traversal(std::span<const Ray> rays, bool any_hit, int runs, std::span<Hit> hits,
                                          std::span<uint8_t> occluded) const {
    const auto trace = [&] {
        if (any_hit) this->occluded(rays, occluded);
        else intersect(rays, hits);
    };
    trace();  // warm-up
    std::vector<double> times;
    for (int r = 0; r < runs; ++r) {
        const auto start = std::chrono::steady_clock::now();
        trace();
        times.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    }
    return times;
}

BuildReport Accel::build_report() const {
    BuildReport report;
    report.device = device();
    return report;
}

void Accel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    check_batch_sizes("Accel::intersect", rays.size(), hits.size());
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) hits[i] = intersect(rays[i]);
    });
}

bool Accel::count_traversal(std::span<const Ray>, bool, TraversalTotals&) const { return false; }

namespace {
[[noreturn]] void throw_not_on_a_device(const Accel& accel, const char* call) {
    throw Error(std::string(call) + ": " + accel.stats().name + " runs on the CPU; batches of device-resident rays "
                "need an accel on a CUDA device (use the span batches here)");
}
}  // namespace

void Accel::intersect_on_device(const Ray*, Hit*, size_t, void*) const {
    throw_not_on_a_device(*this, "Accel::intersect_on_device");
}

void Accel::occluded_on_device(const Ray*, uint8_t*, size_t, void*) const {
    throw_not_on_a_device(*this, "Accel::occluded_on_device");
}

void Accel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    check_batch_sizes("Accel::occluded", rays.size(), occluded.size());
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) occluded[i] = this->occluded(rays[i]) ? 1 : 0;
    });
}

}  // namespace rf
