// Texture decoding: every supported format from tiny committed fixtures
// (tests/data/textures/make_fixtures.py), and clean errors for bad input.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "test_paths.h"

namespace rf {
namespace {

std::string texture_fixture(const std::string& name) { return test::data_path("textures/" + name); }

std::vector<unsigned char> file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The error names the file and stays on one line.
void expect_load_error(const std::string& path, const std::string& fragment) {
    try {
        load_texture(path);
        FAIL() << "no error for " << path;
    } catch (const Error& e) {
        std::string message = e.what();
        EXPECT_NE(message.find(path), std::string::npos) << message;
        EXPECT_NE(message.find(fragment), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

TEST(TextureIo, DecodesRgbPng) {
    Texture t = load_texture(texture_fixture("rgb_2x2.png"));
    EXPECT_EQ(t.width, 2);
    EXPECT_EQ(t.height, 2);
    EXPECT_EQ(t.channels, 3);
    EXPECT_EQ(t.encoding, TextureEncoding::Srgb8);
    EXPECT_EQ(t.name, texture_fixture("rgb_2x2.png"));
    EXPECT_TRUE(t.texels_f.empty());
    // Row 0 is the top of the image: red, green / blue, white.
    EXPECT_EQ(t.texels8, (std::vector<uint8_t>{255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255}));
}

TEST(TextureIo, KeepsRequestedEightBitEncoding) {
    EXPECT_EQ(load_texture(texture_fixture("rgb_2x2.png"), TextureEncoding::Linear8).encoding, TextureEncoding::Linear8);
}

TEST(TextureIo, DecodesRgbaAndGrayPng) {
    Texture rgba = load_texture(texture_fixture("rgba_3x2.png"));
    EXPECT_EQ(rgba.width, 3);
    EXPECT_EQ(rgba.height, 2);
    EXPECT_EQ(rgba.channels, 4);
    ASSERT_EQ(rgba.texels8.size(), 24u);
    EXPECT_EQ(rgba.texels8[7], 128);   // alpha of the second texel
    EXPECT_EQ(rgba.texels8[23], 12);   // alpha of the last texel

    Texture gray = load_texture(texture_fixture("gray_2x1.png"));
    EXPECT_EQ(gray.channels, 1);
    EXPECT_EQ(gray.texels8, (std::vector<uint8_t>{0, 200}));
}

TEST(TextureIo, DecodesPpmAndTopDownTga) {
    Texture ppm = load_texture(texture_fixture("tiny.ppm"));
    EXPECT_EQ(ppm.width, 2);
    EXPECT_EQ(ppm.height, 1);
    EXPECT_EQ(ppm.texels8, (std::vector<uint8_t>{255, 255, 0, 0, 255, 255}));

    Texture tga = load_texture(texture_fixture("tiny.tga"));
    EXPECT_EQ(tga.channels, 3);
    EXPECT_EQ(tga.texels8, (std::vector<uint8_t>{255, 0, 0, 0, 0, 255}));  // BGR on disk -> RGB
}

TEST(TextureIo, DecodesRadianceHdrAsLinearFloat) {
    Texture t = load_texture(texture_fixture("tiny.hdr"));
    EXPECT_EQ(t.encoding, TextureEncoding::LinearFloat);
    EXPECT_EQ(t.width, 2);
    EXPECT_EQ(t.height, 1);
    EXPECT_EQ(t.channels, 3);
    EXPECT_TRUE(t.texels8.empty());
    EXPECT_EQ(t.texels_f, (std::vector<float>{1.0f, 0.5f, 0.25f, 4.0f, 4.0f, 4.0f}));
}

TEST(TextureIo, DecodesExrAsLinearFloat) {
    Texture t = load_texture(texture_fixture("tiny.exr"));
    EXPECT_EQ(t.encoding, TextureEncoding::LinearFloat);
    EXPECT_EQ(t.width, 2);
    EXPECT_EQ(t.height, 2);
    EXPECT_EQ(t.channels, 3);  // the opaque alpha tinyexr adds is dropped
    EXPECT_EQ(t.texels_f, (std::vector<float>{0.5f, 1.0f, 2.0f, 0.0f, 0.25f, 8.0f,
                                              16.0f, 0.125f, 0.0f, 1.5f, 2.5f, 3.5f}));
}

TEST(TextureIo, DecodesFromMemoryUnderAGivenName) {
    std::vector<unsigned char> bytes = file_bytes(texture_fixture("rgb_2x2.png"));
    Texture t = load_texture_from_memory(bytes.data(), bytes.size(), "embedded#0");
    EXPECT_EQ(t.name, "embedded#0");
    EXPECT_EQ(t.width, 2);

    std::vector<unsigned char> junk(16, 'x');
    try {
        load_texture_from_memory(junk.data(), junk.size(), "embedded#1");
        FAIL() << "junk decoded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("embedded#1"), std::string::npos) << e.what();
    }
    EXPECT_THROW(load_texture_from_memory(nullptr, 0, "embedded#2"), Error);
}

TEST(TextureIo, TinyFileDeclaringAHugeImageIsRejected) {
    // An 18-byte TGA header (uncompressed RGB, 4000 x 3000) and 3 bytes of pixels.
    std::vector<unsigned char> tga = {0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xA0, 0x0F, 0xB8, 0x0B, 24, 0, 1, 2, 3};
    try {
        (void)load_texture_from_memory(tga.data(), tga.size(), "tiny.tga");
        FAIL() << "a 21-byte file decoded as 4000x3000";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("declares 4000x3000 pixels but the file has only 21 bytes"),
                  std::string::npos)
            << e.what();
    }
    // The same header over the full pixel data decodes.
    tga.resize(18 + 4000 * 3000 * 3, 7);
    EXPECT_EQ(load_texture_from_memory(tga.data(), tga.size(), "full.tga").width, 4000);
}

TEST(TextureIo, RejectsBadFilesWithOneLineErrors) {
    expect_load_error(texture_fixture("corrupt.png"), "PNG chunk declares");  // checked before stb sees it
    expect_load_error(texture_fixture("truncated.png"), "cannot decode");
    expect_load_error(texture_fixture("huge.png"), "unsupported image size 40000x20000");
    expect_load_error(texture_fixture("empty.png"), "empty");
    expect_load_error(texture_fixture("no_such_file.png"), "not found");
    expect_load_error(test::data_path("textures"), "not a regular file");
}

}  // namespace
}  // namespace rf
