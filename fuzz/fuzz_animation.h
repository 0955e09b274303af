// The animation oracle of the scene-format fuzz targets (fuzz_aff,
// fuzz_json_scene, fuzz_gltf, fuzz_glb), also replayed on the reproducers by
// tests/fuzz_regressions_test.cpp. A scene that loaded is evaluated
// (Scene::set_time) before, inside and after its keys, at huge and
// non-finite times, and back at its start. set_time never throws and keeps
// the triangle count; its GeometryChange names existing meshes and
// instances, sorted and unique; SceneGeometry::update with it gives the
// triangles a fresh build gives (so the change misses nothing); and the
// scene back at its start is the scene first seen there (evaluation is a
// function of t, not of the times before it), which is also the scene as
// loaded (every loader returns its scene at Animation::start).
#pragma once

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::fuzz {

inline std::vector<float> animation_times(const Animation& a) {
    const float inf = std::numeric_limits<float>::infinity();
    return {a.start, a.end, 0.5f * (a.start + a.end), a.start - 1.0f, a.end + 1e6f, 1e30f, -1e30f,
            std::numeric_limits<float>::quiet_NaN(), inf, -inf, a.start};
}

namespace detail {

template <class T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

inline std::string check_change(const Scene& scene, const GeometryChange& c) {
    for (size_t i = 0; i < c.meshes.size(); ++i)
        if (c.meshes[i] >= scene.meshes.size() || (i > 0 && c.meshes[i] <= c.meshes[i - 1]))
            return "the change names meshes out of range or out of order";
    for (size_t i = 0; i < c.instances.size(); ++i)
        if (c.instances[i] >= scene.instances.size() || (i > 0 && c.instances[i] <= c.instances[i - 1]))
            return "the change names instances out of range or out of order";
    return "";
}

// What the scene looks like at one time: every mesh's positions, every instance's placement.
struct Snapshot {
    std::vector<std::vector<Vec3f>> positions;
    std::vector<Instance> instances;
    bool operator==(const Snapshot& o) const {
        if (instances.size() != o.instances.size() || positions.size() != o.positions.size()) return false;
        for (size_t i = 0; i < instances.size(); ++i)
            if (instances[i].mesh != o.instances[i].mesh || instances[i].visible != o.instances[i].visible ||
                std::memcmp(instances[i].transform.m, o.instances[i].transform.m, sizeof(instances[i].transform.m)) != 0)
                return false;
        for (size_t m = 0; m < positions.size(); ++m)
            if (!same_bytes(positions[m], o.positions[m])) return false;
        return true;
    }
};
inline Snapshot snapshot(const Scene& scene) {
    Snapshot s;
    for (const Mesh& m : scene.meshes) s.positions.push_back(m.positions);
    s.instances = scene.instances;
    return s;
}

inline std::optional<SceneGeometry> try_build(const Scene& scene) {
    try {
        return SceneGeometry::build(scene);
    } catch (const Error&) {
        return std::nullopt;  // non-finite world coordinates: an accepted outcome
    }
}

}  // namespace detail

// "" when the scene animates as described above; otherwise what went wrong.
// Other exceptions than rf::Error from SceneGeometry escape (the harness
// reports them).
inline std::string check_animation(Scene& scene) {
    const size_t triangles = scene.triangle_count();
    if (scene.animation.empty()) {  // a still scene: nothing may move (and no geometry to build 12 times)
        const GeometryChange change = scene.set_time(1.0f);
        return change.geometry() || change.camera || scene.triangle_count() != triangles ? "a still scene moved" : "";
    }
    const std::vector<float> times = animation_times(scene.animation);
    std::optional<SceneGeometry> geometry = detail::try_build(scene);
    const detail::Snapshot as_loaded = detail::snapshot(scene);
    std::optional<detail::Snapshot> at_start;
    for (size_t i = 0; i < times.size(); ++i) {
        GeometryChange change;
        try {
            change = scene.set_time(times[i]);
        } catch (const Error& e) {
            return std::string("set_time threw: ") + e.what();
        }
        if (scene.triangle_count() != triangles) return "set_time changed the triangle count";
        if (std::string bad = detail::check_change(scene, change); !bad.empty()) return bad;
        if (i == 0) {
            at_start = detail::snapshot(scene);
            if (!(*at_start == as_loaded)) return "the scene as loaded differs from the scene at its start";
        }
        if (i + 1 == times.size() && !(detail::snapshot(scene) == *at_start))
            return "the scene back at its start differs from the scene first seen there";
        std::optional<SceneGeometry> fresh = detail::try_build(scene);
        if (!geometry || !fresh) {  // start over from the fresh build (or from nothing)
            geometry = std::move(fresh);
            continue;
        }
        try {
            geometry->update(scene, change);
        } catch (const Error& e) {
            return std::string("SceneGeometry::update threw where a build succeeds: ") + e.what();
        }
        if (!detail::same_bytes(geometry->triangles, fresh->triangles))
            return "SceneGeometry::update missed a change (triangles differ from a fresh build)";
    }
    return "";
}

// For the harnesses: a failed check is a crash libFuzzer reports, with its reason on stderr.
inline void trap_unless_animation_is_consistent(Scene& scene) {
    const std::string bad = check_animation(scene);
    if (bad.empty()) return;
    std::fprintf(stderr, "animation check failed: %s\n", bad.c_str());
    __builtin_trap();
}

}  // namespace rf::fuzz
