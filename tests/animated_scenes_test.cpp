// The procedural animated scenes (io/animated_scenes.h): names and sizes,
// determinism from a seed (and across thread counts), sane and finite keys at
// every frame, connected explode fragments that separate, a cloth that never
// enters the ball, n bodies that do not interpenetrate deeply, loading through
// rf::load_scene, and Scene::set_time reproducing the keys.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "core/parallel.h"
#include "io/animated_scenes.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf {
namespace {

// FNV-1a over everything that describes the geometry and its motion.
class Hasher {
public:
    void bytes(const void* data, size_t size) {
        const auto* p = static_cast<const unsigned char*>(data);
        for (size_t i = 0; i < size; ++i) value = (value ^ p[i]) * 1099511628211ull;
    }
    template <class T>
    void vec(const std::vector<T>& v) {
        const size_t n = v.size();
        bytes(&n, sizeof n);
        if (n) bytes(v.data(), n * sizeof(T));
    }
    uint64_t value = 1469598103934665603ull;
};

uint64_t geometry_hash(const Scene& scene) {
    Hasher h;
    for (const Mesh& m : scene.meshes) h.vec(m.positions), h.vec(m.normals), h.vec(m.indices), h.vec(m.material_ids);
    for (const Instance& i : scene.instances) {
        h.bytes(&i.mesh, sizeof i.mesh);
        h.bytes(i.transform.m, sizeof i.transform.m);
    }
    for (const AnimatedNode& n : scene.animation.nodes) {
        h.vec(n.translation_track.times), h.vec(n.translation_track.values);
        h.vec(n.rotation_track.times), h.vec(n.rotation_track.values);
    }
    for (const VertexKeyframes& k : scene.animation.vertex_keyframes) {
        h.vec(k.times);
        for (const auto& p : k.positions) h.vec(p);
        for (const auto& n : k.normals) h.vec(n);
    }
    return h.value;
}

// Default-size scenes, generated once for the whole suite.
const Scene& default_scene(const std::string& kind) {
    static std::map<std::string, Scene> cache;
    auto it = cache.find(kind);
    if (it == cache.end()) it = cache.emplace(kind, make_animated_scene(kind)).first;
    return it->second;
}

const Mesh* find_mesh(const Scene& scene, const std::string& name) {
    for (const Mesh& m : scene.meshes)
        if (m.name == name) return &m;
    return nullptr;
}

Affine3f quaternion_affine(const float* q) {
    const float x = q[0], y = q[1], z = q[2], w = q[3];
    Affine3f a;
    a.m[0][0] = 1 - 2 * (y * y + z * z), a.m[0][1] = 2 * (x * y - w * z), a.m[0][2] = 2 * (x * z + w * y);
    a.m[1][0] = 2 * (x * y + w * z), a.m[1][1] = 1 - 2 * (x * x + z * z), a.m[1][2] = 2 * (y * z - w * x);
    a.m[2][0] = 2 * (x * z - w * y), a.m[2][1] = 2 * (y * z + w * x), a.m[2][2] = 1 - 2 * (x * x + y * y);
    return a;
}

// Instance i's transform at key `frame`, computed from the keys by hand.
Affine3f keyed_transform(const Scene& scene, const InstanceAnimation& ia, int frame) {
    const AnimatedNode& node = scene.animation.nodes[ia.node];
    const float* t = &node.translation_track.values[3 * size_t(frame)];
    const float* q = &node.rotation_track.values[4 * size_t(frame)];
    return Affine3f::translation({t[0], t[1], t[2]}) * quaternion_affine(q) * ia.local;
}

float max_difference(const Affine3f& a, const Affine3f& b) {
    float d = 0.0f;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) d = std::max(d, std::fabs(a.m[r][c] - b.m[r][c]));
    return d;
}

void expect_timing(const Scene& scene, const std::string& what) {
    const Animation& a = scene.animation;
    EXPECT_EQ(a.start, 0.0f) << what;
    EXPECT_NEAR(a.end, 3.3f, 1e-5f) << what;
    EXPECT_EQ(a.frames_per_second, 30.0f) << what;
    EXPECT_FALSE(a.empty()) << what;
}

void expect_track(const Track& track, int width, const std::string& what) {
    ASSERT_EQ(track.key_count(), size_t(kAnimatedSceneFrames)) << what;
    EXPECT_EQ(track.width, width) << what;
    EXPECT_EQ(track.interpolation, Interpolation::Linear) << what;
    ASSERT_EQ(track.values.size(), size_t(width) * track.key_count()) << what;
    for (size_t k = 0; k < track.key_count(); ++k) EXPECT_FLOAT_EQ(track.times[k], float(k) / 30.0f) << what;
}

// ----------------------------------------------------------------------------

TEST(AnimatedScenes, NamesParseSizesAndSeeds) {
    EXPECT_TRUE(is_animated_scene_name("explode"));
    EXPECT_TRUE(is_animated_scene_name("cloth@50k"));
    EXPECT_TRUE(is_animated_scene_name("nbody#3"));
    EXPECT_FALSE(is_animated_scene_name("cornell"));
    EXPECT_FALSE(is_animated_scene_name("explodes"));
    AnimatedSceneSpec s = parse_animated_scene_name("explode@800k");
    EXPECT_EQ(s.kind, "explode");
    EXPECT_EQ(s.triangles, 800000u);
    EXPECT_EQ(s.seed, kAnimatedSceneDefaultSeed);
    s = parse_animated_scene_name("cloth@1.5m#42");
    EXPECT_EQ(s.kind, "cloth");
    EXPECT_EQ(s.triangles, 1500000u);
    EXPECT_EQ(s.seed, 42u);
    s = parse_animated_scene_name("nbody#4294967295");
    EXPECT_EQ(s.triangles, 0u);
    EXPECT_EQ(s.seed, 4294967295u);
    EXPECT_EQ(parse_animated_scene_name("nbody@12345").triangles, 12345u);
    for (const char* bad : {"explode@", "explode@abc", "explode@5m", "explode@10", "explode@-5k", "explode@2kk",
                            "explode#", "explode#x", "explode#4294967296", "explode#7@800k"}) {
        try {
            parse_animated_scene_name(bad);
            ADD_FAILURE() << bad << ": no error";
        } catch (const Error& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(std::string("builtin:") + bad), std::string::npos) << message;
            EXPECT_EQ(message.find('\n'), std::string::npos) << message;
        }
    }
    const auto names = builtin_scene_names();
    for (const char* kind : {"explode", "cloth", "nbody"})
        EXPECT_NE(std::find(names.begin(), names.end(), kind), names.end()) << kind;
}

// Generated twice on all threads and once on one: the same hash; another seed: another.
void expect_deterministic(const std::string& name) {
    const uint64_t first = geometry_hash(make_animated_scene(name));
    EXPECT_EQ(first, geometry_hash(make_animated_scene(name))) << name;
    const uint64_t one_thread = parallel::with_threads(1, [&] { return geometry_hash(make_animated_scene(name)); });
    EXPECT_EQ(first, one_thread) << name;
    EXPECT_NE(first, geometry_hash(make_animated_scene(name + "#7"))) << name;
}

TEST(AnimatedScenes, ExplodeIsDeterministic) { expect_deterministic("explode@20k"); }
TEST(AnimatedScenes, ClothIsDeterministic) { expect_deterministic("cloth@1k"); }
TEST(AnimatedScenes, NbodyIsDeterministic) { expect_deterministic("nbody@20k"); }

// The default sizes (Garanzha 2014's 252K, 92K and 146K), within 3%.
TEST(AnimatedScenes, ExplodeDefaultSize) {
    EXPECT_NEAR(double(default_scene("explode").triangle_count()), double(kExplodeDefaultTriangles),
                0.03 * double(kExplodeDefaultTriangles));
}
TEST(AnimatedScenes, ClothDefaultSize) {
    EXPECT_NEAR(double(default_scene("cloth").triangle_count()), double(kClothDefaultTriangles),
                0.03 * double(kClothDefaultTriangles));
}
TEST(AnimatedScenes, NbodyDefaultSize) {
    EXPECT_NEAR(double(default_scene("nbody").triangle_count()), double(kNbodyDefaultTriangles),
                0.03 * double(kNbodyDefaultTriangles));
}

TEST(AnimatedScenes, SmallSizesAreNearTheRequestedCounts) {
    for (const char* name : {"explode@30k", "nbody@30k", "cloth@1k", "explode@1k", "nbody@1k"}) {
        const double wanted = double(parse_animated_scene_name(name).triangles);
        EXPECT_NEAR(double(make_animated_scene(name).triangle_count()), wanted, 0.1 * wanted) << name;
    }
}

TEST(AnimatedScenes, EveryMeshIsIndexedWithSharedVertices) {
    for (const char* kind : {"explode", "cloth", "nbody"}) {
        const Scene& scene = default_scene(kind);
        for (const Mesh& m : scene.meshes) {
            EXPECT_NO_THROW(m.validate()) << kind << " " << m.name;
            EXPECT_LT(m.vertex_count(), m.indices.size()) << kind << " " << m.name;  // shared
        }
        EXPECT_FALSE(scene.lights.empty() && scene.environment.strength == 0.0f) << kind;
        EXPECT_TRUE(scene.camera.has_value()) << kind;
        EXPECT_GE(scene.materials.size(), 2u) << kind;
    }
}

// Rigid scenes: one node per animated instance, Linear keys per frame,
// finite translations inside `box`, unit quaternions, frame 0 = the instances.
void expect_rigid_keys(const Scene& scene, const Box3f& box, const std::string& what) {
    expect_timing(scene, what);
    const Animation& a = scene.animation;
    ASSERT_EQ(a.instances.size(), a.nodes.size()) << what;
    for (const InstanceAnimation& ia : a.instances) {
        ASSERT_LT(ia.node, a.nodes.size());
        ASSERT_LT(ia.instance, scene.instances.size());
        const AnimatedNode& node = a.nodes[ia.node];
        EXPECT_EQ(node.parent, -1);
        expect_track(node.translation_track, 3, what);
        expect_track(node.rotation_track, 4, what);
        for (int k = 0; k < kAnimatedSceneFrames; ++k) {
            const float* t = &node.translation_track.values[3 * size_t(k)];
            const float* q = &node.rotation_track.values[4 * size_t(k)];
            const Vec3f p(t[0], t[1], t[2]);
            ASSERT_TRUE(is_finite(p)) << what << " frame " << k;
            ASSERT_TRUE(p.x >= box.lo.x && p.y >= box.lo.y && p.z >= box.lo.z) << what << " frame " << k;
            ASSERT_TRUE(p.x <= box.hi.x && p.y <= box.hi.y && p.z <= box.hi.z) << what << " frame " << k;
            ASSERT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0f, 1e-4f) << what;
        }
        EXPECT_LT(max_difference(scene.instances[ia.instance].transform, keyed_transform(scene, ia, 0)), 1e-5f);
    }
}

TEST(AnimatedScenes, ExplodeKeysAreFiniteAndInABox) {
    expect_rigid_keys(default_scene("explode"), Box3f{{-25, 0, -25}, {25, 15, 25}}, "explode");
}

TEST(AnimatedScenes, NbodyKeysAreFiniteAndInsideTheBox) {
    const Scene& scene = default_scene("nbody");
    const Mesh* ground = find_mesh(scene, "ground");
    ASSERT_NE(ground, nullptr);
    // The walls are a quarter of the ground's half-size.
    const float half = 0.25f * ground->bounds().hi.x;
    expect_rigid_keys(scene, Box3f{{-half, 0, -half}, {half, 4 * half, half}}, "nbody");
}

// Triangles a and b of `mesh` are connected when they share a vertex.
bool connected(const Mesh& mesh) {
    std::vector<uint32_t> parent(mesh.vertex_count());
    std::iota(parent.begin(), parent.end(), 0u);
    auto find = [&](uint32_t v) {
        while (parent[v] != v) v = parent[v] = parent[parent[v]];
        return v;
    };
    for (size_t t = 0; t < mesh.triangle_count(); ++t)
        for (int k = 1; k < 3; ++k) parent[find(mesh.indices[3 * t + size_t(k)])] = find(mesh.indices[3 * t]);
    const uint32_t root = find(mesh.indices[0]);
    for (uint32_t v = 0; v < mesh.vertex_count(); ++v)
        if (find(v) != root) return false;
    return true;
}

TEST(AnimatedScenes, ExplodeFragmentsAreConnectedAndFlyApart) {
    const Scene& scene = default_scene("explode");
    const Animation& a = scene.animation;
    EXPECT_GE(a.instances.size(), 100u);
    EXPECT_LE(a.instances.size(), 1024u);
    for (const InstanceAnimation& ia : a.instances) {
        const Mesh& mesh = scene.meshes[scene.instances[ia.instance].mesh];
        ASSERT_GT(mesh.triangle_count(), 0u) << mesh.name;
        EXPECT_TRUE(connected(mesh)) << mesh.name;
    }
    // The fragment centres' spread: unchanged while intact, then growing.
    auto spread = [&](int frame) {
        Box3f box;
        for (const AnimatedNode& n : a.nodes) {
            const float* t = &n.translation_track.values[3 * size_t(frame)];
            box.extend({t[0], t[1], t[2]});
        }
        return box.hi.x - box.lo.x + box.hi.z - box.lo.z;
    };
    EXPECT_EQ(spread(0), spread(10));
    EXPECT_GT(spread(40), 2.0f * spread(0));
    EXPECT_GT(spread(99), 3.0f * spread(0));
}

TEST(AnimatedScenes, ClothNeverEntersTheBallNorTheGround) {
    const Scene& scene = default_scene("cloth");
    const Mesh* ball = find_mesh(scene, "ball");
    const Mesh* cloth = find_mesh(scene, "cloth");
    ASSERT_TRUE(ball && cloth);
    const Box3f b = ball->bounds();
    const Vec3f centre = (b.lo + b.hi) * 0.5f;
    const float radius = 0.5f * (b.hi.x - b.lo.x);
    expect_timing(scene, "cloth");
    ASSERT_EQ(scene.animation.vertex_keyframes.size(), 1u);
    const VertexKeyframes& keys = scene.animation.vertex_keyframes[0];
    EXPECT_EQ(&scene.meshes[keys.mesh], cloth);
    ASSERT_EQ(keys.times.size(), size_t(kAnimatedSceneFrames));
    ASSERT_EQ(keys.positions.size(), keys.times.size());
    EXPECT_TRUE(keys.normals.empty() || keys.normals.size() == keys.times.size());
    float closest = 1e30f, lowest = 1e30f;
    for (size_t k = 0; k < keys.positions.size(); ++k) {
        EXPECT_FLOAT_EQ(keys.times[k], float(k) / 30.0f);
        ASSERT_EQ(keys.positions[k].size(), cloth->vertex_count());
        for (const Vec3f& p : keys.positions[k]) {
            ASSERT_TRUE(is_finite(p) && std::fabs(p.x) < 5.0f && std::fabs(p.z) < 5.0f && p.y < 5.0f) << k;
            closest = std::min(closest, length(p - centre));
            lowest = std::min(lowest, p.y);
        }
    }
    EXPECT_GE(closest, radius - 1e-3f);
    EXPECT_GE(lowest, -1e-4f);
    // It fell and drapes: at the end some of it hangs below the ball's centre.
    float end_low = 1e30f;
    for (const Vec3f& p : keys.positions.back()) end_low = std::min(end_low, p.y);
    EXPECT_LT(end_low, centre.y);
    EXPECT_EQ(cloth->positions, keys.positions.front());
}

TEST(AnimatedScenes, NbodyBodiesDoNotInterpenetrateDeeply) {
    const Scene& scene = default_scene("nbody");
    const Animation& a = scene.animation;
    std::vector<float> radius;  // bounding sphere: the mesh's times the instance's scale
    for (const InstanceAnimation& ia : a.instances) {
        float r = 0.0f;
        for (const Vec3f& p : scene.meshes[scene.instances[ia.instance].mesh].positions) r = std::max(r, length(p));
        radius.push_back(r * ia.local.m[0][0]);
    }
    float worst = 0.0f;  // the deepest overlap over the smaller radius
    for (int k = 0; k < kAnimatedSceneFrames; ++k) {
        std::vector<Vec3f> p;
        for (const InstanceAnimation& ia : a.instances) {
            const float* t = &a.nodes[ia.node].translation_track.values[3 * size_t(k)];
            p.push_back({t[0], t[1], t[2]});
        }
        for (size_t i = 0; i < p.size(); ++i) {
            EXPECT_GE(p[i].y - radius[i], -0.05f * radius[i]) << "frame " << k;  // above the floor
            for (size_t j = i + 1; j < p.size(); ++j) {
                const float depth = radius[i] + radius[j] - length(p[i] - p[j]);
                worst = std::max(worst, depth / std::min(radius[i], radius[j]));
            }
        }
    }
    EXPECT_LT(worst, 0.05f);
}

TEST(AnimatedScenes, LoadThroughLoadScene) {
    for (const char* name : {"explode@20k", "cloth@1k#5", "nbody@10k"}) {
        const Scene scene = load_scene(std::string("builtin:") + name);  // finalize() validates
        EXPECT_EQ(scene.source, std::string("builtin:") + name);
        EXPECT_TRUE(scene.animated()) << name;
        EXPECT_EQ(scene.time, 0.0f) << name;
        EXPECT_EQ(scene.animation.frame_count(), kAnimatedSceneFrames) << name;
    }
    EXPECT_THROW(load_scene("builtin:explode@abc"), Error);
}

TEST(AnimatedScenes, SetTimeReproducesTheRigidKeys) {
    for (const char* name : {"explode@20k", "nbody@20k"}) {
        Scene scene = load_scene(std::string("builtin:") + name);
        for (int frame : {0, 15, 16, 50, 99, 1, 99}) {  // forwards, back to the start, forwards again
            scene.set_time(scene.animation.frame_time(frame));
            for (const InstanceAnimation& ia : scene.animation.instances) {
                const Affine3f& evaluated = scene.instances[ia.instance].transform;
                ASSERT_LT(max_difference(evaluated, keyed_transform(scene, ia, frame)), 1e-4f) << name << " " << frame;
            }
        }
        // Half-way between two keys the translation is half-way too.
        scene.set_time(0.5f * (scene.animation.frame_time(40) + scene.animation.frame_time(41)));
        for (const InstanceAnimation& ia : scene.animation.instances) {
            const Affine3f a = keyed_transform(scene, ia, 40), b = keyed_transform(scene, ia, 41);
            for (int r = 0; r < 3; ++r)
                ASSERT_NEAR(scene.instances[ia.instance].transform.m[r][3], 0.5f * (a.m[r][3] + b.m[r][3]), 1e-4f);
        }
    }
}

TEST(AnimatedScenes, SetTimeMovesTheFragmentsAndKeepsThemAboveTheGround) {
    Scene scene = load_scene("builtin:explode@20k");
    scene.set_time(scene.animation.frame_time(10));  // still intact
    const GeometryChange flying = scene.set_time(scene.animation.frame_time(40));
    EXPECT_EQ(flying.instances.size(), scene.animation.instances.size());
    EXPECT_TRUE(flying.meshes.empty());
    for (int frame : {20, 40, 70, 99}) {
        scene.set_time(scene.animation.frame_time(frame));
        float lowest = 1e30f;
        for (const InstanceAnimation& ia : scene.animation.instances) {
            const Instance& in = scene.instances[ia.instance];
            for (const Vec3f& p : scene.meshes[in.mesh].positions)
                lowest = std::min(lowest, in.transform.transform_point(p).y);
        }
        EXPECT_GE(lowest, -1e-3f) << "frame " << frame;
    }
}

TEST(AnimatedScenes, SetTimeDeformsTheCloth) {
    Scene scene = load_scene("builtin:cloth@1k");
    const VertexKeyframes keys = scene.animation.vertex_keyframes[0];
    for (int frame : {30, 99, 1}) {
        const GeometryChange change = scene.set_time(scene.animation.frame_time(frame));
        ASSERT_EQ(change.meshes.size(), 1u);
        EXPECT_EQ(change.meshes[0], keys.mesh);
        const Mesh& cloth = scene.meshes[keys.mesh];
        for (size_t v = 0; v < cloth.vertex_count(); ++v) {
            ASSERT_NEAR(cloth.positions[v].x, keys.positions[size_t(frame)][v].x, 1e-5f);
            ASSERT_NEAR(cloth.positions[v].y, keys.positions[size_t(frame)][v].y, 1e-5f);
            ASSERT_NEAR(cloth.positions[v].z, keys.positions[size_t(frame)][v].z, 1e-5f);
        }
    }
}

}  // namespace
}  // namespace rf
