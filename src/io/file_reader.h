// Reading a whole file into memory, with a one-line rf::Error when it cannot be.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace rf::io {

// The file's bytes. Throws rf::Error "path: reason" when the file is missing,
// is not a regular file, or cannot be read completely.
std::string read_file(const std::string& path);

// A read-only memory map of a whole file, for the large mesh files: no copy,
// and the pages are read ahead. Same errors as read_file.
class MappedFile {
public:
    explicit MappedFile(const std::string& path);
    ~MappedFile();
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;

    [[nodiscard]] std::string_view bytes() const { return {data_, size_}; }

private:
    const char* data_ = nullptr;
    size_t size_ = 0;
    std::string fallback_;  // used when mmap is not possible
};

}  // namespace rf::io
