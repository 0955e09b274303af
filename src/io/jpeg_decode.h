// JPEG decoding through libjpeg-turbo (Debian's libjpeg62-turbo). stb_image's
// JPEG decoder in Debian 12 (2022-09) reads outside its tables on corrupt
// Huffman codes (found by fuzz_texture; fixed upstream only in 2023), so
// JPEG files never reach it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace rf {

struct DecodedJpeg {
    int width = 0, height = 0;
    int channels = 0;            // 1 (grayscale) or 3 (RGB)
    std::vector<uint8_t> texels;  // rows top to bottom, width * channels bytes each
};

// JPEG files start with SOI (FF D8) followed by a marker.
bool is_jpeg(const unsigned char* data, size_t size);

// Called with the header's size before any pixel is decoded; throws to refuse it.
using JpegSizeCheck = std::function<void(long long width, long long height, int channels)>;

// Decodes a JPEG held in memory. Throws rf::Error (a file error naming `name`)
// for corrupt or truncated data, unsupported colour spaces (CMYK), more than
// kMaxJpegScans progressive scans, and whatever `check_size` refuses.
DecodedJpeg decode_jpeg(const unsigned char* data, size_t size, const std::string& name,
                        const JpegSizeCheck& check_size);

// A progressive JPEG may hold any number of scans, each a full pass over the
// coefficients; real files have about 10 (libjpeg-turbo's tools stop at 500).
inline constexpr int kMaxJpegScans = 500;

}  // namespace rf
