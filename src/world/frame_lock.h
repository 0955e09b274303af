// The lock a world's frame is held by: shared by render passes and query
// batches, exclusive for what changes the frame (set_time, commits, edits).
// A waiting writer goes before new readers: a render thread that starts
// pass after pass would otherwise keep set_time waiting for ever (glibc's
// rwlock, behind std::shared_mutex, prefers readers).
#pragma once

#include <condition_variable>
#include <mutex>

namespace rf {

class FrameLock {
public:
    void lock_shared() {
        std::unique_lock<std::mutex> lock(mutex_);
        changed_.wait(lock, [&] { return !writing_ && waiting_writers_ == 0; });
        ++readers_;
    }
    void unlock_shared() {
        std::lock_guard<std::mutex> lock(mutex_);
        if (--readers_ == 0) changed_.notify_all();
    }
    void lock() {
        std::unique_lock<std::mutex> lock(mutex_);
        ++waiting_writers_;
        changed_.wait(lock, [&] { return !writing_ && readers_ == 0; });
        --waiting_writers_;
        writing_ = true;
    }
    void unlock() {
        std::lock_guard<std::mutex> lock(mutex_);
        writing_ = false;
        changed_.notify_all();
    }

private:
    std::mutex mutex_;
    std::condition_variable changed_;
    int readers_ = 0;
    int waiting_writers_ = 0;
    bool writing_ = false;
};

}  // namespace rf
