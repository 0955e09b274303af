// Wall time for the apps' own timers (the CLI's summary lines, the viewer's
// load and job times).
#pragma once

#include <chrono>

namespace rf {

// Milliseconds since `start` on the steady clock.
inline double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace rf
