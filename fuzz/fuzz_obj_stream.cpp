// The streaming OBJ converter (rf::pack::convert_obj_streaming,
// src/ooc/obj_stream_convert.h): the OBJ read in blocks, its arrays spilled
// to scratch files, its triangles binned into objects and written as a paged
// scene file, at the smallest budget the converter takes (kMinStreamBudget),
// checked against the in-core loader (rf::load_obj) on the same file.
//
// Input: one mode byte, then the OBJ file's bytes. Mode bit 0 turns
// compute_missing_normals off (for both loaders); bits 1-3 cap the triangles
// of an object (kObjectCaps: the budget's own, or 1 to 1000, so a file is cut
// into many objects and a crowded bin into pieces in file order); bit 4
// writes zstd pages; bits 5-7 pick the read block size (kReadBlocks: the
// default 4 MiB, or a few bytes, so lines, CRLF pairs and numbers are cut at
// block ends).
//
// What must hold:
//   1. both loaders succeed or throw rf::Error (anything else escapes to
//      libFuzzer);
//   2. they agree: both use the parser of src/io/obj_parser.h, so when
//      load_obj throws, the converter throws the same message (line numbers
//      included; "no faces" is the same file_error in both); a budget message
//      of load_obj (which has its own, larger budget) is the one exception;
//      when load_obj succeeds, the converter succeeds too;
//   3. after a success: the summary's triangles are load_obj's triangles, its
//      objects at least triangles / cap; the file opens (rf::pack::PackFile)
//      with the summary's triangles, pages, size and load_obj's materials,
//      and every page reads back (PackFile::read_page) and every geometry
//      page views (view_geometry_page) without an rf::Error.
// A broken invariant prints both sides to stderr and aborts.
// FUZZ_OBJ_STREAM_TRACE=1 in the environment prints each loader's outcome.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "ooc/obj_stream_convert.h"
#include "ooc/pack_file.h"
#include "ooc/pack_format.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace {

using namespace rf;
using namespace rf::pack;

constexpr uint8_t kNoNormals = 1;
constexpr uint8_t kZstd = 16;
constexpr uint64_t kObjectCaps[8] = {0, 1, 2, 3, 7, 64, 1000, 5};  // 0: what the budget allows
constexpr size_t kReadBlocks[8] = {size_t(4) << 20, 1, 2, 3, 7, 16, 64, 4096};

const bool g_trace = std::getenv("FUZZ_OBJ_STREAM_TRACE") != nullptr;

[[noreturn]] void fail(const std::string& what) {
    std::fprintf(stderr, "fuzz_obj_stream: invariant broken: %s\n", what.c_str());
    std::abort();
}

void check(bool ok, const std::string& what) {
    if (!ok) fail(what);
}

// Step 3's file checks: the header against the summary, every page read.
void check_file(const std::string& path, const PackSummary& summary, size_t materials) {
    std::optional<PackFile> file;
    std::vector<uint8_t> bytes, scratch;
    try {
        file.emplace(path);
        for (uint64_t i = 0; i < file->directory().size(); ++i) {
            file->read_page(i, bytes, scratch);
            if (i < file->header().geometry_pages) (void)view_geometry_page(bytes, "page " + std::to_string(i));
        }
    } catch (const rf::Error& e) {
        fail(std::string("the converter's file does not read back: ") + e.what());
    }
    const FileHeader& h = file->header();
    check(h.triangle_count == summary.triangles, "header triangles " + std::to_string(h.triangle_count) +
                                                     " != summary " + std::to_string(summary.triangles));
    check(h.geometry_pages == summary.geometry_pages && h.attribute_pages == summary.attribute_pages &&
              h.texture_pages == summary.texture_pages,
          "header page counts != summary");
    check(h.file_bytes == summary.file_bytes && std::filesystem::file_size(path) == summary.file_bytes,
          "file size != summary " + std::to_string(summary.file_bytes));
    check(file->materials().size() == materials, "file materials " + std::to_string(file->materials().size()) +
                                                     " != load_obj's " + std::to_string(materials));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    if (size < 1) return 0;
    const uint8_t mode = data[0];
    const std::string path = rf::fuzz::write_scratch("input.obj", data + 1, size - 1);
    const std::string folder = rf::fuzz::scratch_dir() + "/obj_stream";
    const std::string out = folder + "/out.rfpack";
    std::filesystem::create_directories(folder);
    std::filesystem::remove(out);  // so both loaders see the same folder (an mtllib may name anything)

    LoadOptions load;
    load.compute_missing_normals = (mode & kNoNormals) == 0;
    load.load_textures = false;
    std::optional<size_t> core_triangles, core_materials;
    std::string core_error;
    try {
        const Scene scene = load_obj(path, load);
        core_triangles = scene.triangle_count();
        core_materials = scene.materials.size();
    } catch (const rf::Error& e) {
        core_error = e.what();
    }

    PackWriterOptions writer;
    writer.codec = (mode & kZstd) ? Codec::Zstd : Codec::None;
    writer.threads = 1;
    StreamConvertOptions stream;
    stream.memory_budget = kMinStreamBudget;
    stream.temp_dir = folder;
    stream.compute_missing_normals = load.compute_missing_normals;
    stream.load_textures = false;
    stream.max_object_triangles = kObjectCaps[(mode >> 1) & 7];
    stream.read_block_bytes = kReadBlocks[(mode >> 5) & 7];
    std::optional<StreamConvertResult> result;
    std::string stream_error;
    try {
        result = convert_obj_streaming(path, out, writer, stream);
    } catch (const rf::Error& e) {
        stream_error = e.what();
    }
    if (g_trace) {
        std::fprintf(stderr, "fuzz_obj_stream: load_obj: %s\n",
                     core_triangles ? (std::to_string(*core_triangles) + " triangles").c_str() : core_error.c_str());
        std::fprintf(stderr, "fuzz_obj_stream: convert_obj_streaming: %s\n",
                     result ? (std::to_string(result->convert.summary.triangles) + " triangles, " +
                               std::to_string(result->objects) + " objects").c_str()
                            : stream_error.c_str());
    }

    if (!core_triangles) {
        if (core_error.find("memory budget") != std::string::npos) return 0;
        check(!result, "load_obj threw '" + core_error + "', the converter succeeded");
        check(stream_error == core_error, "load_obj threw '" + core_error + "', the converter '" + stream_error + "'");
        return 0;
    }
    check(result.has_value(), "load_obj succeeded, the converter threw '" + stream_error + "'");
    const PackSummary& summary = result->convert.summary;
    check(summary.triangles == *core_triangles, "converter triangles " + std::to_string(summary.triangles) +
                                                    " != load_obj's " + std::to_string(*core_triangles));
    const uint64_t cap = result->budget.max_object_triangles;
    check(cap > 0 && result->objects >= (summary.triangles + cap - 1) / cap && result->objects <= summary.triangles,
          std::to_string(result->objects) + " objects for " + std::to_string(summary.triangles) +
              " triangles at most " + std::to_string(cap) + " each");
    check_file(out, summary, *core_materials);
    std::filesystem::remove(out);
    return 0;
}
