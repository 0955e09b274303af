// CudaAccel (cuda_accel.h) and the seam's cuda::build_accel.
#include "backend/cuda/cuda_accel.h"

#include "backend/backends.h"
#include "rayforge/core/error.h"

namespace rf::cuda {

Hit CudaAccel::intersect(const Ray& ray) const {
    Hit hit;
    tracer_.intersect(std::span<const Ray>(&ray, 1), std::span<Hit>(&hit, 1));
    return hit;
}

bool CudaAccel::occluded(const Ray& ray) const {
    uint8_t flag = 0;
    tracer_.occluded(std::span<const Ray>(&ray, 1), std::span<uint8_t>(&flag, 1));
    return flag != 0;
}

std::vector<double> CudaAccel::time_traversal(std::span<const Ray> rays, bool any_hit, int runs, std::span<Hit> hits,
                                              std::span<uint8_t> occluded) const {
    if ((any_hit ? occluded.size() : hits.size()) != rays.size())
        throw Error("time_traversal: " + std::to_string(rays.size()) + " rays but a different number of result slots");
    tracer_.upload_rays(rays);
    (void)tracer_.trace_uploaded(any_hit);  // warm-up
    std::vector<double> times;
    for (int r = 0; r < runs; ++r) times.push_back(tracer_.trace_uploaded(any_hit).kernel_ms);
    if (any_hit) tracer_.download_occluded(occluded);
    else tracer_.download_hits(hits);
    return times;
}

std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& options) {
    return std::make_unique<CudaAccel>(geometry, options);
}

}  // namespace rf::cuda
