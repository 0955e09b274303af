// rf::World: opening every kind of scene, the lazy first build, the frame
// protocol (set_time: the triangles and the structure follow; renderers
// follow at their next pass, to the bit what fresh renderers draw), edits
// (geometry_replaced, materials_changed), reopening with other options, the
// device rules in one place (world/device_support.h), and the threading
// contract: a render thread and an updating thread on one world (this test
// runs under ThreadSanitizer).
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <string>
#include <thread>
#include <vector>

#include "accel/brute_force.h"
#include "accel/device_structure.h"
#include "accel_test_rays.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/world.h"
#include "render_test_scene.h"
#include "test_paths.h"
#include "world/device_support.h"

namespace rf {
namespace {

constexpr const char* kAnimated = "builtin:nbody@3k";  // rigid bodies flying apart (instances)
constexpr const char* kDeforming = "builtin:cloth@3k";  // a deforming mesh

RenderOptions small_options(IntegratorKind kind = IntegratorKind::Normals) {
    RenderOptions o = options_for(kind, 24, 16);
    o.threads = 2;
    return o;
}

WorldOptions with_method(UpdateMethod method) {
    WorldOptions options;
    options.update.method = method;
    options.update.clusters.max_count = 20;
    options.update.clusters.max_size = 20.0f;
    options.build.threads = 2;
    return options;
}

// Closest hits of random rays through the world equal brute force on its triangles.
void expect_brute_force_hits(const World& world, uint32_t seed, const std::string& where) {
    const BruteForceAccel reference(world.geometry());
    const std::vector<Ray> rays = test::make_rays(world.geometry(), 300, seed);
    std::vector<Hit> hits(rays.size());
    world.intersect(rays, hits);
    size_t disagreements = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit expected = reference.intersect(rays[i]);
        const bool same = hits[i].found() == expected.found() &&
                          (!expected.found() || std::abs(hits[i].t - expected.t) <= 1e-4f * std::max(1.0f, expected.t));
        disagreements += same ? 0 : 1;
    }
    // A two-level structure tests triangles in object space: a ray grazing a
    // vertex exactly may go either way (dynamic_accel_test.cpp).
    EXPECT_LE(double(disagreements), 0.01 * double(rays.size())) << where;
}

TEST(World, OpensAStillSceneAndBuildsAtTheFirstCommit) {
    const std::unique_ptr<World> world = open_world("builtin:cornell");
    EXPECT_EQ(world->device(), Device{});
    EXPECT_FALSE(world->paged());
    EXPECT_FALSE(world->animated());
    EXPECT_EQ(world->time_range().frame_count(), 1);
    WorldStats stats = world->stats();
    EXPECT_EQ(stats.last_commit, CommitKind::None);  // nothing built yet
    EXPECT_EQ(stats.commits, 0u);
    EXPECT_GT(stats.triangles, 0u);
    EXPECT_GT(stats.load_ms, 0.0);
    EXPECT_TRUE(stats.accel.name.empty());
    EXPECT_EQ(world->camera().eye, load_scene("builtin:cornell").camera_or_default().eye);
    EXPECT_FALSE(world->bounds().is_empty());
    EXPECT_EQ(world->set_time(3.0f).updated, false);  // a still world only records the time
    EXPECT_EQ(world->time(), 3.0f);

    const Accel& accel = world->accel();  // commits
    stats = world->stats();
    EXPECT_EQ(stats.last_commit, CommitKind::Build);
    EXPECT_EQ(stats.commits, 1u);
    EXPECT_EQ(stats.accel.name, accel.stats().name);
    EXPECT_EQ(stats.accel.name, "bvh/binned/bvh8");
    EXPECT_GT(stats.host_bytes, stats.accel.bytes);
    EXPECT_EQ(world->commit().commits, 1u);  // committed once
    expect_brute_force_hits(*world, 1, "cornell");
    EXPECT_TRUE(world->notes().empty());
    EXPECT_THROW((void)world->paged_scene(), Error);
}

TEST(World, MakeWorldFinalizesAProgramsScene) {
    Scene scene;
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    mesh.indices = {0, 1, 2};
    scene.meshes.push_back(mesh);  // no material, no instance: finalize() adds them
    const std::unique_ptr<World> world = make_world(scene);
    EXPECT_EQ(world->scene().instances.size(), 1u);
    EXPECT_EQ(world->scene().materials.size(), 1u);
    EXPECT_TRUE(world->intersect(Ray{{0.2f, 0.2f, 1.0f}, 0.0f, {0, 0, -1}, kInfinity}).found());
    mesh.indices = {0, 1, 7};
    Scene broken;
    broken.meshes.push_back(mesh);
    EXPECT_THROW((void)make_world(broken), Error);
}

// One world moved through time with one renderer that is never told: each
// frame it draws what a renderer made fresh for that frame draws, and the
// world's triangles are those of a fresh world at that time.
class WorldMethods : public ::testing::TestWithParam<UpdateMethod> {};

TEST_P(WorldMethods, RendererFollowsSetTimeAsAFreshRendererWould) {
    const std::unique_ptr<World> world = open_world(kAnimated, with_method(GetParam()));
    ASSERT_TRUE(world->animated());
    const TimeRange range = world->time_range();
    ASSERT_GT(range.frame_count(), 40);
    const RenderOptions o = small_options();
    const Camera camera = world->camera();
    const std::unique_ptr<Renderer> renderer = make_renderer(*world, camera, o);
    EXPECT_EQ(world->stats().update_method, to_string(GetParam()));
    for (int frame : {0, 30, 12, 40, 1}) {
        const UpdateStats update = world->set_time(range.frame_time(frame));
        EXPECT_EQ(update.updated, frame != 0) << frame;  // the world was built at frame 0
        EXPECT_EQ(renderer->passes(), 0) << "a renderer behind its world has restarted";
        render_progressive(*renderer);
        const std::unique_ptr<Renderer> fresh = make_renderer(*world, camera, o);
        render_progressive(*fresh);
        EXPECT_EQ(renderer->image().pixels, fresh->image().pixels) << to_string(GetParam()) << " frame " << frame;

        const std::unique_ptr<World> at_time = open_world(kAnimated);
        at_time->set_time(range.frame_time(frame));
        EXPECT_EQ(world->geometry().triangles.size(), at_time->geometry().triangles.size());
        EXPECT_TRUE(std::equal(world->geometry().triangles.begin(), world->geometry().triangles.end(),
                               at_time->geometry().triangles.begin(), [](const Triangle& a, const Triangle& b) {
                                   return a.v0 == b.v0 && a.v1 == b.v1 && a.v2 == b.v2;
                               }))
            << frame;
        expect_brute_force_hits(*world, uint32_t(frame), to_string(GetParam()) + " frame " + std::to_string(frame));
    }
    const WorldStats stats = world->stats();
    EXPECT_EQ(stats.last_commit, CommitKind::Update);
    EXPECT_EQ(stats.commits, 5u);  // the build and four updates
}

INSTANTIATE_TEST_SUITE_P(AllMethods, WorldMethods,
                         ::testing::Values(UpdateMethod::Refit, UpdateMethod::Adapt, UpdateMethod::Rebuild,
                                           UpdateMethod::Clusters, UpdateMethod::TwoLevel),
                         [](const auto& info) {
                             std::string name = to_string(info.param);
                             std::erase(name, '-');
                             return name;
                         });

// Moved to its first frame before anything is built, a world builds once,
// there; a structure that is not a BVH follows by rebuilding.
TEST(World, MovedBeforeTheFirstCommitBuildsOnceAndGridsRebuild) {
    const std::unique_ptr<World> world = open_world(kDeforming);
    const float t = world->time_range().frame_time(20);
    EXPECT_FALSE(world->set_time(t).updated);
    world->commit();
    EXPECT_EQ(world->stats().commits, 1u);
    EXPECT_EQ(world->stats().update_method, "rebuild");  // the default

    WorldOptions grid;
    grid.build.structure = Structure::Grid;
    const std::unique_ptr<World> gridded = open_world(kDeforming, grid);
    gridded->commit();
    const UpdateStats u = gridded->set_time(t);
    EXPECT_TRUE(u.updated);
    EXPECT_EQ(gridded->stats().last_commit, CommitKind::Update);
    EXPECT_NE(gridded->stats().accel.name.find("grid"), std::string::npos) << gridded->stats().accel.name;
    expect_brute_force_hits(*gridded, 3, "grid rebuilt");
    // Asked to refit a grid: refused, one line.
    WorldOptions refit_grid = grid;
    refit_grid.update.method = UpdateMethod::Refit;
    try {
        (void)open_world(kDeforming, refit_grid);
        ADD_FAILURE() << "a refitted grid was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("rebuilt every frame"), std::string::npos) << e.what();
    }
}

// Mesh positions and instance transforms changed by the program: the
// triangles and the structure follow; a changed triangle count flattens
// and builds again; bad edits are one-line errors that leave the world usable.
TEST(World, GeometryReplacedMovesTrianglesAndStructure) {
    TestScene t;
    const uint32_t grey = t.add_material(diffuse(Vec3f(0.5f)));
    t.add_quad(Vec3f(0.0f), {1, 0, 0}, {0, 1, 0}, grey);
    t.add_box({0, 0, 2}, 0.5f, grey);
    t.finish(Structure::Bvh);
    World& world = *t.world;
    const Ray down{{0.0f, 0.0f, 10.0f}, 0.0f, {0, 0, -1}, kInfinity};
    EXPECT_NEAR(world.intersect(down).t, 7.5f, 1e-5f);  // the box's top at z = 2.5

    for (Vec3f& p : world.scene().meshes[1].positions) p.z += 1.0f;  // the box up by one
    GeometryChange moved;
    moved.meshes = {1};
    const UpdateStats u = world.geometry_replaced(moved);
    EXPECT_TRUE(u.updated);
    EXPECT_NEAR(world.intersect(down).t, 6.5f, 1e-5f);
    expect_brute_force_hits(world, 5, "box moved");

    world.scene().instances[0].transform = Affine3f::translation({0, 0, -1});  // the quad down by one
    EXPECT_TRUE(world.geometry_replaced(GeometryChange{{}, {0}, false}).updated);
    const Ray low{{3.0f, 3.0f, 10.0f}, 0.0f, {0, 0, -1}, kInfinity};
    EXPECT_FALSE(world.intersect(low).found());
    world.scene().meshes[0].positions = {{-4, -4, 0}, {4, -4, 0}, {4, 4, 0}, {-4, 4, 0}};
    EXPECT_TRUE(world.geometry_replaced(GeometryChange{{0}, {}, false}).updated);
    EXPECT_NEAR(world.intersect(low).t, 11.0f, 1e-5f);

    // A triangle more: flattened again.
    Mesh& quad = world.scene().meshes[0];
    quad.positions.push_back({0, 0, 3});
    quad.indices.insert(quad.indices.end(), {0, 1, 4});
    quad.material_ids.push_back(grey);
    const size_t before = world.geometry().size();
    EXPECT_TRUE(world.geometry_replaced(GeometryChange{{0}, {}, false}).updated);
    EXPECT_EQ(world.geometry().size(), before + 1);
    EXPECT_EQ(world.stats().last_commit, CommitKind::Build);
    expect_brute_force_hits(world, 6, "a triangle added");

    // Material ids changed in place: the triangles' materials follow.
    const uint32_t red = uint32_t(world.scene().materials.size());
    world.scene().materials.push_back(diffuse({0.8f, 0.1f, 0.1f}));
    world.scene().meshes[1].material_ids.assign(world.scene().meshes[1].material_ids.size(), red);
    world.materials_changed();
    EXPECT_EQ(world.geometry().material[world.intersect(down).prim], red);
    world.scene().meshes[1].material_ids.push_back(red);  // one id too many: an error, nothing written
    EXPECT_THROW(world.materials_changed(), Error);
    world.scene().meshes[1].material_ids.pop_back();

    EXPECT_THROW(world.geometry_replaced(GeometryChange{{9}, {}, false}), Error);
    world.scene().meshes[1].positions[0].x = std::nanf("");
    try {
        world.geometry_replaced(GeometryChange{{1}, {}, false});
        ADD_FAILURE() << "a NaN position was accepted";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
    }
    world.scene().meshes[1].positions[0].x = -0.5f;
    expect_brute_force_hits(world, 7, "after a refused edit");
}

// A renderer outlives its World: it shares the world's state and keeps
// rendering its last frame.
TEST(World, RendererOutlivesItsWorld) {
    std::unique_ptr<World> world = open_world("builtin:cornell");
    const Camera camera = world->camera();
    const RenderOptions o = small_options();
    const std::unique_ptr<Renderer> renderer = make_renderer(*world, camera, o);
    const Image before = render(*world, camera, o);
    world.reset();
    render_progressive(*renderer);
    EXPECT_EQ(renderer->image().pixels, before.pixels);
}

// Reopened with other options, a world keeps its scene as it is now (the
// time, the edits) and renders the same image with another structure.
TEST(World, ReopenKeepsTheSceneAtItsTime) {
    const std::unique_ptr<World> world = open_world(kAnimated, with_method(UpdateMethod::Refit));
    world->set_time(world->time_range().frame_time(25));
    world->scene().lights.clear();
    WorldOptions other;
    other.build.builder = Builder::Sbvh;
    other.build.layout = Layout::Bvh2;
    const std::unique_ptr<World> reopened = world->reopen(other);
    EXPECT_EQ(reopened->time(), world->time());
    EXPECT_TRUE(reopened->scene().lights.empty());
    EXPECT_EQ(reopened->accel().stats().name, "rebuild/sbvh/bvh2");  // animated: the default update method
    const RenderOptions o = small_options();
    EXPECT_EQ(render(*reopened, world->camera(), o).pixels, render(*world, world->camera(), o).pixels);
}

// Device-resident batches need a world on a CUDA device: on the CPU they are
// one clear error (tests/gpu/device_batch_test.cpp checks them on a device).
TEST(World, DeviceBatchesOnTheCpuAreOneError) {
    const std::unique_ptr<World> world = open_world("builtin:cornell");
    Ray ray{Vec3f(0.0f, 1.0f, 3.0f), 0.0f, Vec3f(0.0f, 0.0f, -1.0f), kInfinity};
    Hit hit;
    uint8_t blocked = 0;
    try {
        world->intersect_on_device(&ray, &hit, 1);
        ADD_FAILURE() << "a CPU world traced device rays";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("runs on the CPU"), std::string::npos) << e.what();
    }
    EXPECT_THROW(world->occluded_on_device(&ray, &blocked, 1), Error);
}

TEST(World, PagedWorldRendersFromItsFile) {
    const std::string path = test::temp_dir("world_paged") + "/cornell.rfpack";
    Scene cornell = load_scene("builtin:cornell");
    (void)convert_to_paged(cornell, path);
    WorldOptions options;
    options.paged.memory_budget = size_t(8) << 20;
    const std::unique_ptr<World> world = open_world(path, options);
    EXPECT_TRUE(world->paged());
    EXPECT_FALSE(world->animated());
    EXPECT_EQ(world->stats().last_commit, CommitKind::None);  // its structure came with the file
    EXPECT_EQ(world->stats().triangles, world->paged_scene().info().triangles);
    EXPECT_EQ(world->accel().stats().name, "paged/bvh");
    EXPECT_TRUE(world->geometry().triangles.empty());
    EXPECT_FALSE(world->set_time(1.0f).updated);
    EXPECT_THROW(world->geometry_replaced(GeometryChange{{0}, {}, false}), Error);
    const Image image = render(*world, world->camera(), small_options(IntegratorKind::Whitted));
    double sum = 0.0;
    for (const Vec3f& p : image.pixels) sum += p.x + p.y + p.z;
    EXPECT_GT(sum, 0.0);
}

// The device rules, decided in one place and checked without a device.
TEST(WorldRules, WhatADeviceCannotDoIsRefusedWhenAskedAndReplacedWhenDefault) {
    WorldOptions cuda;
    cuda.device = parse_device("cuda:0");
    // Asked for: refused, whatever the scene.
    for (UpdateMethod method : {UpdateMethod::Adapt, UpdateMethod::Clusters}) {
        WorldOptions asked = cuda;
        asked.update.method = method;
        EXPECT_THROW((void)plan_world(asked, WorldKind::Still, std::nullopt), Error) << to_string(method);
    }
    // The scene file's own: rebuild, with a note.
    const WorldPlan plan = plan_world(cuda, WorldKind::Animated, std::string("adapt"));
    EXPECT_EQ(*plan.update.method, UpdateMethod::Rebuild);
    ASSERT_EQ(plan.notes.size(), 1u);
    EXPECT_NE(plan.notes[0].find("adapt runs on the CPU only"), std::string::npos) << plan.notes[0];
    // The CPU runs every method as the file says, without a note.
    const WorldPlan cpu = plan_world(WorldOptions{}, WorldKind::Animated, std::string("adapt"));
    EXPECT_EQ(*cpu.update.method, UpdateMethod::Adapt);
    EXPECT_TRUE(cpu.notes.empty());
    EXPECT_TRUE(cpu.dynamic_bvh);
    // Nobody asked: the default.
    EXPECT_EQ(*plan_world(WorldOptions{}, WorldKind::Animated, std::nullopt).update.method, kDefaultUpdateMethod);
    // Paged scenes render on the CPU.
    EXPECT_THROW((void)plan_world(cuda, WorldKind::Paged, std::nullopt), Error);
    EXPECT_NO_THROW((void)plan_world(WorldOptions{}, WorldKind::Paged, std::nullopt));
    // The device is named once.
    WorldOptions twice;
    twice.build.device = parse_device("cuda:1");
    EXPECT_THROW((void)plan_world(twice, WorldKind::Still, std::nullopt), Error);
    // An unknown scene method is the file's error.
    EXPECT_THROW((void)plan_world(WorldOptions{}, WorldKind::Animated, std::string("sideways")), Error);
}

TEST(WorldRules, OnACudaDeviceTheStructureAndTheKernelAgree) {
    BuildOptions b;
    b.device = parse_device("cuda:0");
    EXPECT_EQ(with_device_structure(b).structure, Structure::Bvh);  // both default
    b.gpu_kernel = GpuKernel::Grid;
    EXPECT_EQ(with_device_structure(b).structure, Structure::Grid);  // the kernel decides the default structure
    b = BuildOptions{};
    b.device = parse_device("cuda:0");
    b.structure = Structure::KdTree;
    EXPECT_EQ(with_device_structure(b).gpu_kernel, GpuKernel::KdShortStack);  // the structure decides the default kernel
    b.structure = Structure::ProximityGrid;
    EXPECT_EQ(with_device_structure(b).gpu_kernel, GpuKernel::ProximityGrid);
    b.gpu_kernel = GpuKernel::KdRestart;
    EXPECT_THROW((void)with_device_structure(b), Error);  // both chosen, disagreeing
    b = BuildOptions{};
    b.device = parse_device("cuda:0");
    b.structure = Structure::BruteForce;
    EXPECT_THROW((void)with_device_structure(b), Error);
    b.device = Device{};
    EXPECT_EQ(with_device_structure(b).structure, Structure::BruteForce);  // the CPU ignores the kernel
}

// The threading contract: a render thread runs passes while another thread
// moves the world; set_time waits for a pass in flight and every pass sees
// one whole frame. At the end the renderer draws what a fresh one draws.
TEST(WorldThreads, RenderThreadAndUpdatingThread) {
    const std::unique_ptr<World> world = open_world(kAnimated, with_method(UpdateMethod::Refit));
    const Camera camera = world->camera();
    RenderOptions o = small_options();
    o.threads = 1;
    const std::unique_ptr<Renderer> renderer = make_renderer(*world, camera, o);
    std::atomic<bool> done{false};
    std::atomic<int> passes{0};
    std::thread render_thread([&] {
        while (!done.load()) {
            renderer->render_pass();
            passes.fetch_add(1);
        }
    });
    const TimeRange range = world->time_range();
    for (int frame = 1; frame <= 12; ++frame) {
        EXPECT_TRUE(world->set_time(range.frame_time(frame)).updated);
        std::vector<Hit> hits(64);
        world->intersect(test::make_rays(world->geometry(), 64, uint32_t(frame)), hits);  // queries meanwhile
    }
    while (passes.load() < 3) std::this_thread::yield();
    done = true;
    render_thread.join();
    renderer->render_pass();
    const std::unique_ptr<Renderer> fresh = make_renderer(*world, camera, o);
    while (fresh->passes() < renderer->passes()) fresh->render_pass();  // the same passes of the last frame
    EXPECT_EQ(renderer->image().pixels, fresh->image().pixels);
}

// Changing the world from inside one of its passes (a progress callback, on
// whichever of the pass's threads it runs) would wait for itself: it is an
// error instead, and a query from there is answered. Between passes the
// world is free.
TEST(WorldThreads, ChangingTheWorldFromInsideAPassIsAnError) {
    const std::unique_ptr<World> world = open_world(kAnimated);
    RenderOptions o = small_options();
    o.spp = 2;
    const std::unique_ptr<Renderer> renderer = make_renderer(*world, world->camera(), o);
    bool refused = false;
    renderer->render_pass([&](double) {
        if (refused) return;
        try {
            world->set_time(0.5f);
        } catch (const Error& e) {
            refused = std::string(e.what()).find("inside a render pass") != std::string::npos;
        }
    });
    EXPECT_TRUE(refused);
    std::vector<Hit> hits(4);  // (progress callbacks run one at a time: core/progress.h)
    renderer->render_pass([&](double) { world->intersect(test::make_rays(world->geometry(), 4, 1), hits); });
    int moved = 0;
    renderer->set_camera(world->camera());  // restarted: render_progressive has passes to run
    render_progressive(*renderer, [&](const Renderer&) {  // between passes
        moved += world->set_time(0.1f * float(moved + 1)).updated ? 1 : 0;
        return moved < 3;  // every move restarts the renderer: stop after three
    });
    EXPECT_EQ(moved, 3);
}

}  // namespace
}  // namespace rf
