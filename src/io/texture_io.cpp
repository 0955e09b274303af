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
#include <string_view>
#include <vector>

#include "io/file_reader.h"
#include "io/jpeg_decode.h"
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

// tinyexr's C structs, freed on every path. tinyexr's own LoadEXRFromMemory
// leaks its header on most errors (found by fuzz_exr), so the decode below
// does the same steps with the header owned here.
struct ExrHeaderOwner {
    EXRHeader header;
    ExrHeaderOwner() { InitEXRHeader(&header); }
    ~ExrHeaderOwner() { FreeEXRHeader(&header); }  // also after a failed parse, which allocates too
    ExrHeaderOwner(const ExrHeaderOwner&) = delete;
    ExrHeaderOwner& operator=(const ExrHeaderOwner&) = delete;
};

struct ExrImageOwner {
    EXRImage image;
    bool loaded = false;  // a failed LoadEXRImageFromMemory has already freed what it allocated
    ExrImageOwner() { InitEXRImage(&image); }
    ~ExrImageOwner() {
        if (loaded) FreeEXRImage(&image);
    }
    ExrImageOwner(const ExrImageOwner&) = delete;
    ExrImageOwner& operator=(const ExrImageOwner&) = delete;
};

Error exr_error(const std::string& name, const char* err, const char* fallback) {
    std::string reason = err ? err : fallback;
    FreeEXRErrorMessage(err);
    return file_error(name, 0, "cannot decode EXR: " + reason);
}

// One decoded channel value; HALF channels were requested as FLOAT.
float exr_value(const unsigned char* channel, int pixel_type, size_t index) {
    if (pixel_type == TINYEXR_PIXELTYPE_UINT) {
        uint32_t v;
        std::memcpy(&v, channel + 4 * index, 4);
        return float(v);
    }
    float v;
    std::memcpy(&v, channel + 4 * index, 4);
    return v;
}

// tinyexr 1.0.1 assumes that the "tiles" attribute holds 9 bytes and
// "compression" at least 1 (asserts compiled out in release builds) and reads
// past shorter ones (found by fuzz_exr). The header's attributes are checked
// here first: name\0 type\0 uint32 size, data; a 0 byte ends the header.
bool exr_attribute_sizes_are_safe(const unsigned char* data, size_t size) {
    size_t pos = 8;  // magic number and version
    while (pos < size && data[pos] != 0) {
        std::string_view names[2];
        for (std::string_view& field : names) {
            const void* nul = std::memchr(data + pos, 0, size - pos);
            if (nul == nullptr) return true;  // truncated: tinyexr reports it
            const size_t end = size_t(static_cast<const unsigned char*>(nul) - data);
            field = std::string_view(reinterpret_cast<const char*>(data + pos), end - pos);
            pos = end + 1;
        }
        if (size - pos < 4) return true;
        uint32_t length = 0;
        std::memcpy(&length, data + pos, 4);  // little-endian, like the host
        pos += 4;
        if (names[0] == "tiles" && length != 9) return false;
        if (names[0] == "compression" && length < 1) return false;
        if (length > size - pos) return true;
        pos += length;
    }
    return true;
}

Texture decode_exr(const unsigned char* data, size_t size, const std::string& name) {
    EXRVersion version;
    if (ParseEXRVersionFromMemory(&version, data, size) != TINYEXR_SUCCESS)
        throw file_error(name, 0, "cannot decode EXR: bad version header");
    if (version.multipart || version.non_image)
        throw file_error(name, 0, "cannot decode EXR: multi-part and deep images are not supported");
    if (!exr_attribute_sizes_are_safe(data, size))
        throw file_error(name, 0, "cannot decode EXR: malformed 'tiles' or 'compression' attribute");
    ExrHeaderOwner header_owner;
    EXRHeader& header = header_owner.header;
    const char* err = nullptr;
    if (ParseEXRHeaderFromMemory(&header, &version, data, size, &err) != TINYEXR_SUCCESS)
        throw exr_error(name, err, "bad header");
    // tinyexr 1.0.1's PIZ decoder trusts the lengths inside the data and reads
    // past the end of the file on malformed input (found by fuzz_exr), so PIZ
    // files are refused rather than decoded unsafely.
    if (header.compression_type == TINYEXR_COMPRESSIONTYPE_PIZ)
        throw file_error(name, 0, "cannot decode EXR: PIZ compression is not supported (save with ZIP or none)");
    // An absurd data window is rejected before anything is decoded.
    const long long w = (long long)header.data_window.max_x - header.data_window.min_x + 1;
    const long long h = (long long)header.data_window.max_y - header.data_window.min_y + 1;
    check_dimensions(w, h, name);
    check_budget(w, h, 4, sizeof(float), name);  // the channels as floats, and our copy

    // The color channels: R, G, B (A optional), or a single gray channel.
    int rgba[4] = {-1, -1, -1, -1};
    for (int c = 0; c < header.num_channels; ++c) {
        if (header.pixel_types[c] == TINYEXR_PIXELTYPE_HALF) header.requested_pixel_types[c] = TINYEXR_PIXELTYPE_FLOAT;
        const std::string channel = header.channels[c].name;
        for (int k = 0; k < 4; ++k)
            if (channel == std::string(1, "RGBA"[k])) rgba[k] = c;
    }
    if (header.num_channels == 1) rgba[0] = rgba[1] = rgba[2] = 0;
    if (rgba[0] < 0 || rgba[1] < 0 || rgba[2] < 0)
        throw file_error(name, 0, "cannot decode EXR: no R, G and B channels");

    ExrImageOwner image_owner;
    EXRImage& image = image_owner.image;
    if (LoadEXRImageFromMemory(&image, &header, data, size, &err) != TINYEXR_SUCCESS)
        throw exr_error(name, err, "decode failed");
    image_owner.loaded = true;
    if (image.width != w || image.height != h)
        throw file_error(name, 0, "cannot decode EXR: decoded size differs from the data window");

    const int channels = rgba[3] >= 0 ? 4 : 3;
    Texture tex;
    tex.name = name;
    tex.width = int(w);
    tex.height = int(h);
    tex.channels = channels;
    tex.encoding = TextureEncoding::LinearFloat;
    budgeted_resize(tex.texels_f, size_t(w) * size_t(h) * size_t(channels), "texture '" + name + "'");
    auto copy_texel = [&](unsigned char** source, size_t from, size_t to) {
        for (int k = 0; k < channels; ++k)
            tex.texels_f[to * size_t(channels) + size_t(k)] =
                exr_value(source[rgba[k]], header.requested_pixel_types[rgba[k]], from);
    };
    if (header.tiled) {
        // Tiles hold tile_size_x * tile_size_y values per channel; edge tiles are clipped.
        for (int t = 0; t < image.num_tiles; ++t) {
            const EXRTile& tile = image.tiles[t];
            for (int j = 0; j < header.tile_size_y; ++j)
                for (int i = 0; i < header.tile_size_x; ++i) {
                    const long long x = (long long)tile.offset_x * header.tile_size_x + i;
                    const long long y = (long long)tile.offset_y * header.tile_size_y + j;
                    if (x < 0 || y < 0 || x >= w || y >= h) continue;
                    copy_texel(tile.images, size_t(i) + size_t(j) * size_t(header.tile_size_x),
                               size_t(y) * size_t(w) + size_t(x));
                }
        }
    } else {
        for (size_t i = 0; i < size_t(w) * size_t(h); ++i) copy_texel(image.images, i, i);
    }
    // Drop an all-opaque alpha channel: environment maps are large.
    if (channels == 4) {
        bool opaque = true;
        for (size_t i = 3; i < tex.texels_f.size() && opaque; i += 4) opaque = tex.texels_f[i] == 1.0f;
        if (opaque) {
            for (size_t i = 0; i < size_t(w) * size_t(h); ++i)
                for (int k = 0; k < 3; ++k) tex.texels_f[3 * i + size_t(k)] = tex.texels_f[4 * i + size_t(k)];
            tex.texels_f.resize(size_t(w) * size_t(h) * 3);
            tex.texels_f.shrink_to_fit();
            tex.channels = 3;
        }
    }
    return tex;
}

// stb_image grows its PNG data buffer to whatever an IDAT chunk's length field
// says before reading it, so a 100-byte file can make it allocate gigabytes
// (found by fuzz_texture). Every chunk must fit in the file before stb sees it.
void check_png_chunks(const unsigned char* data, size_t size, const std::string& name) {
    static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (size < 8 || std::memcmp(data, kSignature, 8) != 0) return;
    size_t offset = 8;
    while (offset + 8 <= size) {
        const uint64_t length = (uint64_t(data[offset]) << 24) | (uint64_t(data[offset + 1]) << 16) |
                                (uint64_t(data[offset + 2]) << 8) | uint64_t(data[offset + 3]);
        const std::string type(reinterpret_cast<const char*>(data + offset + 4), 4);
        const uint64_t remaining = size - offset - 8;
        if (length + 4 > remaining)  // data plus CRC
            throw file_byte_error(name, offset,
                                  "PNG chunk declares " + std::to_string(length) + " bytes but only " +
                                      std::to_string(remaining) + " remain in the file");
        if (type == "IEND") return;
        offset += 12 + size_t(length);
    }
}

// stb_image's GIF, PSD and PIC decoders in Debian 12's libstb (2022-09) have
// known out-of-bounds bugs (CVE-2023-45661 to -45667 among them), and no
// scene format uses these for textures: they are refused by their signature.
void refuse_unsafe_formats(const unsigned char* data, size_t size, const std::string& name) {
    auto starts_with = [&](const char* magic, size_t n) { return size >= n && std::memcmp(data, magic, n) == 0; };
    const char* format = starts_with("GIF8", 4)                 ? "GIF"
                         : starts_with("8BPS", 4)               ? "PSD"
                         : starts_with("\x53\x80\xF6\x34", 4) ? "Softimage PIC"
                                                                : nullptr;
    if (format)
        throw file_error(name, 0, std::string(format) + " images are not supported as textures (use PNG, JPEG, TGA, BMP, HDR or EXR)");
}

Texture decode_jpeg_texture(const unsigned char* data, size_t size, const std::string& name,
                            TextureEncoding encoding8) {
    // Every coded 8x8 block costs at least one bit (its DC code), and a 4:2:0
    // chroma block covers 256 pixels, so even a progressive file that stops
    // after one chroma scan holds under 4096 pixels per byte beyond its
    // headers: a tiny file declaring a huge image is refused before the
    // decoder allocates for it.
    DecodedJpeg jpeg = decode_jpeg(data, size, name, [&](long long width, long long height, int channels) {
        check_dimensions(width, height, name);
        if (uint64_t(width) * uint64_t(height) > uint64_t(size) * 4096 + 65536)
            throw file_error(name, 0, "image declares " + std::to_string(width) + "x" + std::to_string(height) +
                                          " pixels but the file has only " + std::to_string(size) +
                                          " bytes (truncated or corrupt)");
        check_budget(width, height, channels, 1, name);
    });
    Texture tex;
    tex.name = name;
    tex.width = jpeg.width;
    tex.height = jpeg.height;
    tex.channels = jpeg.channels;
    tex.encoding = encoding8 == TextureEncoding::LinearFloat ? TextureEncoding::Linear8 : encoding8;
    tex.texels8 = std::move(jpeg.texels);
    return tex;
}

Texture decode_stb(const unsigned char* data, size_t size, const std::string& name, TextureEncoding encoding8) {
    if (size > size_t(std::numeric_limits<int>::max())) throw file_error(name, 0, "image file too large");
    refuse_unsafe_formats(data, size, name);
    check_png_chunks(data, size, name);
    const int len = int(size);
    int width = 0, height = 0, channels = 0;
    if (!stbi_info_from_memory(data, len, &width, &height, &channels))
        throw file_error(name, 0, "cannot decode image: " + stb_reason());
    check_dimensions(width, height, name);
    check_budget(width, height, channels, stbi_is_hdr_from_memory(data, len) ? sizeof(float) : 1, name);
    // No format stb decodes packs more than ~8k pixels into a byte (deflate's
    // limit is 1032:1 on 1-bit PNG rows); a tiny file declaring a huge image is
    // truncated or corrupt, and decoding it would only fill memory with zeros.
    constexpr uint64_t kMaxPixelsPerByte = 16384;
    if (uint64_t(width) * uint64_t(height) > uint64_t(size) * kMaxPixelsPerByte + 65536)
        throw file_error(name, 0, "image declares " + std::to_string(width) + "x" + std::to_string(height) +
                                      " pixels but the file has only " + std::to_string(size) +
                                      " bytes (truncated or corrupt)");

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
    if (is_jpeg(data, size)) return decode_jpeg_texture(data, size, name, encoding8);
    return decode_stb(data, size, name, encoding8);
}

Texture load_texture(const std::string& path, TextureEncoding encoding8) {
    std::string bytes = io::read_file(path);
    return load_texture_from_memory(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), path,
                                    encoding8);
}

}  // namespace rf
