// JPEG textures through libjpeg-turbo (src/io/jpeg_decode.cpp). The test
// images are encoded here with libjpeg's compressor, so no binary fixture
// hides what they contain: baseline and progressive colour, grayscale, and
// broken variants (truncated, a huge declared size, the fuzzer's corrupt
// Huffman table in tests/data/textures/regressions/).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <jpeglib.h>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"

namespace rf {
namespace {

// Encodes `pixels` (rows top first, `channels` 1 or 3) with libjpeg.
std::vector<unsigned char> encode_jpeg(int width, int height, int channels, const std::vector<unsigned char>& pixels,
                                       bool progressive) {
    jpeg_compress_struct cinfo;
    jpeg_error_mgr errors;
    cinfo.err = jpeg_std_error(&errors);
    jpeg_create_compress(&cinfo);
    unsigned char* buffer = nullptr;
    unsigned long size = 0;
    jpeg_mem_dest(&cinfo, &buffer, &size);
    cinfo.image_width = JDIMENSION(width);
    cinfo.image_height = JDIMENSION(height);
    cinfo.input_components = channels;
    cinfo.in_color_space = channels == 1 ? JCS_GRAYSCALE : JCS_RGB;
    jpeg_set_defaults(&cinfo);
    jpeg_set_quality(&cinfo, 95, TRUE);
    for (int c = 0; c < cinfo.num_components; ++c) cinfo.comp_info[c].h_samp_factor = cinfo.comp_info[c].v_samp_factor = 1;
    if (progressive) jpeg_simple_progression(&cinfo);
    jpeg_start_compress(&cinfo, TRUE);
    while (cinfo.next_scanline < cinfo.image_height) {
        JSAMPROW row = const_cast<unsigned char*>(pixels.data()) + size_t(cinfo.next_scanline) * width * channels;
        jpeg_write_scanlines(&cinfo, &row, 1);
    }
    jpeg_finish_compress(&cinfo);
    jpeg_destroy_compress(&cinfo);
    std::vector<unsigned char> bytes(buffer, buffer + size);
    std::free(buffer);
    return bytes;
}

// 16 x 8: the left half red, the right half blue.
std::vector<unsigned char> red_blue_halves() {
    std::vector<unsigned char> pixels(16 * 8 * 3, 0);
    for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 16; ++x) pixels[size_t(y * 16 + x) * 3 + (x < 8 ? 0 : 2)] = 255;
    return pixels;
}

std::string error_of(const std::vector<unsigned char>& bytes, const std::string& name) {
    try {
        (void)load_texture_from_memory(bytes.data(), bytes.size(), name);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

TEST(JpegDecode, BaselineAndProgressiveColour) {
    for (bool progressive : {false, true}) {
        SCOPED_TRACE(progressive ? "progressive" : "baseline");
        const std::vector<unsigned char> jpeg = encode_jpeg(16, 8, 3, red_blue_halves(), progressive);
        const Texture t = load_texture_from_memory(jpeg.data(), jpeg.size(), "halves.jpg");
        ASSERT_EQ(t.width, 16);
        ASSERT_EQ(t.height, 8);
        ASSERT_EQ(t.channels, 3);
        EXPECT_EQ(t.encoding, TextureEncoding::Srgb8);
        ASSERT_EQ(t.texels8.size(), 16u * 8u * 3u);
        // Block centres away from the colour edge: lossy, but close.
        auto texel = [&](int x, int y, int c) { return int(t.texels8[size_t(y * 16 + x) * 3 + size_t(c)]); };
        EXPECT_NEAR(texel(2, 4, 0), 255, 8);
        EXPECT_NEAR(texel(2, 4, 2), 0, 8);
        EXPECT_NEAR(texel(13, 4, 0), 0, 8);
        EXPECT_NEAR(texel(13, 4, 2), 255, 8);
    }
}

TEST(JpegDecode, GrayscaleHasOneChannel) {
    const std::vector<unsigned char> jpeg = encode_jpeg(8, 8, 1, std::vector<unsigned char>(64, 128), false);
    const Texture t = load_texture_from_memory(jpeg.data(), jpeg.size(), "gray.jpg", TextureEncoding::Linear8);
    ASSERT_EQ(t.channels, 1);
    EXPECT_EQ(t.encoding, TextureEncoding::Linear8);
    for (unsigned char v : t.texels8) EXPECT_NEAR(int(v), 128, 2);
}

TEST(JpegDecode, TruncatedFileIsAnError) {
    std::vector<unsigned char> jpeg = encode_jpeg(16, 8, 3, red_blue_halves(), false);
    jpeg.resize(jpeg.size() * 2 / 3);
    const std::string message = error_of(jpeg, "cut.jpg");
    EXPECT_NE(message.find("cut.jpg"), std::string::npos) << message;
    EXPECT_NE(message.find("cannot decode JPEG"), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos);
}

TEST(JpegDecode, TinyFileDeclaringAHugeImageIsRefused) {
    std::vector<unsigned char> jpeg = encode_jpeg(16, 8, 3, red_blue_halves(), false);
    // SOF0 (FF C0): length(2) precision(1) height(2) width(2).
    size_t sof = 0;
    for (size_t i = 2; i + 9 < jpeg.size(); ++i)
        if (jpeg[i] == 0xFF && jpeg[i + 1] == 0xC0) {
            sof = i;
            break;
        }
    ASSERT_GT(sof, 0u);
    jpeg[sof + 5] = 0x2E;  // height 12000
    jpeg[sof + 6] = 0xE0;
    jpeg[sof + 7] = 0x2E;  // width 12000
    jpeg[sof + 8] = 0xE0;
    const std::string message = error_of(jpeg, "huge.jpg");
    EXPECT_NE(message.find("declares 12000x12000 pixels"), std::string::npos) << message;
}

TEST(JpegDecode, GifAndPsdAreRefusedByName) {
    const std::vector<unsigned char> gif = {'G', 'I', 'F', '8', '9', 'a', 1, 0, 1, 0, 0, 0, 0};
    EXPECT_NE(error_of(gif, "a.gif").find("GIF images are not supported"), std::string::npos);
    const std::vector<unsigned char> psd = {'8', 'B', 'P', 'S', 0, 1, 0, 0, 0, 0, 0, 0};
    EXPECT_NE(error_of(psd, "a.psd").find("PSD images are not supported"), std::string::npos);
}

}  // namespace
}  // namespace rf
