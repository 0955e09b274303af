// The texture page manager of the CPU (Garanzha 2014, §6.5, after Peachey
// 1990, "Texture on Demand"): a budgeted cache of 32x32 RGBA8 texture tiles
// (one texture page each, pack_format.h) in this process's memory, filled on
// demand. A texel fetch whose tile is missing reads it from the file right
// there (pread), under the lock of the shard that owns the tile: shading
// threads on the CPU can block on I/O cheaply, so no request loop is needed
// (the GPU would defer its lookups to the batch loop instead).
//
// Callers get copies of the texels they ask for, taken under the lock, never
// pointers into the pool: another thread may evict the tile a moment later.
// So a lookup pins nothing, and any pool of at least one slot per shard is
// correct; kMinSlots asks for more so that the taps of several threads'
// filters do not evict each other at every fetch.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "ooc/pack_file.h"
#include "ooc/page_cache.h"

namespace rf::pack {

// One RGBA8 texel as stored in a tile (colour codes in the texture's encoding, alpha linear).
using Texel8 = std::array<uint8_t, 4>;

// A texel of a tile: the tile's index among the file's texture pages and the
// texel's index within the tile (y * kTextureTileSide + x).
struct TexelAddress {
    uint32_t tile = 0;
    uint32_t texel = 0;
};

class TextureTileCache {
public:
    static constexpr size_t kTileBytes = size_t(kTextureTileSide) * kTextureTileSide * 4;
    // The fewest slots accepted (or every tile, when the file has fewer).
    static constexpr uint32_t kMinSlots = 16;
    static constexpr uint32_t kMaxShards = 64;

    // The smallest budget for which the constructor gives `slots` slots
    // (when the file has that many tiles): the slots, their tables and the shards.
    [[nodiscard]] static size_t budget_for_slots(uint32_t slots);

    // The texture pages of `file`, which must outlive the cache; as many
    // slots as fit in budget_bytes with the tables (memory_bytes() <=
    // budget_bytes), at most one per tile. rf::Error naming `name` when
    // fewer than min(kMinSlots, tiles) fit, or a texture page is not a
    // 4096-byte tile. A file without textures needs no pool (any budget).
    TextureTileCache(const PackFile& file, size_t budget_bytes, std::string name = "textures");
    ~TextureTileCache();
    TextureTileCache(const TextureTileCache&) = delete;
    TextureTileCache& operator=(const TextureTileCache&) = delete;

    // Copies the texels at `addresses` into `out` (same length), reading the
    // tiles that are missing; each distinct tile is looked up once. Meant
    // for a filter's few taps. Thread-safe. rf::Error naming the tile and
    // its page when a tile is outside the file or fails to read (the cache
    // stays usable; texels already copied are kept).
    void fetch(std::span<const TexelAddress> addresses, std::span<Texel8> out);
    [[nodiscard]] Texel8 fetch(TexelAddress address);

    [[nodiscard]] const std::string& name() const { return name_; }
    [[nodiscard]] uint32_t page_count() const { return page_count_; }  // tiles in the file
    [[nodiscard]] uint32_t slot_count() const { return slot_count_; }
    [[nodiscard]] uint32_t shard_count() const { return shard_count_; }
    [[nodiscard]] uint32_t cached_count() const;

    // Every tile out (stats kept).
    void clear();
    // Summed over the shards; requests count tile lookups (a fetch of four
    // texels in one tile is one request). swaps and manage_ms stay 0: there
    // is no swap loop.
    [[nodiscard]] PageCacheStats stats() const;
    void reset_stats();
    // The pool, the slot and hash tables and the shards (with their read
    // buffers): what this cache holds in memory.
    [[nodiscard]] size_t memory_bytes() const;

    // A shard's lock, clock and hash table (defined in the .cpp).
    struct Shard;

private:

    [[nodiscard]] Shard& shard_of(uint32_t tile) const;
    [[nodiscard]] uint32_t find(const Shard& s, uint32_t tile) const;
    void insert(Shard& s, uint32_t tile, uint32_t slot);
    void erase(Shard& s, uint32_t tile);
    uint32_t take_victim(Shard& s);
    uint32_t load(Shard& s, uint32_t tile);
    [[nodiscard]] uint32_t lookup_or_load(Shard& s, uint32_t tile);

    const PackFile& file_;
    std::string name_;
    uint64_t first_page_ = 0;    // directory index of tile 0
    uint32_t page_count_ = 0;
    uint32_t slot_count_ = 0;
    uint32_t shard_count_ = 0;
    uint32_t shard_shift_ = 32;  // a tile's shard: the top bits of its hash
    std::unique_ptr<uint8_t[]> pool_;
    std::unique_ptr<uint32_t[]> slot_tile_;  // the tile each slot holds, or kNoTile
    std::unique_ptr<uint8_t[]> slot_uses_;   // 5-bit use counts
    std::unique_ptr<uint32_t[]> tables_;     // every shard's hash table (slot indices)
    size_t table_entries_ = 0;
    std::unique_ptr<Shard[]> shards_;
};

}  // namespace rf::pack
