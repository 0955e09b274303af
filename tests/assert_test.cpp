// RF_ASSERT (core/assert.h): on where RAYFORGE_ASSERTIONS is defined (Debug
// and sanitizer builds, which CI runs), a broken invariant stops the process
// with FILE:LINE and the condition; off, it costs nothing and checks nothing.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "backend/cpu/cpu_wavefront.h"
#include "core/assert.h"
#include "render/light_set.h"

namespace rf {
namespace {

#if defined(RAYFORGE_ASSERTIONS)

TEST(Assertions, ABrokenInvariantAbortsNamingTheCondition) {
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    std::vector<uint32_t> queue(3), keys(2);
    EXPECT_DEATH(sort_queue_by_key(queue, keys), "assertion failed: queue.size\\(\\) == keys.size\\(\\)");
    const LightSet empty;
    float probability = 0.0f, u = 0.0f;
    EXPECT_DEATH((void)empty.select(0.5f, probability, u), "a light selected from an empty light set");
}

TEST(Assertions, AHeldInvariantPassesSilently) {
    std::vector<uint32_t> queue{2, 0, 1}, keys{3, 1, 2};
    sort_queue_by_key(queue, keys);
    EXPECT_EQ(queue, (std::vector<uint32_t>{0, 1, 2}));
    int evaluated = 0;
    RF_ASSERT(++evaluated == 1, "evaluated once");
    EXPECT_EQ(evaluated, 1);
}

#else

TEST(Assertions, OffInReleaseBuilds) {
    int evaluated = 0;
    RF_ASSERT(++evaluated == 1, "not evaluated when assertions are off");
    EXPECT_EQ(evaluated, 0);
}

#endif

}  // namespace
}  // namespace rf
