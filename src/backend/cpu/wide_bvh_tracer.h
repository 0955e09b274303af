// The tracer of the 4- and 8-wide BVHs (CPU only: SIMD), the counterpart of
// trace/tracers.h's structs with one addition: batches trace runs of eight
// consecutive rays that share an octant as packets
// (wide_bvh_packet_traversal.h) and every other ray singly, which
// accel/view_accel.h picks up through intersect_batch / occluded_batch.
#pragma once

#include <cstdint>
#include <span>

#include "backend/cpu/ray_batches.h"
#include "backend/cpu/wide_bvh_packet_traversal.h"
#include "backend/cpu/wide_bvh_traversal.h"
#include "trace/tracers.h"

namespace rf {

template <int N>
struct WideBvhTracer {
    WideBvhView<N> bvh;

    [[nodiscard]] Hit intersect(const Ray& ray) const { return wide_bvh_intersect(bvh, ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const { return wide_bvh_occluded(bvh, ray); }
    Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c, [&](TraversalCounters& t) { return wide_bvh_intersect_counted(bvh, ray, t); },
            [&](TraversalCounters& t) { return wide_bvh_occluded_counted(bvh, ray, t); });
    }

    // hits[lo, hi) of rays[lo, hi): packets where eight rays fit one (rays_fit_packet).
    void intersect_batch(const Ray* rays, Hit* hits, size_t lo, size_t hi) const {
        size_t i = lo;
        for (; i + kRayPacketSize <= hi; i += kRayPacketSize) {
            if (rays_fit_packet(&rays[i])) {
                wide_bvh_intersect_packet(bvh, &rays[i], &hits[i]);
            } else {
                for (size_t k = i; k < i + kRayPacketSize; ++k) hits[k] = wide_bvh_intersect(bvh, rays[k]);
            }
        }
        for (; i != hi; ++i) hits[i] = wide_bvh_intersect(bvh, rays[i]);
    }
    void occluded_batch(const Ray* rays, uint8_t* occluded, size_t lo, size_t hi) const {
        size_t i = lo;
        for (; i + kRayPacketSize <= hi; i += kRayPacketSize) {
            if (rays_fit_packet(&rays[i])) {
                wide_bvh_occluded_packet(bvh, &rays[i], &occluded[i]);
            } else {
                for (size_t k = i; k < i + kRayPacketSize; ++k) occluded[k] = wide_bvh_occluded(bvh, rays[k]) ? 1 : 0;
            }
        }
        for (; i != hi; ++i) occluded[i] = wide_bvh_occluded(bvh, rays[i]) ? 1 : 0;
    }
};

}  // namespace rf
