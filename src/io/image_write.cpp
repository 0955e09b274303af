// Writing rendered images (.png, .exr, .pfm) and reading them back.
//  - PNG: 8-bit sRGB of tone_curve(exposure * radiance) (stb_image_write).
//    Curves: clamp; Reinhard, Stark, Shirley, Ferwerda 2002, "Photographic Tone
//    Reproduction for Digital Images", the global operator L / (1 + L) applied
//    to luminance and the color scaled by L'/L (keeps hue and saturation);
//    ACES: Krzysztof Narkowicz 2015, "ACES Filmic Tone Mapping Curve", a
//    rational fit of the ACES RRT+ODT, applied per channel.
//  - EXR: 32-bit float RGB (tinyexr), exposure applied as a plain scale.
//  - PFM: the Portable Float Map ("PF", little endian, rows stored bottom to
//    top as the format specifies), exposure applied as a plain scale.
#include <stb_image.h>
#include <stb_image_write.h>
#include <tinyexr.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "math/color.h"
#include "render/tone_map.h"

namespace rf {
namespace {

enum class ImageFormat { Png, Exr, Pfm };

ImageFormat format_of(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext == ".png") return ImageFormat::Png;
    if (ext == ".exr") return ImageFormat::Exr;
    if (ext == ".pfm") return ImageFormat::Pfm;
    throw file_error(path, 0, "unsupported image extension '" + ext + "' (expected .png, .exr or .pfm)");
}

bool host_is_little_endian() {
    const uint32_t one = 1;
    unsigned char first;
    std::memcpy(&first, &one, 1);
    return first == 1;
}

void byte_swap_floats(std::vector<float>& values) {
    for (float& f : values) {
        uint32_t bits;
        std::memcpy(&bits, &f, 4);
        bits = (bits >> 24) | ((bits >> 8) & 0xFF00u) | ((bits << 8) & 0xFF0000u) | (bits << 24);
        std::memcpy(&f, &bits, 4);
    }
}

// Interleaved RGB floats, rows top to bottom, scaled by exposure.
std::vector<float> scaled_rgb(const Image& image, float exposure) {
    std::vector<float> rgb(image.pixels.size() * 3);
    for (size_t i = 0; i < image.pixels.size(); ++i) {
        rgb[3 * i + 0] = image.pixels[i].x * exposure;
        rgb[3 * i + 1] = image.pixels[i].y * exposure;
        rgb[3 * i + 2] = image.pixels[i].z * exposure;
    }
    return rgb;
}

void write_png(const std::string& path, const Image& image, const ToneMapping& tone) {
    std::vector<uint8_t> bytes(image.pixels.size() * 3);
    for (size_t i = 0; i < image.pixels.size(); ++i) {
        tone_map_pixel(image.pixels[i], tone, &bytes[3 * i]);
    }
    if (!stbi_write_png(path.c_str(), image.width, image.height, 3, bytes.data(), image.width * 3))
        throw file_error(path, 0, "cannot write PNG file");
}

void write_exr(const std::string& path, const Image& image, float exposure) {
    std::vector<float> rgb = scaled_rgb(image, exposure);
    const char* err = nullptr;
    int status = SaveEXR(rgb.data(), image.width, image.height, 3, /*save_as_fp16=*/0, path.c_str(), &err);
    if (status != TINYEXR_SUCCESS) {
        std::string reason = err ? err : "unknown error";
        if (err) FreeEXRErrorMessage(err);
        throw file_error(path, 0, "cannot write EXR file: " + reason);
    }
}

void write_pfm(const std::string& path, const Image& image, float exposure) {
    std::vector<float> rgb = scaled_rgb(image, exposure);
    if (!host_is_little_endian()) byte_swap_floats(rgb);
    std::ofstream out(path, std::ios::binary);
    if (!out) throw file_error(path, 0, "cannot open file for writing");
    out << "PF\n" << image.width << ' ' << image.height << "\n-1.0\n";  // negative scale: little endian
    const size_t row_floats = size_t(image.width) * 3;
    for (int y = image.height - 1; y >= 0; --y)
        out.write(reinterpret_cast<const char*>(rgb.data() + size_t(y) * row_floats),
                  std::streamsize(row_floats * sizeof(float)));
    if (!out) throw file_error(path, 0, "cannot write PFM file");
}

Image read_png(const std::string& path) {
    int w = 0, h = 0, channels = 0;
    unsigned char* data = stbi_load(path.c_str(), &w, &h, &channels, 3);
    if (!data) {
        const char* reason = stbi_failure_reason();
        throw file_error(path, 0, std::string("cannot read PNG: ") + (reason ? reason : "unknown error"));
    }
    Image image(w, h);
    for (size_t i = 0; i < image.pixels.size(); ++i)
        image.pixels[i] = srgb_to_linear(Vec3f(data[3 * i], data[3 * i + 1], data[3 * i + 2]) * (1.0f / 255.0f));
    stbi_image_free(data);
    return image;
}

Image read_exr(const std::string& path) {
    float* rgba = nullptr;
    int w = 0, h = 0;
    const char* err = nullptr;
    if (LoadEXR(&rgba, &w, &h, path.c_str(), &err) != TINYEXR_SUCCESS) {
        std::string reason = err ? err : "unknown error";
        if (err) FreeEXRErrorMessage(err);
        throw file_error(path, 0, "cannot read EXR: " + reason);
    }
    Image image(w, h);
    for (size_t i = 0; i < image.pixels.size(); ++i)
        image.pixels[i] = Vec3f(rgba[4 * i], rgba[4 * i + 1], rgba[4 * i + 2]);
    free(rgba);  // tinyexr allocates with malloc
    return image;
}

Image read_pfm(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw file_error(path, 0, "cannot open file");
    in.seekg(0, std::ios::end);
    const auto file_size = static_cast<unsigned long long>(in.tellg());
    in.seekg(0);
    std::string magic;
    long long w = 0, h = 0;
    double scale = 0.0;
    if (!(in >> magic >> w >> h >> scale) || (magic != "PF" && magic != "Pf"))
        throw file_error(path, 1, "not a PFM file (expected 'PF' or 'Pf', width, height, scale)");
    if (w < 1 || h < 1 || w > 65536 || h > 65536 || scale == 0.0 || !std::isfinite(scale))
        throw file_error(path, 2, "invalid PFM header (size " + std::to_string(w) + "x" + std::to_string(h) + ")");
    in.get();  // the single whitespace character that ends the header
    const int channels = magic == "PF" ? 3 : 1;
    const unsigned long long header = static_cast<unsigned long long>(in.tellg());
    const unsigned long long needed = static_cast<unsigned long long>(w) * h * channels * sizeof(float);
    if (file_size < header || file_size - header < needed)
        throw file_byte_error(path, file_size, "PFM pixel data is truncated (" + std::to_string(needed) +
                                                   " bytes expected after the header)");
    std::vector<float> values(size_t(w) * size_t(h) * size_t(channels));
    in.read(reinterpret_cast<char*>(values.data()), std::streamsize(needed));
    if (!in) throw file_byte_error(path, header, "cannot read PFM pixel data");
    if ((scale < 0.0) != host_is_little_endian()) byte_swap_floats(values);
    Image image{int(w), int(h)};
    for (int y = 0; y < image.height; ++y) {
        const float* row = values.data() + size_t(image.height - 1 - y) * size_t(w) * size_t(channels);
        for (int x = 0; x < image.width; ++x) {
            const float* p = row + size_t(x) * size_t(channels);
            image.at(x, y) = channels == 3 ? Vec3f(p[0], p[1], p[2]) : Vec3f(p[0]);
        }
    }
    return image;
}

}  // namespace

ToneCurve parse_tone_curve(const std::string& name) {
    std::string lower = name;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (lower == "clamp") return ToneCurve::Clamp;
    if (lower == "reinhard") return ToneCurve::Reinhard;
    if (lower == "aces") return ToneCurve::Aces;
    throw Error("unknown tone curve '" + name + "' (expected clamp, reinhard or aces)");
}

std::string to_string(ToneCurve curve) {
    switch (curve) {
        case ToneCurve::Clamp: return "clamp";
        case ToneCurve::Reinhard: return "reinhard";
        case ToneCurve::Aces: return "aces";
    }
    return "unknown";
}

void write_image(const std::string& path, const Image& image, float exposure) {
    write_image(path, image, ToneMapping{exposure, ToneCurve::Clamp});
}

void write_image(const std::string& path, const Image& image, const ToneMapping& tone) {
    const float exposure = tone.exposure;
    ImageFormat format = format_of(path);
    if (image.width <= 0 || image.height <= 0 ||
        image.pixels.size() != size_t(image.width) * size_t(image.height))
        throw file_error(path, 0, "cannot write an empty or inconsistent image (" + std::to_string(image.width) +
                                      "x" + std::to_string(image.height) + ")");
    if (!std::isfinite(exposure) || exposure < 0.0f)
        throw file_error(path, 0, "exposure must be finite and >= 0");
    switch (format) {
        case ImageFormat::Png: write_png(path, image, tone); break;
        case ImageFormat::Exr: write_exr(path, image, exposure); break;  // linear: the curve is for display only
        case ImageFormat::Pfm: write_pfm(path, image, exposure); break;
    }
}

Image read_image(const std::string& path) {
    ImageFormat format = format_of(path);
    if (!std::filesystem::is_regular_file(path)) throw file_error(path, 0, "no such file");
    switch (format) {
        case ImageFormat::Png: return read_png(path);
        case ImageFormat::Exr: return read_exr(path);
        case ImageFormat::Pfm: return read_pfm(path);
    }
    return {};
}

}  // namespace rf
