// Writing and reading back rendered images: PNG (8-bit sRGB), EXR and PFM (float),
// and the tone curves applied to PNG output (clamp, Reinhard, ACES).
#include <gtest/gtest.h>
#include <stb_image.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "math/color.h"
#include "render/tone_map.h"
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


// ---- Tone mapping --------------------------------------------------------

constexpr ToneCurve kAllCurves[] = {ToneCurve::Clamp, ToneCurve::Reinhard, ToneCurve::Aces};

TEST(ToneMapping, CurveNamesRoundTripAndUnknownNamesAreErrors) {
    for (ToneCurve curve : kAllCurves) EXPECT_EQ(parse_tone_curve(to_string(curve)), curve);
    EXPECT_EQ(parse_tone_curve("ACES"), ToneCurve::Aces);
    EXPECT_EQ(parse_tone_curve("Reinhard"), ToneCurve::Reinhard);
    try {
        (void)parse_tone_curve("filmic");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("filmic"), std::string::npos) << e.what();
    }
    EXPECT_THROW((void)parse_tone_curve(""), Error);
}

TEST(ToneMapping, EveryCurveMapsZeroToZeroAndIsMonotonicOnGrey) {
    for (ToneCurve curve : kAllCurves) {
        EXPECT_EQ(apply_tone_curve(Vec3f(0.0f), curve), Vec3f(0.0f)) << to_string(curve);
        float previous = 0.0f;
        // 1e-4 .. 1e4 in steps of 1.5%.
        for (float x = 1e-4f; x < 1e4f; x *= 1.015f) {
            const Vec3f y = apply_tone_curve(Vec3f(x), curve);
            ASSERT_GE(y.x, previous) << to_string(curve) << " at " << x;
            ASSERT_LE(y.x, 1.0f) << to_string(curve) << " at " << x;
            ASSERT_EQ(y.x, y.y) << to_string(curve);  // grey stays grey
            ASSERT_EQ(y.x, y.z) << to_string(curve);
            previous = y.x;
        }
    }
}

TEST(ToneMapping, ClampIsTheIdentityOnTheUnitInterval) {
    const Vec3f c(0.25f, 0.5f, 0.75f);
    EXPECT_EQ(apply_tone_curve(c, ToneCurve::Clamp), c);
    EXPECT_EQ(apply_tone_curve(Vec3f(3.0f, -2.0f, NAN), ToneCurve::Clamp), Vec3f(1.0f, 0.0f, 0.0f));
}

TEST(ToneMapping, ReinhardHalvesUnitGreyAndKeepsHue) {
    EXPECT_FLOAT_EQ(apply_tone_curve(Vec3f(1.0f), ToneCurve::Reinhard).x, 0.5f);
    EXPECT_FLOAT_EQ(apply_tone_curve(Vec3f(3.0f), ToneCurve::Reinhard).x, 0.75f);
    // A color below the clipping point keeps its channel ratios; its
    // luminance L becomes L / (1 + L).
    const Vec3f c(0.8f, 0.4f, 0.1f);
    const Vec3f mapped = apply_tone_curve(c, ToneCurve::Reinhard);
    EXPECT_NEAR(mapped.y / mapped.x, c.y / c.x, 1e-6f);
    EXPECT_NEAR(mapped.z / mapped.x, c.z / c.x, 1e-6f);
    const float l = luminance(c);
    EXPECT_NEAR(luminance(mapped), l / (1.0f + l), 1e-6f);
    // +inf is very bright, not NaN.
    const Vec3f inf = apply_tone_curve(Vec3f(INFINITY, 0.0f, 0.0f), ToneCurve::Reinhard);
    EXPECT_EQ(inf.x, 1.0f);
    EXPECT_EQ(inf.y, 0.0f);
}

TEST(ToneMapping, AcesMatchesNarkowiczAndSaturates) {
    // (2.51 + 0.03) / (2.43 + 0.59 + 0.14) at 1.
    EXPECT_NEAR(apply_tone_curve(Vec3f(1.0f), ToneCurve::Aces).x, 2.54f / 3.16f, 1e-6f);
    EXPECT_NEAR(apply_tone_curve(Vec3f(0.18f), ToneCurve::Aces).x,
                0.18f * (2.51f * 0.18f + 0.03f) / (0.18f * (2.43f * 0.18f + 0.59f) + 0.14f), 1e-6f);
    EXPECT_GT(apply_tone_curve(Vec3f(5.0f), ToneCurve::Aces).x, 0.98f);
    EXPECT_EQ(apply_tone_curve(Vec3f(8.0f), ToneCurve::Aces).x, 1.0f);
    EXPECT_EQ(apply_tone_curve(Vec3f(1e6f), ToneCurve::Aces).x, 1.0f);
    EXPECT_EQ(apply_tone_curve(Vec3f(INFINITY), ToneCurve::Aces).x, 1.0f);
    // Per channel: a saturated color stays ordered.
    const Vec3f c = apply_tone_curve(Vec3f(2.0f, 0.5f, 0.05f), ToneCurve::Aces);
    EXPECT_GT(c.x, c.y);
    EXPECT_GT(c.y, c.z);
}

// HDR values spanning the curves' interesting range.
Image hdr_image() {
    Image image(6, 4);
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x)
            image.at(x, y) = Vec3f(0.05f * float(x + 1) * float(y + 1), 0.3f * float(x), 4.0f / float(x + y + 1));
    return image;
}

TEST(ToneMapping, PngWithEachCurveReadsBackAsTheCurve) {
    const std::string dir = test::temp_dir("image_io_tone_png");
    const Image image = hdr_image();
    for (ToneCurve curve : kAllCurves) {
        const ToneMapping tone{0.7f, curve};
        const std::string path = dir + "/" + to_string(curve) + ".png";
        write_image(path, image, tone);
        const Image back = read_image(path);
        ASSERT_EQ(back.width, image.width);
        ASSERT_EQ(back.height, image.height);
        for (size_t i = 0; i < image.pixels.size(); ++i) {
            const Vec3f expected = linear_to_srgb(apply_tone_curve(image.pixels[i] * tone.exposure, curve));
            const Vec3f got = linear_to_srgb(back.pixels[i]);
            for (int k = 0; k < 3; ++k)
                EXPECT_NEAR(got[k], expected[k], 0.5f / 255.0f + 1e-5f) << to_string(curve) << " pixel " << i;
        }
    }
    // The float overload is the Clamp curve.
    write_image(dir + "/float.png", image, 0.7f);
    const Image clamp = read_image(dir + "/clamp.png"), by_float = read_image(dir + "/float.png");
    for (size_t i = 0; i < image.pixels.size(); ++i) EXPECT_EQ(clamp.pixels[i], by_float.pixels[i]) << i;
}

TEST(ToneMapping, HdrFormatsIgnoreTheCurveAndApplyOnlyExposure) {
    const std::string dir = test::temp_dir("image_io_tone_hdr");
    const Image image = hdr_image();
    for (const char* ext : {".exr", ".pfm"}) {
        const std::string path = dir + "/aces" + ext;
        write_image(path, image, ToneMapping{2.0f, ToneCurve::Aces});
        const Image back = read_image(path);
        ASSERT_EQ(back.pixels.size(), image.pixels.size());
        for (size_t i = 0; i < image.pixels.size(); ++i) EXPECT_EQ(back.pixels[i], image.pixels[i] * 2.0f) << ext << i;
    }
    EXPECT_THROW(write_image(dir + "/bad.exr", image, ToneMapping{-1.0f, ToneCurve::Reinhard}), Error);
}


// The host's table encoding is the exact encoding for every float it can see:
// each step's threshold and 64 floats either side, each bucket's ends, and a
// dense sweep.
TEST(ToneMapping, TableEncodingEqualsTheExactEncoding) {
    const auto next = [](float f, int steps) {
        for (int i = 0; i < std::abs(steps); ++i) f = std::nextafter(f, steps > 0 ? 2.0f : -1.0f);
        return f;
    };
    for (int code = 1; code <= 255; ++code) {
        const float threshold = srgb8_thresholds().at[code - 1];
        EXPECT_EQ(encode_srgb8_exact(threshold), code);
        EXPECT_EQ(encode_srgb8_exact(next(threshold, -1)), code - 1);
        for (int d = -64; d <= 64; ++d) {
            const float v = std::clamp(next(threshold, d), 0.0f, 1.0f);
            ASSERT_EQ(encode_srgb8_table(v), encode_srgb8_exact(v)) << v;
        }
    }
    // Each bucket of the table's first and last float.
    for (uint32_t bucket = 0; bucket < std::size(srgb8_thresholds().first_code); ++bucket)
        for (uint32_t bits : {bucket << Srgb8Thresholds::kBucketShift,
                              (bucket << Srgb8Thresholds::kBucketShift) | ((1u << Srgb8Thresholds::kBucketShift) - 1u)}) {
            float v;
            std::memcpy(&v, &bits, sizeof v);
            if (v > 1.0f) continue;
            ASSERT_EQ(encode_srgb8_table(v), encode_srgb8_exact(v)) << v;
        }
    for (uint32_t i = 0; i <= (1u << 20); ++i) {
        const float v = float(i) / float(1u << 20);
        ASSERT_EQ(encode_srgb8_table(v), encode_srgb8_exact(v)) << v;
    }
    EXPECT_EQ(encode_srgb8_table(0.0f), 0);
    EXPECT_EQ(encode_srgb8_table(1.0f), 255);
}

// A PNG holds tone_map_srgb8 of each pixel, the bytes a display image shows.
TEST(ToneMapping, PngBytesAreTheDisplayCodes) {
    Image image = gradient_image(9, 4);
    image.at(0, 0) = Vec3f(4.0f, -1.0f, std::nanf(""));
    const std::string path = test::temp_dir("png_bytes") + "/a.png";
    const ToneMapping tone{1.7f, ToneCurve::Reinhard};
    write_image(path, image, tone);
    int w = 0, h = 0, channels = 0;
    unsigned char* bytes = stbi_load(path.c_str(), &w, &h, &channels, 3);
    ASSERT_NE(bytes, nullptr);
    ASSERT_EQ(w, 9);
    for (size_t i = 0; i < image.pixels.size(); ++i) {
        uint8_t expected[3];
        tone_map_srgb8(image.pixels[i], tone, expected);
        for (int k = 0; k < 3; ++k) EXPECT_EQ(bytes[3 * i + size_t(k)], expected[k]) << i;
    }
    stbi_image_free(bytes);
}

}  // namespace
}  // namespace rf
