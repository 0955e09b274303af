// Page reads with a real queue depth. A page manager's swap reads its
// admitted pages all at once; on the compute threads (two on this kind of
// machine) that keeps two reads in flight, and a disk answers random 4 KB
// reads about 3x faster with 32 in flight than with 2 (docs/paged-scenes.md).
// So the reads run on a process-wide pool of kReaderThreads threads that
// mostly wait on the disk: each takes the next read, does it (pread,
// checksum, decompression, checks: PackFile::read_page) and takes another.
// Where io_uring is used (uring_reader.h) the pool does only the checksums,
// decompression and checks of the pages io_uring read.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace rf::pack {

class ReaderPool {
public:
    static constexpr int kReaderThreads = 32;

    // The process's pool, its threads started on first use: kReaderThreads,
    // or RAYFORGE_PAGE_READERS (1..256) from the environment.
    static ReaderPool& shared();

    explicit ReaderPool(int threads);
    ~ReaderPool();
    ReaderPool(const ReaderPool&) = delete;
    ReaderPool& operator=(const ReaderPool&) = delete;

    // Calls task(i) for every i in [0, count), up to the pool's size at
    // once, and returns when all have returned. `task` must not throw. One
    // run at a time: concurrent callers wait their turn.
    void run(size_t count, const std::function<void(size_t)>& task);

    [[nodiscard]] size_t size() const { return threads_.size(); }

private:
    void serve();

    std::mutex run_mutex_;  // one run at a time
    std::mutex mutex_;
    std::condition_variable work_, done_;
    const std::function<void(size_t)>* task_ = nullptr;
    size_t count_ = 0, next_ = 0, finished_ = 0;
    unsigned generation_ = 0;
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

}  // namespace rf::pack
