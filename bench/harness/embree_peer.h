// The CPU peer: Embree 3 (Debian's libembree-dev) building its own BVH over
// the same triangles and tracing the same ray arrays, in the same process.
// Without Embree at build time, embree_available() is false and building a
// peer throws.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::bench {

enum class EmbreeQuality : uint8_t { Low, Medium, High };  // RTC_BUILD_QUALITY_*

inline constexpr EmbreeQuality kAllEmbreeQualities[] = {EmbreeQuality::Low, EmbreeQuality::Medium,
                                                        EmbreeQuality::High};
inline const char* embree_quality_name(EmbreeQuality quality) {
    switch (quality) {
        case EmbreeQuality::Low: return "low";
        case EmbreeQuality::Medium: return "medium";
        case EmbreeQuality::High: return "high";
    }
    return "?";
}

bool embree_available();
std::string embree_version();  // "" without Embree

class EmbreePeer {
public:
    // Builds an Embree scene over `geometry` (one triangle mesh, primitive i =
    // geometry.triangles[i], so primitive ids compare directly with ours).
    // `threads` = 0 uses all cores. Throws rf::Error when Embree is missing or fails.
    EmbreePeer(const SceneGeometry& geometry, EmbreeQuality quality, int threads);
    ~EmbreePeer();
    EmbreePeer(const EmbreePeer&) = delete;
    EmbreePeer& operator=(const EmbreePeer&) = delete;

    // rtcIntersect1 / rtcOccluded1 per ray, parallel over rays like our batches.
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;

    [[nodiscard]] double build_ms() const { return build_ms_; }
    // Bytes Embree allocated for the built scene beyond the vertex and index
    // buffers (from its memory monitor); 0 when unknown.
    [[nodiscard]] size_t bytes() const { return bytes_; }

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    double build_ms_ = 0.0;
    size_t bytes_ = 0;
};

// The dynamic peer (`rayforge bench --animate`): one Embree scene over the
// frame's triangles, kept current each frame by refitting
// (RTC_BUILD_QUALITY_REFIT on the geometry of a LOW scene, Embree's
// dynamic-scene mode) or by a full rebuild at LOW or MEDIUM.
enum class EmbreeUpdate : uint8_t { Refit, Low, Medium };
inline constexpr EmbreeUpdate kAllEmbreeUpdates[] = {EmbreeUpdate::Refit, EmbreeUpdate::Low, EmbreeUpdate::Medium};
inline const char* embree_update_name(EmbreeUpdate update) {
    switch (update) {
        case EmbreeUpdate::Refit: return "refit";
        case EmbreeUpdate::Low: return "low";
        case EmbreeUpdate::Medium: return "medium";
    }
    return "?";
}

class EmbreeDynamicPeer {
public:
    // Builds the scene over `geometry` (primitive i = geometry.triangles[i]);
    // build_ms() times it as EmbreePeer does. Throws rf::Error when Embree is
    // missing or fails.
    EmbreeDynamicPeer(const SceneGeometry& geometry, EmbreeUpdate update, int threads);
    ~EmbreeDynamicPeer();
    EmbreeDynamicPeer(const EmbreeDynamicPeer&) = delete;
    EmbreeDynamicPeer& operator=(const EmbreeDynamicPeer&) = delete;

    // The frame's positions (same triangle count and order): copied into the
    // scene's vertex buffer (copy_ms()), then rtcUpdateGeometryBuffer,
    // rtcCommitGeometry and rtcCommitScene refit or rebuild it. Returns the
    // milliseconds of the commits (the refit or rebuild alone).
    double update(const SceneGeometry& geometry);
    [[nodiscard]] double copy_ms() const { return copy_ms_; }

    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    [[nodiscard]] double build_ms() const { return build_ms_; }
    [[nodiscard]] EmbreeUpdate mode() const { return update_; }

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    EmbreeUpdate update_ = EmbreeUpdate::Refit;
    double build_ms_ = 0.0;
    double copy_ms_ = 0.0;
};

}  // namespace rf::bench
