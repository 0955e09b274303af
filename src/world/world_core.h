// The state behind an rf::World, shared by the world and every renderer
// made for it (so a renderer outliving its World keeps rendering its last
// frame): the scene and its flat triangles, or a paged scene; the structure
// and how it follows time; the frame lock and the frame's version.
//
// Renderers read the frame through a FrameReading held for a whole pass:
// the world shared, with the scene, triangles and structure of the frame and
// its version; a renderer that sees a new version binds to the new
// structure and rebuilds its shading tables before tracing
// (render/renderer_base.cpp). Everything that changes the frame holds the
// lock exclusively and bumps the version.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "rayforge/world.h"
#include "world/device_support.h"
#include "world/frame_lock.h"

namespace rf {

struct WorldCore {
    // Opened or made by open_world / make_world (world.cpp).
    WorldCore(Scene scene, const WorldOptions& options, double load_ms);
    WorldCore(std::unique_ptr<PagedScene> paged, const WorldOptions& options, double load_ms);

    // The world held shared for a pass or a query batch, committed first
    // (unless told not to: statistics). Nested readings on one thread take
    // the lock once.
    class FrameReading {
    public:
        enum class Commit : bool { No, Yes };
        explicit FrameReading(const WorldCore& core, Commit commit = Commit::Yes);
        ~FrameReading();
        FrameReading(const FrameReading&) = delete;
        FrameReading& operator=(const FrameReading&) = delete;
        [[nodiscard]] const Scene& scene() const { return core_.scene; }
        [[nodiscard]] const SceneGeometry& geometry() const { return core_.geometry; }
        [[nodiscard]] const Accel& accel() const { return core_.current_accel(); }
        [[nodiscard]] uint64_t version() const { return core_.version.load(std::memory_order_relaxed); }

    private:
        const WorldCore& core_;
        bool locked_ = false;
    };

    // This thread works for a reading another thread holds (a pass's
    // progress callback on one of the pass's worker threads): readings
    // nested in it take no lock, and changes are refused as on the reading's
    // own thread.
    class OnBehalfOfReading {
    public:
        explicit OnBehalfOfReading(const WorldCore& core);
        ~OnBehalfOfReading();
        OnBehalfOfReading(const OnBehalfOfReading&) = delete;
        OnBehalfOfReading& operator=(const OnBehalfOfReading&) = delete;

    private:
        const WorldCore& core_;
    };

    // The world held exclusively; rf::Error when this thread is inside a
    // pass or a query of the same world (it would wait for itself).
    class FrameWriting {
    public:
        FrameWriting(WorldCore& core, const char* what);
        ~FrameWriting();
        FrameWriting(const FrameWriting&) = delete;
        FrameWriting& operator=(const FrameWriting&) = delete;

    private:
        WorldCore& core_;
    };

    void commit(const ProgressCallback& progress);
    [[nodiscard]] bool committed() const { return built.load(std::memory_order_acquire); }
    UpdateStats set_time(float t);
    UpdateStats geometry_replaced(GeometryChange change);
    void materials_changed();
    [[nodiscard]] WorldStats stats() const;
    [[nodiscard]] const Accel& current_accel() const;

    // What the world is.
    const Device device;
    const WorldKind kind;
    WorldPlan plan;
    Scene scene;              // a paged world's: its lights, environment, a material and its camera
    SceneGeometry geometry;   // a paged world's: its bounds only
    std::unique_ptr<PagedScene> paged;

    // The structure (one of the two; the paged scene's own for a paged world).
    std::unique_ptr<Accel> still_accel;
    std::unique_ptr<DynamicAccel> dynamic_accel;

    mutable FrameLock lock;
    std::atomic<bool> built{false};
    // Bumped (under the exclusive lock) by every change a renderer must see;
    // read without the lock by a renderer asking whether it is behind.
    std::atomic<uint64_t> version{1};
    float time = 0.0f;
    double load_ms = 0.0;
    CommitKind last_commit = CommitKind::None;
    double commit_ms = 0.0;
    uint64_t commits = 0;

private:
    void build(const ProgressCallback& progress);
    UpdateStats update_structure(const GeometryChange& change);
};

// The core behind a World (for make_renderer and the backends).
std::shared_ptr<WorldCore> core_of(World& world);

}  // namespace rf
