// Progress of work counted in units from many threads (the references a
// builder places in leaves), forwarded to an rf::ProgressCallback as a
// fraction mapped into [from, to] of the caller's whole, in steps of at
// least 1% so a callback is not flooded. The fraction never exceeds `to`,
// even when more units arrive than expected (spatial splits add references).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <mutex>

#include "rayforge/core/progress.h"

namespace rf {

class ProgressMeter {
public:
    ProgressMeter(const ProgressCallback& callback, double expected_units, double from = 0.0, double to = 1.0)
        : callback_(callback), expected_(std::max(expected_units, 1.0)), from_(from), to_(to) {}

    // Thread-safe.
    void add(uint64_t units) {
        if (!callback_) return;
        const uint64_t done = done_.fetch_add(units, std::memory_order_relaxed) + units;
        const double fraction = from_ + (to_ - from_) * std::min(1.0, double(done) / expected_);
        if (fraction < reported_.load(std::memory_order_relaxed) + 0.01) return;
        std::lock_guard<std::mutex> lock(mutex_);
        if (fraction <= reported_.load(std::memory_order_relaxed)) return;
        reported_.store(fraction, std::memory_order_relaxed);
        callback_(fraction);
    }

    // Reports `to` (the work is done), once.
    void finish() {
        if (!callback_) return;
        std::lock_guard<std::mutex> lock(mutex_);
        if (reported_.load(std::memory_order_relaxed) >= to_) return;
        reported_.store(to_, std::memory_order_relaxed);
        callback_(to_);
    }

private:
    const ProgressCallback& callback_;
    double expected_, from_, to_;
    std::atomic<uint64_t> done_{0};
    std::atomic<double> reported_{-1.0};
    std::mutex mutex_;
};

}  // namespace rf
