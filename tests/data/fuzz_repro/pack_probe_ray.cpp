// Reproducer (not built by the project): traces one ray through a paged
// scene with the public API, for the fuzz_pack findings on rays
// (docs/robustness.md). Build it against the fuzz build's libraries, e.g.
//   cd build-fuzz && clang++ -std=c++20 -fsanitize=address,undefined -fsanitize=fuzzer-no-link \
//     -DRAYFORGE_ASSERTIONS=1 -I../include -I../src ../tests/data/fuzz_repro/pack_probe_ray.cpp \
//     librayforge_fuzz_lib.a librayforge_fuzz_pack_lib.a librayforge_fuzz_lib.a librayforge_fuzz_third_party.a \
//     -lz -ljpeg -ltbb -lzstd -o pack_probe_ray
//   tail -c +2 ../tests/fuzz/pack/triangles-raw.bin > /tmp/t.rfpack   # the seed without its mode byte
//   ./pack_probe_ray /tmp/t.rfpack 0.5 0.5 0.25  1e-39 0 0  0 inf     # never returns (grid walk)
//   ./pack_probe_ray /tmp/t.rfpack nan 0 5  0 0 -1  0 3e38            # UBSan: NaN converted to int (start_cell)
// Arguments: FILE ox oy oz dx dy dz tmin tmax.
#include <cstdio>
#include <cstdlib>

#include "rayforge/ooc/paged_scene.h"

int main(int argc, char** argv) {
    if (argc != 10) {
        std::fprintf(stderr, "usage: %s FILE ox oy oz dx dy dz tmin tmax\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, nullptr, _IONBF, 0);
    rf::PagedSceneOptions options;
    options.memory_budget = size_t(1) << 20;
    options.threads = 1;
    const auto scene = rf::open_paged_scene(argv[1], options);
    const auto f = [&](int i) { return std::strtof(argv[i], nullptr); };
    rf::Ray ray;
    ray.org = {f(2), f(3), f(4)};
    ray.dir = {f(5), f(6), f(7)};
    ray.tmin = f(8);
    ray.tmax = f(9);
    const rf::Hit hit = scene->accel().intersect(ray);
    std::printf("closest: t %g prim %u\n", hit.t, hit.prim);
    std::printf("occluded: %d\n", int(scene->accel().occluded(ray)));
    return 0;
}
