// The bookkeeping of one device build, handed to each of its stages: the
// meter of its live device buffers (stages.peak_device_bytes is the
// meter's peak), the CUDA-event timer of its stages, and the stage times
// they fill.
#pragma once

#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/event_timer.h"

namespace rf::cuda {

struct DeviceBvh;

struct BuildContext {
    explicit BuildContext(DeviceBuildStages& build_stages) : stages(build_stages) {}
    MemoryMeter meter;
    EventTimer timer;
    DeviceBuildStages& stages;
    // Set: the device emission leaves the canonical BVH here (device_bvh.h)
    // instead of downloading it.
    DeviceBvh* resident = nullptr;
};

}  // namespace rf::cuda
