// Embree 3 adapter of the bench (compiled only when find_package(embree 3) succeeds).
#include "embree_peer.h"

#include <embree3/rtcore.h>

#include <atomic>
#include <chrono>
#include <string>

#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

constexpr size_t kRayGrainSize = 256;  // as in our own batched queries

RTCBuildQuality to_rtc(EmbreeQuality quality) {
    switch (quality) {
        case EmbreeQuality::Low: return RTC_BUILD_QUALITY_LOW;
        case EmbreeQuality::Medium: return RTC_BUILD_QUALITY_MEDIUM;
        case EmbreeQuality::High: return RTC_BUILD_QUALITY_HIGH;
    }
    return RTC_BUILD_QUALITY_MEDIUM;
}

std::string device_error_text(RTCDevice device) {
    switch (rtcGetDeviceError(device)) {
        case RTC_ERROR_NONE: return "no error";
        case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
        case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
        case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
        case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
        case RTC_ERROR_CANCELLED: return "cancelled";
        default: return "unknown error";
    }
}

// Embree reports every allocation and release of its device here.
bool track_memory(void* user, ssize_t bytes, bool /*post*/) {
    static_cast<std::atomic<int64_t>*>(user)->fetch_add(int64_t(bytes), std::memory_order_relaxed);
    return true;
}

void fill_ray(const Ray& ray, RTCRay& out) {
    out.org_x = ray.org.x;
    out.org_y = ray.org.y;
    out.org_z = ray.org.z;
    out.tnear = ray.tmin;
    out.dir_x = ray.dir.x;
    out.dir_y = ray.dir.y;
    out.dir_z = ray.dir.z;
    out.time = 0.0f;
    out.tfar = ray.tmax;
    out.mask = 0xFFFFFFFFu;
    out.id = 0;
    out.flags = 0;
}

// Three unshared vertices per triangle: the same floats our traversal reads.
void copy_vertices(const SceneGeometry& geometry, float* vertices) {
    parallel::for_range(size_t(0), geometry.triangles.size(), size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const Triangle& t = geometry.triangles[i];
            const float data[9] = {t.v0.x, t.v0.y, t.v0.z, t.v1.x, t.v1.y, t.v1.z, t.v2.x, t.v2.y, t.v2.z};
            for (int k = 0; k < 9; ++k) vertices[9 * i + size_t(k)] = data[k];
        }
    });
}

// A triangle mesh over `geometry` with its vertex buffer filled; throws when
// Embree cannot allocate it.
RTCGeometry new_mesh(RTCDevice device, const SceneGeometry& geometry, RTCBuildQuality quality, float** vertex_buffer) {
    const size_t triangle_count = geometry.triangles.size();
    RTCGeometry mesh = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(mesh, quality);
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
        mesh, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * triangle_count));
    auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
        mesh, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), triangle_count));
    if (triangle_count > 0 && (!vertices || !indices)) {
        rtcReleaseGeometry(mesh);
        throw Error("embree: cannot allocate buffers for " + std::to_string(triangle_count) + " triangles (" +
                    device_error_text(device) + ")");
    }
    copy_vertices(geometry, vertices);
    parallel::for_range(size_t(0), triangle_count, size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i)
            for (uint32_t k = 0; k < 3; ++k) indices[3 * i + k] = uint32_t(3 * i + k);
    });
    if (vertex_buffer) *vertex_buffer = vertices;
    return mesh;
}

RTCDevice new_device(int threads) {
    const std::string config = threads > 0 ? "threads=" + std::to_string(threads) : "";
    RTCDevice device = rtcNewDevice(config.c_str());
    if (!device) throw Error("embree: rtcNewDevice failed (" + config + ")");
    return device;
}

void intersect_scene(RTCScene scene, std::span<const Ray> rays, std::span<Hit> hits) {
    if (rays.size() != hits.size()) throw Error("EmbreePeer::intersect: ray and hit counts differ");
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        for (size_t i = lo; i < hi; ++i) {
            RTCRayHit rayhit;
            fill_ray(rays[i], rayhit.ray);
            rayhit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rayhit.hit.primID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &context, &rayhit);
            Hit hit;
            if (rayhit.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
                hit.t = rayhit.ray.tfar;
                hit.u = rayhit.hit.u;
                hit.v = rayhit.hit.v;
                hit.prim = rayhit.hit.primID;
            }
            hits[i] = hit;
        }
    });
}

void occluded_scene(RTCScene scene, std::span<const Ray> rays, std::span<uint8_t> occluded) {
    if (rays.size() != occluded.size()) throw Error("EmbreePeer::occluded: ray and result counts differ");
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        for (size_t i = lo; i < hi; ++i) {
            RTCRay ray;
            fill_ray(rays[i], ray);
            rtcOccluded1(scene, &context, &ray);
            occluded[i] = ray.tfar < 0.0f ? 1 : 0;  // Embree sets tfar = -inf on a hit
        }
    });
}

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

bool embree_available() { return true; }

std::string embree_version() {
    return std::to_string(RTC_VERSION_MAJOR) + "." + std::to_string(RTC_VERSION_MINOR) + "." +
           std::to_string(RTC_VERSION_PATCH);
}

struct EmbreePeer::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::atomic<int64_t> allocated{0};
    ~Impl() {
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
};

EmbreePeer::EmbreePeer(const SceneGeometry& geometry, EmbreeQuality quality, int threads)
    : impl_(std::make_unique<Impl>()) {
    impl_->device = new_device(threads);
    rtcSetDeviceMemoryMonitorFunction(impl_->device, track_memory, &impl_->allocated);

    // Timed like our builds: from the triangle array in memory to a scene
    // that answers queries (Embree's copy into its own buffers included).
    const auto start = std::chrono::steady_clock::now();
    const int64_t before = impl_->allocated.load();
    const size_t triangle_count = geometry.triangles.size();
    impl_->scene = rtcNewScene(impl_->device);
    rtcSetSceneBuildQuality(impl_->scene, to_rtc(quality));
    RTCGeometry mesh = new_mesh(impl_->device, geometry, to_rtc(quality), nullptr);
    rtcCommitGeometry(mesh);
    rtcAttachGeometry(impl_->scene, mesh);
    rtcReleaseGeometry(mesh);
    rtcCommitScene(impl_->scene);
    build_ms_ = ms_since(start);
    if (rtcGetDeviceError(impl_->device) != RTC_ERROR_NONE)
        throw Error("embree: scene build failed (" + device_error_text(impl_->device) + ")");
    const int64_t buffers = int64_t(triangle_count * (9 * sizeof(float) + 3 * sizeof(uint32_t)));
    const int64_t used = impl_->allocated.load() - before - buffers;
    bytes_ = used > 0 ? size_t(used) : 0;
}

EmbreePeer::~EmbreePeer() = default;

void EmbreePeer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    intersect_scene(impl_->scene, rays, hits);
}

void EmbreePeer::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    occluded_scene(impl_->scene, rays, occluded);
}

// --- the dynamic peer ---

struct EmbreeDynamicPeer::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    RTCGeometry mesh = nullptr;  // owned by the scene
    float* vertices = nullptr;   // the mesh's vertex buffer
    size_t triangle_count = 0;
    ~Impl() {
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
};

EmbreeDynamicPeer::EmbreeDynamicPeer(const SceneGeometry& geometry, EmbreeUpdate update, int threads)
    : impl_(std::make_unique<Impl>()), update_(update) {
    impl_->device = new_device(threads);
    // Embree uses a geometry's own quality (REFIT among them) only in a LOW
    // scene, its two-level mode for dynamic scenes; MEDIUM rebuilds it all.
    const RTCBuildQuality scene_quality = update == EmbreeUpdate::Medium ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_LOW;
    const RTCBuildQuality mesh_quality = update == EmbreeUpdate::Refit ? RTC_BUILD_QUALITY_REFIT : scene_quality;
    const auto start = std::chrono::steady_clock::now();
    impl_->triangle_count = geometry.triangles.size();
    impl_->scene = rtcNewScene(impl_->device);
    rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(impl_->scene, scene_quality);
    impl_->mesh = new_mesh(impl_->device, geometry, mesh_quality, &impl_->vertices);
    rtcCommitGeometry(impl_->mesh);
    rtcAttachGeometry(impl_->scene, impl_->mesh);
    rtcReleaseGeometry(impl_->mesh);  // the scene keeps it alive
    rtcCommitScene(impl_->scene);
    build_ms_ = ms_since(start);
    if (rtcGetDeviceError(impl_->device) != RTC_ERROR_NONE)
        throw Error("embree: scene build failed (" + device_error_text(impl_->device) + ")");
}

EmbreeDynamicPeer::~EmbreeDynamicPeer() = default;

double EmbreeDynamicPeer::update(const SceneGeometry& geometry) {
    if (geometry.triangles.size() != impl_->triangle_count)
        throw Error("embree: the frame has " + std::to_string(geometry.triangles.size()) + " triangles, the scene " +
                    std::to_string(impl_->triangle_count));
    auto start = std::chrono::steady_clock::now();
    copy_vertices(geometry, impl_->vertices);
    copy_ms_ = ms_since(start);
    start = std::chrono::steady_clock::now();
    rtcUpdateGeometryBuffer(impl_->mesh, RTC_BUFFER_TYPE_VERTEX, 0);
    rtcCommitGeometry(impl_->mesh);
    rtcCommitScene(impl_->scene);
    const double commit_ms = ms_since(start);
    if (rtcGetDeviceError(impl_->device) != RTC_ERROR_NONE)
        throw Error("embree: scene update failed (" + device_error_text(impl_->device) + ")");
    return commit_ms;
}

void EmbreeDynamicPeer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    intersect_scene(impl_->scene, rays, hits);
}

void EmbreeDynamicPeer::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    occluded_scene(impl_->scene, rays, occluded);
}

}  // namespace rf::bench
