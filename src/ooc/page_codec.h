// How a page's bytes are stored (PageEntry::codec): as they are, as one
// zstd frame, or (Codec::Meshopt, the default) with meshoptimizer's vertex
// codec run over each array of fixed-size records (a geometry page's nodes
// and quads, an attribute page's vertices, triangles and records), its
// index-sequence codec over a shared attribute page's corners, and zstd
// over the result. The meshopt codecs turn the byte columns of neighbouring
// records into small deltas, which is what zstd alone does not find in
// 24-byte quads and 80-byte nodes (docs/paged-scenes.md has the sizes).
//
// A Meshopt page as stored: a zstd frame of
//   uint32_t prefix_bytes, the page's first prefix_bytes raw (its header;
//   for a shared attribute page also its materials),
//   per array: uint32_t encoded_bytes, the encoded array,
//   the raw bytes after the last array (uint32_t count, bytes).
// The arrays are found from the prefix, so the decoder needs no more than
// the page kind, the file's attribute format and the raw size (from the
// directory); every length is checked before use.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ooc/pack_format.h"

namespace rf::pack {

struct StoredPage {
    std::vector<uint8_t> bytes;
    uint32_t raw_bytes = 0;
    Codec codec = Codec::None;  // the codec used: None where the asked one does not make the page smaller
};

// `raw` as stored with `codec` (zstd at `zstd_level`). Texture tiles are
// not arrays of records: Meshopt stores them with zstd alone.
[[nodiscard]] StoredPage encode_page(std::vector<uint8_t> raw, PageKind kind, AttributeFormat format, Codec codec,
                                     int zstd_level);

// Decodes `stored` (codec Zstd or Meshopt) into `raw` (exactly the page's
// raw size); false when the bytes do not decode to that size. (A Meshopt
// page's intermediate stream is held in a buffer of the calling thread.)
[[nodiscard]] bool decode_page(std::span<const uint8_t> stored, Codec codec, PageKind kind, AttributeFormat format,
                               std::span<uint8_t> raw);

}  // namespace rf::pack
