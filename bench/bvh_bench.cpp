// Micro-benchmarks of the binned SAH builder and BVH closest-hit traversal on
// procedural scenes (the full protocol over real scenes is `rayforge bench`).
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/bvh_accel.h"
#include "rayforge/accel/accel.h"

namespace {

rf::Vec3f random_unit(std::mt19937& rng) {
    std::normal_distribution<float> n(0.0f, 1.0f);
    for (;;) {
        const rf::Vec3f d(n(rng), n(rng), n(rng));
        if (rf::length_squared(d) > 1e-6f) return rf::normalize(d);
    }
}

// About `count` small triangles scattered in a 100^3 box.
const rf::SceneGeometry& soup(size_t count) {
    static rf::SceneGeometry g = [count] {
        rf::SceneGeometry geometry;
        std::mt19937 rng(1);
        std::uniform_real_distribution<float> u(0.0f, 100.0f);
        for (size_t i = 0; i < count; ++i) {
            const rf::Vec3f c(u(rng), u(rng), u(rng));
            const rf::Triangle t{c + random_unit(rng) * 0.3f, c + random_unit(rng) * 0.3f, c + random_unit(rng) * 0.3f};
            geometry.triangles.push_back(t);
            geometry.bounds.extend(t.bounds());
        }
        return geometry;
    }();
    return g;
}

// A UV sphere of radius 10 with about `count` triangles.
const rf::SceneGeometry& sphere(size_t count) {
    static rf::SceneGeometry g = [count] {
        rf::SceneGeometry geometry;
        const int rings = static_cast<int>(std::sqrt(static_cast<double>(count) / 2.0));
        const int segments = 2 * rings;
        auto point = [&](int ring, int segment) {
            const float theta = 3.14159265f * static_cast<float>(ring) / static_cast<float>(rings);
            const float phi = 6.2831853f * static_cast<float>(segment) / static_cast<float>(segments);
            return rf::Vec3f(10.0f * std::sin(theta) * std::cos(phi), 10.0f * std::cos(theta),
                             10.0f * std::sin(theta) * std::sin(phi));
        };
        for (int r = 0; r < rings; ++r) {
            for (int s = 0; s < segments; ++s) {
                const rf::Vec3f a = point(r, s), b = point(r + 1, s), c = point(r + 1, s + 1), d = point(r, s + 1);
                for (const rf::Triangle& t : {rf::Triangle{a, b, c}, rf::Triangle{a, c, d}}) {
                    geometry.triangles.push_back(t);
                    geometry.bounds.extend(t.bounds());
                }
            }
        }
        return geometry;
    }();
    return g;
}

constexpr size_t kMillion = 1000000;

void report_build(benchmark::State& state, const rf::SceneGeometry& g) {
    const rf::BuildOptions options{.threads = static_cast<int>(state.range(0))};
    double sah = 0.0;
    for (auto _ : state) {
        const rf::Bvh bvh = rf::build_bvh(g.triangles, options);  // binned SAH, the default
        benchmark::DoNotOptimize(bvh.nodes.data());
        state.PauseTiming();
        sah = bvh.sah_cost();
        state.ResumeTiming();
    }
    state.counters["sah"] = sah;
    state.counters["Mtris/s"] = benchmark::Counter(static_cast<double>(g.size() * state.iterations()) / 1e6,
                                                   benchmark::Counter::kIsRate);
}

void BM_BinnedSahBuild_Soup1M(benchmark::State& state) { report_build(state, soup(kMillion)); }
void BM_BinnedSahBuild_Sphere1M(benchmark::State& state) { report_build(state, sphere(kMillion)); }
BENCHMARK(BM_BinnedSahBuild_Soup1M)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_BinnedSahBuild_Sphere1M)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

// Single-threaded closest hits for rays between random points of the soup's box.
void BM_ClosestHit_Soup1M(benchmark::State& state) {
    const rf::SceneGeometry& g = soup(kMillion);
    const rf::BvhAccel accel(g, rf::build_bvh(g.triangles, rf::BuildOptions{}), "bvh/binned/bvh2", 0.0);
    std::mt19937 rng(2);
    std::uniform_real_distribution<float> u(0.0f, 100.0f);
    std::vector<rf::Ray> rays(1 << 16);
    for (rf::Ray& ray : rays) {
        ray.org = rf::Vec3f(u(rng), u(rng), u(rng));
        ray.dir = random_unit(rng);
    }
    size_t i = 0, hits = 0;
    for (auto _ : state) {
        hits += accel.intersect(rays[i]).found();
        i = (i + 1) & (rays.size() - 1);
    }
    state.counters["Mrays/s"] = benchmark::Counter(static_cast<double>(state.iterations()) / 1e6,
                                                   benchmark::Counter::kIsRate);
    state.counters["hit_rate"] = static_cast<double>(hits) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_ClosestHit_Soup1M);

}  // namespace
