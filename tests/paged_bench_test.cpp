// `rayforge bench --paged` (bench/harness/paged_bench.h): on a small paged
// scene, every (budget, workload) row exists, both budgets trace the same
// rays, the paged answers equal the in-core ones within the quantisation,
// the fully cached warm runs read nothing and a tenth of the scene reads
// pages; and the command prints its table.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <sstream>
#include <string>

#include "cli_runner.h"
#include "paged_bench.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "test_paths.h"

namespace rf {
namespace {

const char* const kWorkloads[] = {"primary", "shadow", "diffuse1", "diffuse2", "diffuse3", "path"};

struct SpheresPack {
    std::string path;
    Light sun;
};

// builtin:spheres, paged in pages of 256 quads (hundreds of pages).
const SpheresPack& spheres_pack() {
    static const SpheresPack pack = [] {
        Scene scene = make_builtin_scene("spheres");
        scene.finalize();
        PagedWriteOptions options;
        options.quads_per_page = 256;
        options.flatten_instances = true;  // hundreds of pages
        SpheresPack p;
        p.path = test::temp_dir("paged_bench") + "/spheres.rfpack";
        convert_to_paged(scene, p.path, options);
        p.sun = scene.lights.at(0);
        return p;
    }();
    return pack;
}

const bench::PagedBenchRow* find_row(const bench::PagedFileResult& result, double budget, const std::string& workload) {
    for (const bench::PagedBenchRow& r : result.rows)
        if (r.budget == budget && r.workload == workload) return &r;
    return nullptr;
}

uint64_t bytes_read(const bench::PagedRunFigures& run) {
    uint64_t bytes = 0;
    for (const bench::PagedCacheFigures& c : run.caches) bytes += c.bytes_read;
    return bytes;
}

TEST(PagedBench, RowsAgreeWithInCoreAndReadOnlyWhenTheCacheIsShort) {
    bench::PagedBenchConfig config;
    config.budgets = {1.0, 0.1};
    config.width = 64;
    config.height = 48;
    config.repetitions = 1;
    config.passes = 2;
    config.light = spheres_pack().sun;
    std::ostringstream log;
    const bench::PagedFileResult result = bench::run_paged_bench(spheres_pack().path, config, log);

    ASSERT_EQ(result.rows.size(), 2 * std::size(kWorkloads));
    ASSERT_EQ(result.summary.budgets.size(), 2u);
    EXPECT_GT(result.summary.info.geometry_pages, 100u);
    uint64_t short_cache_bytes = 0;
    for (const char* workload : kWorkloads) {
        const bench::PagedBenchRow* full = find_row(result, 1.0, workload);
        const bench::PagedBenchRow* tenth = find_row(result, 0.1, workload);
        ASSERT_TRUE(full && tenth) << workload;
        EXPECT_GT(full->rays, 0u) << workload;
        EXPECT_EQ(full->rays, tenth->rays) << workload;
        EXPECT_GT(bytes_read(full->cold), 0u) << workload;
        short_cache_bytes += bytes_read(tenth->warm);
        // (A path-tracing pass samples new directions: its second pass may still read.)
        if (std::string(workload) == "path") continue;
        EXPECT_EQ(bytes_read(full->warm), 0u) << workload << ": everything was cached after the warm-up";
        for (const bench::PagedBenchRow* r : {full, tenth}) {
            const double tolerance = 0.005 * double(r->in_core_hits) + 1.0;
            EXPECT_NEAR(double(r->paged_hits), double(r->in_core_hits), tolerance) << workload << " at " << r->budget;
            EXPECT_GT(r->agreement, 0.99) << workload << " at " << r->budget;
            EXPECT_GT(r->slowdown, 0.0) << workload;
        }
    }
    EXPECT_GT(short_cache_bytes, 0u) << "a tenth of the scene must read pages again";
    // f = 1 holds every page; 0.1 about a tenth of them.
    for (const bench::PagedCacheFigures& m : result.summary.budgets[0].second) EXPECT_EQ(m.slots, m.pages) << m.name;
    const bench::PagedCacheFigures& geometry = result.summary.budgets[1].second[0];
    EXPECT_NEAR(double(geometry.slots), 0.1 * double(geometry.pages), 1.0);
}

TEST(PagedBench, CliPrintsTheTable) {
    const std::string path = spheres_pack().path;
    const test::CliResult run =
        test::run_cli("bench --paged " + path + " --res 32x24 --budgets 1,0.1 --passes 2 -q");
    ASSERT_EQ(run.exit_code, 0) << run.err;
    // builtin:spheres has a light: the shadow set aims at it.
    EXPECT_NE(run.out.find("shadow set: "), std::string::npos);
    EXPECT_EQ(run.out.find("shadow set: none"), std::string::npos);
    EXPECT_NE(run.out.find("shadow "), std::string::npos);
    EXPECT_NE(run.out.find("machine: "), std::string::npos);
    EXPECT_NE(run.out.find("command: rayforge bench --paged"), std::string::npos);
    EXPECT_NE(run.out.find("workload"), std::string::npos);
    for (const char* workload : {"primary", "diffuse3", "path"}) EXPECT_NE(run.out.find(workload), std::string::npos);
    EXPECT_TRUE(run.err.empty()) << run.err;
    const test::CliResult lit = test::run_cli("bench --paged " + path +
                                              " --res 16x12 --budgets 1/2 --passes 2 --reps 1 --light-dir=-0.4,-1,-0.3 -q");
    ASSERT_EQ(lit.exit_code, 0) << lit.err;
    EXPECT_NE(lit.out.find("\nshadow "), std::string::npos) << lit.out;
    const test::CliResult bad = test::run_cli("bench --paged " + path + " --budgets 2");
    EXPECT_EQ(bad.exit_code, 1);
    EXPECT_NE(bad.err.find("--budgets"), std::string::npos);
}

}  // namespace
}  // namespace rf
