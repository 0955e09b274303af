// Writing and reading back rendered images: PNG (8-bit sRGB), EXR and PFM (float).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "render/color.h"
#include "test_paths.h"

namespace rf {
namespace {

// A small image with distinct, non-symmetric values in [0, 1].
Image gradient_image(int w = 7, int h = 5) {
    Image image(w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            image.at(x, y) = Vec3f(float(x) / float(w - 1), float(y) / float(h - 1), 0.25f + 0.05f * float(x + y) / 2.0f);
    return image;
}

long count_newlines(const std::string& text) { return long(std::count(text.begin(), text.end(), '\n')); }

TEST(ImageIo, PngRoundTripWithinQuantisation) {
    std::string path = test::temp_dir("image_io_png") + "/out.png";
    Image original = gradient_image();
    write_image(path, original);
    Image back = read_image(path);
    ASSERT_EQ(back.width, original.width);
    ASSERT_EQ(back.height, original.height);
    for (size_t i = 0; i < original.pixels.size(); ++i) {
        // 8-bit sRGB quantisation: half a code value in the encoded space.
        Vec3f a = linear_to_srgb(original.pixels[i]), b = linear_to_srgb(back.pixels[i]);
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], 0.5f / 255.0f + 1e-5f) << "pixel " << i;
    }
}

TEST(ImageIo, PngAppliesExposureAndClamps) {
    std::string path = test::temp_dir("image_io_png_exposure") + "/out.png";
    Image image(2, 1);
    image.at(0, 0) = Vec3f(1.0f, 0.5f, 0.0f);
    image.at(1, 0) = Vec3f(8.0f, -1.0f, NAN);
    write_image(path, image, 0.5f);
    Image back = read_image(path);
    EXPECT_NEAR(back.at(0, 0).x, 0.5f, 0.01f);
    EXPECT_NEAR(back.at(0, 0).y, 0.25f, 0.01f);
    EXPECT_EQ(back.at(0, 0).z, 0.0f);
    EXPECT_EQ(back.at(1, 0).x, 1.0f);  // 4.0 clamps to white
    EXPECT_EQ(back.at(1, 0).y, 0.0f);  // negative clamps to black
    EXPECT_EQ(back.at(1, 0).z, 0.0f);  // NaN written as black
}

TEST(ImageIo, ExrRoundTripIsExact) {
    std::string path = test::temp_dir("image_io_exr") + "/out.exr";
    Image original = gradient_image();
    original.at(3, 2) = Vec3f(12.5f, 0.001f, 1000.0f);  // HDR values survive
    write_image(path, original);
    Image back = read_image(path);
    ASSERT_EQ(back.width, original.width);
    ASSERT_EQ(back.height, original.height);
    for (size_t i = 0; i < original.pixels.size(); ++i) EXPECT_EQ(back.pixels[i], original.pixels[i]) << i;
}

TEST(ImageIo, PfmRoundTripIsExactAndStoresRowsBottomUp) {
    std::string path = test::temp_dir("image_io_pfm") + "/out.pfm";
    Image original = gradient_image(4, 3);
    original.at(0, 2) = Vec3f(42.0f, -3.0f, 7.5f);  // bottom-left pixel
    write_image(path, original);
    Image back = read_image(path);
    ASSERT_EQ(back.width, 4);
    ASSERT_EQ(back.height, 3);
    for (size_t i = 0; i < original.pixels.size(); ++i) EXPECT_EQ(back.pixels[i], original.pixels[i]) << i;

    // The first pixel after the header is the bottom-left one, little endian.
    std::ifstream in(path, std::ios::binary);
    std::string header((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string expected_header = "PF\n4 3\n-1.0\n";
    ASSERT_EQ(header.compare(0, expected_header.size(), expected_header), 0);
    ASSERT_EQ(header.size(), expected_header.size() + 4 * 3 * 3 * sizeof(float));
    const unsigned char* first = reinterpret_cast<const unsigned char*>(header.data() + expected_header.size());
    uint32_t bits = uint32_t(first[0]) | uint32_t(first[1]) << 8 | uint32_t(first[2]) << 16 | uint32_t(first[3]) << 24;
    float value;
    std::memcpy(&value, &bits, 4);
    EXPECT_EQ(value, 42.0f);
}

TEST(ImageIo, UnknownExtensionIsAnErrorNamingTheFile) {
    std::string path = test::temp_dir("image_io_ext") + "/out.bmpx";
    try {
        write_image(path, gradient_image());
        FAIL() << "expected rf::Error";
    } catch (const Error& e) {
        std::string message = e.what();
        EXPECT_NE(message.find("out.bmpx"), std::string::npos) << message;
        EXPECT_NE(message.find("extension"), std::string::npos) << message;
        EXPECT_EQ(count_newlines(message), 0);
    }
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_THROW((void)read_image(path), Error);
}

TEST(ImageIo, EmptyImageAndUnwritablePathAreErrors) {
    std::string dir = test::temp_dir("image_io_errors");
    EXPECT_THROW(write_image(dir + "/empty.png", Image{}), Error);
    Image inconsistent(2, 2);
    inconsistent.pixels.pop_back();
    EXPECT_THROW(write_image(dir + "/bad.exr", inconsistent), Error);
    for (const char* ext : {".png", ".exr", ".pfm"})
        EXPECT_THROW(write_image(dir + "/no/such/dir/out" + std::string(ext), gradient_image()), Error) << ext;
}

TEST(ImageIo, ReadingMissingOrTruncatedFilesIsAnError) {
    std::string dir = test::temp_dir("image_io_read_errors");
    EXPECT_THROW((void)read_image(dir + "/missing.png"), Error);
    {
        std::ofstream out(dir + "/truncated.pfm", std::ios::binary);
        out << "PF\n100000 100000\n-1.0\n" << std::string(64, '\0');
    }
    EXPECT_THROW((void)read_image(dir + "/truncated.pfm"), Error);
    {
        std::ofstream out(dir + "/garbage.png", std::ios::binary);
        out << "definitely not a png";
    }
    EXPECT_THROW((void)read_image(dir + "/garbage.png"), Error);
    {
        std::ofstream out(dir + "/garbage.exr", std::ios::binary);
        out << "definitely not an exr";
    }
    EXPECT_THROW((void)read_image(dir + "/garbage.exr"), Error);
}

}  // namespace
}  // namespace rf
