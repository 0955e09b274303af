// Progress of long work (builds, render passes), reported as a fraction.
#pragma once

#include <functional>

namespace rf {

// Called from one thread at a time with the fraction done (0..1), never
// decreasing within one piece of work.
using ProgressCallback = std::function<void(double fraction)>;

}  // namespace rf
