#include "ooc/uring_reader.h"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "ooc/reader_pool.h"

#if RAYFORGE_HAS_URING
#include <liburing.h>
#endif

namespace rf::pack {

namespace {

// Why io_uring is not used ("" when it is).
std::string& refusal() {
    static std::string why;
    return why;
}

}  // namespace

#if RAYFORGE_HAS_URING

struct UringReader::Ring {
    io_uring ring;
};

std::unique_ptr<UringReader> UringReader::create(std::string& why) {
    auto* ring = new Ring;
    const int error = io_uring_queue_init(kQueueDepth, &ring->ring, 0);
    if (error < 0) {
        why = std::string("io_uring refused: ") + std::strerror(-error);
        delete ring;
        return nullptr;
    }
    std::unique_ptr<UringReader> reader(new UringReader);
    reader->ring_ = ring;
    return reader;
}

UringReader* UringReader::shared() {
    static UringReader* reader = []() -> UringReader* {
        const char* io = std::getenv("RAYFORGE_PAGE_IO");
        if (!io || std::strcmp(io, "uring") != 0) {
            refusal() = "the default; RAYFORGE_PAGE_IO=uring reads through io_uring";
            return nullptr;
        }
        return create(refusal()).release();  // lives as long as the process (reads may run from static destructors)
    }();
    return reader;
}

UringReader::~UringReader() {
    if (ring_) io_uring_queue_exit(&ring_->ring);
    delete ring_;
}

void UringReader::read_all(std::span<Read> reads, const std::function<void(size_t)>& done_with) {
    const std::lock_guard<std::mutex> lock(mutex_);
    io_uring& ring = ring_->ring;
    std::vector<uint32_t> done(reads.size(), 0);  // bytes read so far
    const auto finished = [&](size_t i) {
        if (done_with) done_with(i);
    };
    size_t next = 0, in_flight = 0;
    const auto submit = [&](size_t i) {
        io_uring_sqe* sqe = io_uring_get_sqe(&ring);
        if (!sqe) {  // (not expected: at most kQueueDepth are in flight) make room
            io_uring_submit(&ring);
            sqe = io_uring_get_sqe(&ring);
        }
        Read& r = reads[i];
        io_uring_prep_read(sqe, r.fd, r.into + done[i], r.bytes - done[i], r.offset + done[i]);
        io_uring_sqe_set_data64(sqe, i);
        ++in_flight;
    };
    for (Read& r : reads) r.error = 0;
    while (next < reads.size() || in_flight > 0) {
        while (next < reads.size() && in_flight < kQueueDepth) {
            if (reads[next].bytes == 0) {
                finished(next++);
                continue;
            }
            submit(next++);
        }
        if (in_flight == 0) break;
        int rc = io_uring_submit_and_wait(&ring, 1);
        if (rc < 0 && rc != -EINTR) {  // the ring failed as a whole: every read not finished fails
            for (size_t i = 0; i < reads.size(); ++i)
                if (reads[i].error == 0 && (i >= next || done[i] < reads[i].bytes)) {
                    reads[i].error = -rc;
                    finished(i);
                }
            return;
        }
        io_uring_cqe* cqe;
        unsigned head, seen = 0;
        io_uring_for_each_cqe(&ring, head, cqe) {
            ++seen;
            --in_flight;
            const size_t i = size_t(io_uring_cqe_get_data64(cqe));
            Read& r = reads[i];
            if (cqe->res < 0) {
                if (cqe->res == -EINTR || cqe->res == -EAGAIN) {
                    submit(i);
                } else {
                    r.error = -cqe->res;
                    finished(i);
                }
            } else if (cqe->res == 0) {
                r.error = EIO;  // the file ended before the page did
                finished(i);
            } else {
                done[i] += uint32_t(cqe->res);
                if (done[i] < r.bytes) submit(i);  // a short read: continue it
                else finished(i);
            }
        }
        io_uring_cq_advance(&ring, seen);
    }
}

#else  // built without liburing

struct UringReader::Ring {};

std::unique_ptr<UringReader> UringReader::create(std::string& why) {
    why = "built without liburing, so without io_uring";
    return nullptr;
}

UringReader* UringReader::shared() {
    if (refusal().empty()) (void)create(refusal());  // (only to say why)
    return nullptr;
}

UringReader::~UringReader() { delete ring_; }

void UringReader::read_all(std::span<Read>, const std::function<void(size_t)>&) {}

#endif

std::string UringReader::describe() {
    if (shared()) return "io_uring (queue depth " + std::to_string(kQueueDepth) + ")";
    return "reader pool (" + std::to_string(ReaderPool::shared().size()) + " threads): " + refusal();
}

}  // namespace rf::pack
