// Converting an OBJ file of any size into a paged scene file within a memory
// budget (the dissertation's preprocessor works out of core, §6.3.1): the
// file is read once in blocks and its arrays are spilled to scratch files
// (spill_file.h); triangles are then cut into spatially compact objects
// (bins of a 128^3 grid over the vertices' bounds, taken in Morton order
// until an object holds the most the budget allows) and each object goes
// through the PackWriter as `generate`'s objects do.
//
// Passes over the input and the scratch files:
//   1. parse: v/vt/vn appended to their scratch arrays, each triangle's
//      corners and material (40 bytes) to the triangle array;
//   2. (when a face has no normal) area-weighted vertex normals accumulated
//      per position index, through a write-back block cache;
//   3. count triangles per bin (centroids; positions through a read cache);
//   4. distribute: each triangle, resolved to positions and its 64-byte
//      shading record, written into its object's region (112 bytes);
//   5. per object: vertices welded by their OBJ position index (so the quad
//      pairing sees the file's topology), then PackWriter::add_object.
// Memory: the budget covers the bins (12 bytes each), the caches, the
// buffers and the largest object (kObjectBytesPerTriangle a triangle);
// scratch space is about 40 + 112 bytes a triangle plus the vertex arrays.
//
// One difference from load_obj: missing normals are smoothed per OBJ
// position, where load_obj smooths per (v, vt, vn) mesh vertex (so it keeps
// a crease at a uv seam that this converter smooths over).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "ooc/convert_scene.h"

namespace rf::pack {

// Working memory per triangle of an object: its 112-byte record, the
// welding map, positions, indices, shading records and the writer's own.
inline constexpr size_t kObjectBytesPerTriangle = 112 + 48 + 6 + 12 + 64 + kWriterBytesPerTriangle;
inline constexpr size_t kMinStreamBudget = size_t(96) << 20;
inline constexpr size_t kStreamReadBlock = size_t(4) << 20;  // the input's read size, part of the fixed bytes

struct StreamConvertOptions {
    size_t memory_budget = size_t(1) << 30;  // bytes, at least kMinStreamBudget
    std::string temp_dir;                    // scratch files; "" = the output's folder
    bool compute_missing_normals = true;     // as LoadOptions
    bool load_textures = true;
    uint64_t max_object_triangles = 0;       // 0 = what the budget allows; else at most this (tests, fuzzing)
    size_t read_block_bytes = kStreamReadBlock;  // the input is read in blocks of this size (>= 1)
};

// How a budget is divided (exposed for tests and the summary).
struct StreamBudget {
    size_t fixed_bytes = 0;       // bins, I/O buffers
    size_t cache_bytes = 0;       // the vertex-array block caches, together
    uint64_t max_object_triangles = 0;
};
StreamBudget plan_stream_budget(size_t memory_budget);

struct StreamConvertResult {
    ConvertResult convert;
    uint64_t objects = 0;        // objects handed to the writer
    uint64_t scratch_bytes = 0;  // the scratch files' largest total size
    StreamBudget budget;
};

// rf::Error (one line) on a malformed file (as load_obj's messages), a
// budget below kMinStreamBudget, or a scratch folder that cannot be written.
StreamConvertResult convert_obj_streaming(const std::string& obj_path, const std::string& out_path,
                                          const PackWriterOptions& options, const StreamConvertOptions& stream,
                                          const ProgressCallback& progress = {});

}  // namespace rf::pack
