#include "ooc/spill_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "rayforge/core/error.h"

namespace rf::pack {

namespace {
constexpr size_t kAppendBuffer = size_t(1) << 20;
}

SpillFile::SpillFile(const std::string& folder, const std::string& what) : what_(what) {
    std::string name = (folder.empty() ? std::string(".") : folder) + "/.rayforge-spill-XXXXXX";
    fd_ = ::mkstemp(name.data());
    if (fd_ < 0)
        throw Error("cannot create a scratch file for the " + what + " in '" + (folder.empty() ? "." : folder) +
                    "': " + std::strerror(errno) + " (--temp-dir picks another folder)");
    ::unlink(name.c_str());  // gone when closed, also after a crash
    buffer_.reserve(kAppendBuffer);
}

SpillFile::~SpillFile() {
    if (fd_ >= 0) ::close(fd_);
}

void SpillFile::append(const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    while (bytes > 0) {
        const size_t n = std::min(bytes, kAppendBuffer - buffer_.size());
        buffer_.insert(buffer_.end(), p, p + n);
        p += n;
        bytes -= n;
        if (buffer_.size() == kAppendBuffer) flush();
    }
}

void SpillFile::flush() {
    if (buffer_.empty()) return;
    write(size_, buffer_.data(), buffer_.size());
    buffer_.clear();
}

void SpillFile::read(uint64_t offset, void* data, size_t bytes) const {
    auto* p = static_cast<unsigned char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::pread(fd_, p, bytes, off_t(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw Error("reading the scratch file of the " + what_ + " failed: " +
                                (n < 0 ? std::strerror(errno) : "unexpected end"));
        p += n;
        offset += uint64_t(n);
        bytes -= size_t(n);
    }
}

void SpillFile::write(uint64_t offset, const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::pwrite(fd_, p, bytes, off_t(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw Error("writing the scratch file of the " + what_ + " failed: " +
                                (n < 0 ? std::strerror(errno) : "no space") + " (disk full? --temp-dir)");
        p += n;
        offset += uint64_t(n);
        size_ = std::max(size_, offset);
        bytes -= size_t(n);
    }
}

void SpillFile::resize(uint64_t bytes) {
    flush();
    if (::ftruncate(fd_, off_t(bytes)) != 0)
        throw Error("cannot size the scratch file of the " + what_ + ": " + std::strerror(errno));
    size_ = bytes;
}

SpillReader::SpillReader(const SpillFile& file, uint64_t begin, uint64_t end, size_t buffer_bytes)
    : file_(file), file_offset_(begin), end_(end), buffer_(buffer_bytes) {}

bool SpillReader::refill(size_t need) {
    const size_t left = filled_ - pos_;
    std::memmove(buffer_.data(), buffer_.data() + pos_, left);
    pos_ = 0;
    filled_ = left;
    const size_t n = size_t(std::min<uint64_t>(buffer_.size() - left, end_ - file_offset_));
    if (n > 0) file_.read(file_offset_, buffer_.data() + left, n);
    file_offset_ += n;
    filled_ += n;
    return filled_ >= need;
}

}  // namespace rf::pack
