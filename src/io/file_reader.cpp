#include "io/file_reader.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <system_error>

#include "rayforge/core/error.h"

namespace rf::io {

std::string read_file(const std::string& path) {
    std::error_code ec;
    auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) throw file_error(path, 0, "file not found");
    if (!std::filesystem::is_regular_file(status)) throw file_error(path, 0, "not a regular file");

    std::unique_ptr<FILE, int (*)(FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
    if (!file) throw file_error(path, 0, std::string("cannot open: ") + std::strerror(errno));
    // The size comes from the open file, so a file that changes underneath is caught by the read.
    if (std::fseek(file.get(), 0, SEEK_END) != 0) throw file_error(path, 0, "cannot seek");
    long size = std::ftell(file.get());
    if (size < 0) throw file_error(path, 0, "cannot tell size");
    std::rewind(file.get());

    std::string bytes(size_t(size), '\0');
    if (size > 0 && std::fread(bytes.data(), 1, bytes.size(), file.get()) != bytes.size())
        throw file_error(path, 0, "read failed");
    return bytes;
}

}  // namespace rf::io
