// libjpeg-turbo behind rf::decode_jpeg (jpeg_decode.h). libjpeg reports
// errors through a callback that must not return; it longjmps back here. Only
// C objects live between setjmp and the calls that may jump, and everything
// they own is released by jpeg_destroy_decompress on both paths.
#include "io/jpeg_decode.h"

#include <csetjmp>
#include <cstdio>
#include <cstring>

#include <jpeglib.h>
// jerror.h after jpeglib.h: the message codes (JWRN_JPEG_EOF).
#include <jerror.h>

#include "rayforge/core/error.h"

namespace rf {

namespace {

struct JpegErrorManager {
    jpeg_error_mgr base;  // first, so libjpeg's pointer is ours too
    std::jmp_buf jump;
    char message[JMSG_LENGTH_MAX];
};

void on_jpeg_error(j_common_ptr cinfo) {
    auto* manager = reinterpret_cast<JpegErrorManager*>(cinfo->err);
    manager->base.format_message(cinfo, manager->message);
    std::longjmp(manager->jump, 1);
}

// A truncated file would otherwise come back padded with grey blocks: an
// error. Other corrupt-data warnings (extraneous bytes before a marker) are
// common in real files that every viewer shows, so they stay silent.
void on_jpeg_warning(j_common_ptr cinfo, int level) {
    if (level < 0 && cinfo->err->msg_code == JWRN_JPEG_EOF) on_jpeg_error(cinfo);
}

void limit_scans(j_common_ptr cinfo) {
    auto* d = reinterpret_cast<j_decompress_ptr>(cinfo);
    if (d->is_decompressor && d->input_scan_number > kMaxJpegScans) {
        auto* manager = reinterpret_cast<JpegErrorManager*>(cinfo->err);
        std::snprintf(manager->message, sizeof manager->message, "more than %d progressive scans", kMaxJpegScans);
        std::longjmp(manager->jump, 1);
    }
}

}  // namespace

bool is_jpeg(const unsigned char* data, size_t size) {
    return size >= 3 && data[0] == 0xFF && data[1] == 0xD8 && data[2] == 0xFF;
}

DecodedJpeg decode_jpeg(const unsigned char* data, size_t size, const std::string& name,
                        const JpegSizeCheck& check_size) {
    DecodedJpeg image;  // constructed before setjmp: a jump back never skips its destructor
    std::string refusal;
    jpeg_decompress_struct cinfo;
    JpegErrorManager errors;
    jpeg_progress_mgr progress;
    std::memset(&cinfo, 0, sizeof cinfo);
    cinfo.err = jpeg_std_error(&errors.base);
    errors.base.error_exit = on_jpeg_error;
    errors.base.emit_message = on_jpeg_warning;
    errors.message[0] = '\0';
    progress.progress_monitor = limit_scans;

    if (setjmp(errors.jump)) {
        jpeg_destroy_decompress(&cinfo);
        throw file_error(name, 0, std::string("cannot decode JPEG: ") + errors.message);
    }
    jpeg_create_decompress(&cinfo);
    cinfo.progress = &progress;
    jpeg_mem_src(&cinfo, data, static_cast<unsigned long>(size));
    jpeg_read_header(&cinfo, TRUE);
    if (cinfo.jpeg_color_space == JCS_CMYK || cinfo.jpeg_color_space == JCS_YCCK) {
        jpeg_destroy_decompress(&cinfo);
        throw file_error(name, 0, "cannot decode JPEG: CMYK images are not supported (save as RGB)");
    }
    cinfo.out_color_space = cinfo.num_components == 1 ? JCS_GRAYSCALE : JCS_RGB;
    const int channels = cinfo.num_components == 1 ? 1 : 3;
    try {
        check_size(cinfo.image_width, cinfo.image_height, channels);
        image.texels.resize(size_t(cinfo.image_width) * cinfo.image_height * size_t(channels));
    } catch (const std::exception& e) {  // no jump crosses this block: it calls no libjpeg function
        refusal = e.what();
    }
    if (!refusal.empty()) {
        jpeg_destroy_decompress(&cinfo);
        throw Error(refusal);
    }
    image.width = int(cinfo.image_width);
    image.height = int(cinfo.image_height);
    image.channels = channels;

    jpeg_start_decompress(&cinfo);
    const size_t row_bytes = size_t(cinfo.output_width) * size_t(cinfo.output_components);
    while (cinfo.output_scanline < cinfo.output_height) {
        JSAMPROW row = image.texels.data() + size_t(cinfo.output_scanline) * row_bytes;
        jpeg_read_scanlines(&cinfo, &row, 1);
    }
    jpeg_finish_decompress(&cinfo);
    jpeg_destroy_decompress(&cinfo);
    return image;
}

}  // namespace rf
