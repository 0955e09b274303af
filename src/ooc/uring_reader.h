// Page reads through io_uring (Linux 5.1+, Debian's liburing): a swap's
// reads are submitted together and kept up to kQueueDepth in flight from
// the calling thread, without a thread per read; the checksums and codecs
// then run on the reader pool (reader_pool.h). Where io_uring is refused
// (built without liburing, a kernel or seccomp policy that says no:
// io_uring_queue_init fails) or RAYFORGE_PAGE_IO=pool is set, the reader
// pool does the reads itself (pread), as before.
#pragma once

#include <cstdint>
#include <mutex>
#include <span>
#include <string>

namespace rf::pack {

class UringReader {
public:
    static constexpr unsigned kQueueDepth = 64;

    // One read: `bytes` at `offset` of `fd` into `into`. error: 0, or the
    // errno of a failed read (EIO for a file that ends early).
    struct Read {
        int fd = -1;
        uint64_t offset = 0;
        uint32_t bytes = 0;
        uint8_t* into = nullptr;
        int error = 0;
    };

    // The process's reader, or nullptr where io_uring is not used (above).
    static UringReader* shared();
    // "io_uring (queue depth 64)" or "reader pool (N threads): WHY".
    static std::string describe();

    ~UringReader();
    UringReader(const UringReader&) = delete;
    UringReader& operator=(const UringReader&) = delete;

    // Does every read (short reads continued); one batch at a time.
    void read_all(std::span<Read> reads);

private:
    UringReader() = default;
    struct Ring;
    Ring* ring_ = nullptr;
    std::mutex mutex_;
};

}  // namespace rf::pack
