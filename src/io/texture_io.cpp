// Texture decoding: stb_image for the 8-bit formats and Radiance HDR,
// tinyexr for OpenEXR. The file is read into memory here so that both paths
// (files and glTF-embedded images) share one decoder.
#include <stb/stb_image.h>
#include <tinyexr.h>

#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <string>

#include "io/file_reader.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"

namespace rf {

namespace {

// Larger images are almost surely corrupt headers; 16K x 16K is already 1 GiB as float RGBA.
constexpr long long kMaxDimension = 32768;
constexpr long long kMaxTexels = 1ll << 28;

void check_dimensions(long long width, long long height, const std::string& name) {
    if (width <= 0 || height <= 0 || width > kMaxDimension || height > kMaxDimension || width * height > kMaxTexels)
        throw file_error(name, 0, "unsupported image size " + std::to_string(width) + "x" + std::to_string(height));
}

// The decoder's buffer and our copy of it, checked against the memory budget
// before the decoder allocates anything.
void check_budget(long long width, long long height, int channels, size_t bytes_per_channel,
                  const std::string& name) {
    checked_array_bytes("texture '" + name + "'", size_t(width) * size_t(height) * size_t(channels),
                        2 * bytes_per_channel);
}

// OpenEXR files start with the magic number 20000630 (little-endian).
bool is_exr(const unsigned char* data, size_t size) {
    return size >= 4 && data[0] == 0x76 && data[1] == 0x2f && data[2] == 0x31 && data[3] == 0x01;
}

std::string stb_reason() {
    const char* reason = stbi_failure_reason();
    return reason ? reason : "unknown error";
}

Texture decode_exr(const unsigned char* data, size_t size, const std::string& name) {
    // Read the header first so that an absurd data window is rejected before decoding.
    EXRVersion version;
    if (ParseEXRVersionFromMemory(&version, data, size) != TINYEXR_SUCCESS)
        throw file_error(name, 0, "cannot decode EXR: bad version header");
    if (version.multipart || version.non_image)
        throw file_error(name, 0, "cannot decode EXR: multi-part and deep images are not supported");
    EXRHeader header;
    InitEXRHeader(&header);
    const char* err = nullptr;
    if (ParseEXRHeaderFromMemory(&header, &version, data, size, &err) != TINYEXR_SUCCESS) {
        std::string reason = err ? err : "bad header";
        FreeEXRErrorMessage(err);
        throw file_error(name, 0, "cannot decode EXR: " + reason);
    }
    long long w = (long long)header.data_window.max_x - header.data_window.min_x + 1;
    long long h = (long long)header.data_window.max_y - header.data_window.min_y + 1;
    FreeEXRHeader(&header);
    check_dimensions(w, h, name);
    check_budget(w, h, 4, sizeof(float), name);  // tinyexr decodes to RGBA float

    float* rgba = nullptr;
    int width = 0, height = 0;
    err = nullptr;
    if (LoadEXRFromMemory(&rgba, &width, &height, data, size, &err) != TINYEXR_SUCCESS) {
        std::string reason = err ? err : "decode failed";
        FreeEXRErrorMessage(err);
        throw file_error(name, 0, "cannot decode EXR: " + reason);
    }
    std::unique_ptr<float, void (*)(void*)> owned(rgba, &std::free);
    check_dimensions(width, height, name);

    Texture tex;
    tex.name = name;
    tex.width = width;
    tex.height = height;
    tex.encoding = TextureEncoding::LinearFloat;
    const size_t texels = size_t(width) * size_t(height);
    bool opaque = true;
    for (size_t i = 0; i < texels && opaque; ++i) opaque = rgba[4 * i + 3] == 1.0f;
    // Drop an all-opaque alpha channel: environment maps are large.
    tex.channels = opaque ? 3 : 4;
    if (opaque) {
        tex.texels_f.resize(texels * 3);
        for (size_t i = 0; i < texels; ++i) std::memcpy(&tex.texels_f[3 * i], &rgba[4 * i], 3 * sizeof(float));
    } else {
        tex.texels_f.assign(rgba, rgba + texels * 4);
    }
    return tex;
}

Texture decode_stb(const unsigned char* data, size_t size, const std::string& name, TextureEncoding encoding8) {
    if (size > size_t(std::numeric_limits<int>::max())) throw file_error(name, 0, "image file too large");
    const int len = int(size);
    int width = 0, height = 0, channels = 0;
    if (!stbi_info_from_memory(data, len, &width, &height, &channels))
        throw file_error(name, 0, "cannot decode image: " + stb_reason());
    check_dimensions(width, height, name);
    check_budget(width, height, channels, stbi_is_hdr_from_memory(data, len) ? sizeof(float) : 1, name);

    Texture tex;
    tex.name = name;
    if (stbi_is_hdr_from_memory(data, len)) {
        std::unique_ptr<float, void (*)(void*)> pixels(
            stbi_loadf_from_memory(data, len, &width, &height, &channels, 0), &stbi_image_free);
        if (!pixels) throw file_error(name, 0, "cannot decode image: " + stb_reason());
        tex.encoding = TextureEncoding::LinearFloat;
        tex.texels_f.assign(pixels.get(), pixels.get() + size_t(width) * height * channels);
    } else {
        std::unique_ptr<unsigned char, void (*)(void*)> pixels(
            stbi_load_from_memory(data, len, &width, &height, &channels, 0), &stbi_image_free);
        if (!pixels) throw file_error(name, 0, "cannot decode image: " + stb_reason());
        tex.encoding = encoding8 == TextureEncoding::LinearFloat ? TextureEncoding::Linear8 : encoding8;
        tex.texels8.assign(pixels.get(), pixels.get() + size_t(width) * height * channels);
    }
    tex.width = width;
    tex.height = height;
    tex.channels = channels;
    return tex;
}

}  // namespace

Texture load_texture_from_memory(const unsigned char* data, size_t size, const std::string& name,
                                 TextureEncoding encoding8) {
    if (data == nullptr || size == 0) throw file_error(name, 0, "empty image data");
    if (is_exr(data, size)) return decode_exr(data, size, name);
    return decode_stb(data, size, name, encoding8);
}

Texture load_texture(const std::string& path, TextureEncoding encoding8) {
    std::string bytes = io::read_file(path);
    return load_texture_from_memory(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), path,
                                    encoding8);
}

}  // namespace rf
