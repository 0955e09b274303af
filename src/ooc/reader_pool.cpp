#include "ooc/reader_pool.h"

#include <cstdlib>

namespace rf::pack {

ReaderPool& ReaderPool::shared() {
    static ReaderPool pool([] {
        const char* text = std::getenv("RAYFORGE_PAGE_READERS");
        const long n = text ? std::strtol(text, nullptr, 10) : 0;
        return n >= 1 && n <= 256 ? int(n) : kReaderThreads;
    }());
    return pool;
}

ReaderPool::ReaderPool(int threads) {
    threads_.reserve(size_t(threads));
    for (int t = 0; t < threads; ++t) threads_.emplace_back([this] { serve(); });
}

ReaderPool::~ReaderPool() {
    {
        const std::lock_guard<std::mutex> lock(mutex_);
        stopping_ = true;
    }
    work_.notify_all();
    for (std::thread& t : threads_) t.join();
}

void ReaderPool::run(size_t count, const std::function<void(size_t)>& task) {
    if (count == 0) return;
    const std::lock_guard<std::mutex> one_run(run_mutex_);
    std::unique_lock<std::mutex> lock(mutex_);
    task_ = &task;
    count_ = count;
    next_ = finished_ = 0;
    ++generation_;
    // As many readers as there are reads (a swap of two pages wakes two, not all).
    const size_t wake = count < threads_.size() ? count : threads_.size();
    for (size_t i = 0; i < wake; ++i) work_.notify_one();
    done_.wait(lock, [&] { return finished_ == count_; });
    task_ = nullptr;
}

// A reader: waits for a run, takes indices until none is left, then waits
// for the next run.
void ReaderPool::serve() {
    unsigned seen = 0;
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
        work_.wait(lock, [&] { return stopping_ || (generation_ != seen && next_ < count_); });
        if (stopping_) return;
        seen = generation_;
        while (next_ < count_) {
            const size_t i = next_++;
            const std::function<void(size_t)>& task = *task_;
            lock.unlock();
            task(i);
            lock.lock();
            if (++finished_ == count_) done_.notify_one();
        }
    }
}

}  // namespace rf::pack
