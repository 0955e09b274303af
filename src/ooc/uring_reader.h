// Page reads through io_uring (Linux 5.1+, Debian's liburing): a swap's
// reads are submitted together and kept up to kQueueDepth in flight from
// one thread, without a thread per read; the checksums and codecs run on
// the reader pool (reader_pool.h) as the reads complete. Used when
// RAYFORGE_PAGE_IO=uring is set: on the 2-core development machine, with
// the pages in the OS cache and decoding the larger cost, the reader pool
// doing its own preads was 7-16 % faster (docs/paged-scenes.md), so it is
// the default. Where io_uring is asked for but refused (built without
// liburing, a kernel or seccomp policy that says no: io_uring_queue_init
// fails) the reader pool reads, and describe() says why.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
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
    // A reader of its own; nullptr, with the reason in `why`, where io_uring is refused.
    static std::unique_ptr<UringReader> create(std::string& why);
    // "io_uring (queue depth 64)" or "reader pool (N threads): why not io_uring".
    static std::string describe();

    ~UringReader();
    UringReader(const UringReader&) = delete;
    UringReader& operator=(const UringReader&) = delete;

    // Does every read (short reads continued), calling done(i) as read i
    // completes or fails (from the calling thread); one batch at a time.
    void read_all(std::span<Read> reads, const std::function<void(size_t)>& done = {});

private:
    UringReader() = default;
    struct Ring;
    Ring* ring_ = nullptr;
    std::mutex mutex_;
};

}  // namespace rf::pack
