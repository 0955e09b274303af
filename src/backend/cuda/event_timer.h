// Two CUDA events around device work on the default stream: the bench's
// launch timings and the builders' per-stage times. Destroyed on every path.
#pragma once

#include <cuda_runtime.h>

#include "backend/cuda/cuda_check.h"

namespace rf::cuda {

class EventTimer {
public:
    EventTimer() {
        RF_CUDA_CHECK(cudaEventCreate(&start_));
        const cudaError_t status = cudaEventCreate(&stop_);
        if (status != cudaSuccess) {
            cudaEventDestroy(start_);
            throw_cuda_error(status, "cudaEventCreate(&stop_)", __FILE__, __LINE__);
        }
    }
    ~EventTimer() {
        cudaEventDestroy(start_);
        cudaEventDestroy(stop_);
    }
    EventTimer(const EventTimer&) = delete;
    EventTimer& operator=(const EventTimer&) = delete;

    void start() { RF_CUDA_CHECK(cudaEventRecord(start_)); }
    // Waits for the work since start() (launch errors surface here) and
    // returns its milliseconds.
    double stop_ms() {
        RF_CUDA_CHECK(cudaGetLastError());
        RF_CUDA_CHECK(cudaEventRecord(stop_));
        RF_CUDA_CHECK(cudaEventSynchronize(stop_));
        float ms = 0.0f;
        RF_CUDA_CHECK(cudaEventElapsedTime(&ms, start_, stop_));
        return double(ms);
    }

private:
    cudaEvent_t start_ = nullptr, stop_ = nullptr;
};

// One untimed event on the default stream: the host waits on it for the
// work enqueued before record() (an asynchronous copy landing) and no more.
class StreamEvent {
public:
    StreamEvent() { RF_CUDA_CHECK(cudaEventCreateWithFlags(&event_, cudaEventDisableTiming)); }
    ~StreamEvent() { cudaEventDestroy(event_); }
    StreamEvent(const StreamEvent&) = delete;
    StreamEvent& operator=(const StreamEvent&) = delete;

    void record() { RF_CUDA_CHECK(cudaEventRecord(event_)); }
    void synchronize() { RF_CUDA_CHECK(cudaEventSynchronize(event_)); }

private:
    cudaEvent_t event_ = nullptr;
};

}  // namespace rf::cuda
