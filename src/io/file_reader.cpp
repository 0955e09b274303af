#include "io/file_reader.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

#include "rayforge/core/error.h"

namespace rf::io {

namespace {

// Opens `path` for reading and returns its size; throws the loaders' one-line errors.
int open_regular_file(const std::string& path, size_t& size) {
    // O_NONBLOCK: opening a FIFO must not wait for a writer; fstat then rejects it.
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        if (errno == ENOENT) throw file_error(path, 0, "file not found");
        throw file_error(path, 0, std::string("cannot open: ") + std::strerror(errno));
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        throw file_error(path, 0, "not a regular file");
    }
    size = size_t(st.st_size);
    return fd;
}

}  // namespace

std::string read_file(const std::string& path) {
    size_t size = 0;
    int fd = open_regular_file(path, size);
    std::string bytes(size, '\0');
    size_t done = 0;
    while (done < size) {
        ssize_t n = ::read(fd, bytes.data() + done, size - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            ::close(fd);
            throw file_error(path, 0, "read failed");
        }
        done += size_t(n);
    }
    ::close(fd);
    return bytes;
}

MappedFile::MappedFile(const std::string& path) {
    int fd = open_regular_file(path, size_);
    if (size_ > 0) {
        void* map = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
        if (map != MAP_FAILED) data_ = static_cast<const char*>(map);
    }
    ::close(fd);
    if (size_ > 0 && data_ == nullptr) {
        fallback_ = read_file(path);
        data_ = fallback_.data();
        size_ = fallback_.size();
    }
}

MappedFile::~MappedFile() {
    if (data_ != nullptr && fallback_.empty()) ::munmap(const_cast<char*>(data_), size_);
}

}  // namespace rf::io
