// The texture tile cache: demand paging of 32x32 RGBA8 tiles (Peachey 1990,
// "Texture on Demand"; Garanzha 2014, §6.5), synchronous, from many shading
// threads at once.
//
// Sharding: a tile belongs to one of up to kMaxShards shards, chosen by the
// top bits of a hash of its id (the taps of one filter, neighbouring tiles,
// land in different shards); each shard owns a fixed run of the pool's
// slots, a mutex and an open-addressing table tile -> slot (linear probing,
// at most half full, deletion by backward shift, so no tombstones pile up).
// A hit costs one lock, one probe and a copy of the few texels asked for; a
// miss also reads the tile under the lock, which holds up only the threads
// that want the same shard.
//
// Eviction: Garanzha 2014's manager (§6.2) keeps a 5-bit use count per page,
// zeroes the counts every 10th swap and evicts the least used after a sort
// of all page ids. Here a victim is needed at every miss, by one thread
// under one shard's lock, so there is no swap to sort at: instead the
// shard's slots are swept by a clock hand (generalised CLOCK), with the same
// counts. A use adds 1 (saturating at 31, the loading use included); the
// hand evicts the first slot whose count is 0 and halves the counts of the
// slots it passes. So counts age at the pace of the shard's misses, as the
// dissertation's periodic reset ages them at the pace of its swaps, and a tile used
// n times survives about log2(n) + 1 sweeps, an approximate LFU that favours
// recent use, found in O(1) amortised steps (a sweep ends within 6 turns).
//
// Memory: the pool is allocated once, not zero-filled (untouched slots are
// not resident), and the budget covers it with every table and each shard's
// buffer for reading a compressed tile (reserved once: a tile's stored size
// is at most its raw size, checked at construction).
#include "ooc/texture_cache.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <mutex>

#include "rayforge/core/error.h"

namespace rf::pack {

namespace {

constexpr uint32_t kNoTile = 0xFFFFFFFFu;
constexpr uint32_t kEmptyEntry = 0xFFFFFFFFu;
constexpr uint8_t kMaxUses = 31;              // 5-bit counts, as Garanzha 2014's TimeUsed
constexpr uint32_t kMinSlotsPerShard = 8;     // fewer shards rather than shards of a few slots
constexpr uint32_t kMaxSlots = 0x7FFFFFFFu;

// What one slot costs besides its tile: its tile id and use count, and at
// most four hash-table entries (a shard's table is the power of two at or
// above twice its slots).
constexpr size_t kBytesPerSlot = TextureTileCache::kTileBytes + sizeof(uint32_t) + 1 + 4 * sizeof(uint32_t);

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// A 32-bit finaliser (MurmurHash3's fmix32 constants): tile ids are dense
// and neighbouring, the shards and tables want them spread.
uint32_t hash_tile(uint32_t tile) {
    tile ^= tile >> 16;
    tile *= 0x85EBCA6Bu;
    tile ^= tile >> 13;
    tile *= 0xC2B2AE35u;
    tile ^= tile >> 16;
    return tile;
}

// The most shards (a power of two) that keep kMinSlotsPerShard slots each.
uint32_t shards_for(uint32_t slots) {
    uint32_t shards = 1;
    while (shards * 2 <= TextureTileCache::kMaxShards && slots / (shards * 2) >= kMinSlotsPerShard) shards *= 2;
    return shards;
}

size_t table_capacity(uint32_t slots) { return std::bit_ceil(std::max<size_t>(2 * size_t(slots), 2)); }

}  // namespace

struct alignas(64) TextureTileCache::Shard {
    std::mutex mutex;
    uint32_t first_slot = 0;
    uint32_t slot_count = 0;
    uint32_t hand = 0;    // the clock's next slot, relative to first_slot
    uint32_t cached = 0;
    uint32_t* table = nullptr;
    uint32_t table_mask = 0;
    std::vector<uint8_t> scratch;  // stored bytes of a compressed tile
    PageCacheStats stats;
};

namespace {

// What a shard costs besides its slots: itself and its read buffer.
constexpr size_t kBytesPerShard = sizeof(TextureTileCache::Shard) + TextureTileCache::kTileBytes;

// Memory of `slots` slots in shards_for(slots) shards, at most: grows with
// the slots, so the most slots within a budget are found by bisection.
size_t bytes_for_slots(uint32_t slots) {
    return slots == 0 ? 0 : shards_for(slots) * kBytesPerShard + size_t(slots) * kBytesPerSlot;
}

// The most slots (at most `tiles`) that fit the budget.
uint32_t fit_budget(size_t budget_bytes, uint32_t tiles) {
    uint32_t lo = 0, hi = uint32_t(std::min<size_t>({tiles, kMaxSlots, budget_bytes / kBytesPerSlot}));
    while (lo < hi) {
        const uint32_t mid = lo + (hi - lo + 1) / 2;
        if (bytes_for_slots(mid) <= budget_bytes) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

// Texture pages must be tiles: 4096 bytes raw, stored in at most as many
// (so a shard's read buffer, reserved once, never grows).
void check_tiles(const PackFile& file, const std::string& name) {
    const std::span<const PageEntry> directory = file.directory();
    for (uint64_t page = file.first_texture_page(); page < directory.size(); ++page) {
        const PageEntry& e = directory[size_t(page)];
        if (e.raw_bytes != TextureTileCache::kTileBytes || e.stored_bytes > TextureTileCache::kTileBytes)
            throw Error(name + ": " + file.path() + ": page " + std::to_string(page) + " holds " +
                        std::to_string(e.raw_bytes) + " bytes (" + std::to_string(e.stored_bytes) +
                        " stored), not a texture tile of " + std::to_string(TextureTileCache::kTileBytes));
    }
}

}  // namespace

size_t TextureTileCache::budget_for_slots(uint32_t slots) { return bytes_for_slots(slots); }

TextureTileCache::TextureTileCache(const PackFile& file, size_t budget_bytes, std::string name)
    : file_(file), name_(std::move(name)), first_page_(file.first_texture_page()),
      page_count_(file.header().texture_pages) {
    check_tiles(file, name_);
    slot_count_ = fit_budget(budget_bytes, page_count_);
    const uint32_t need = std::min(kMinSlots, page_count_);
    if (slot_count_ < need)
        throw Error(name_ + ": a budget of " + std::to_string(budget_bytes) + " bytes holds " +
                    std::to_string(slot_count_) + " texture tiles; at least " + std::to_string(need) +
                    " are needed (the bilinear taps of several threads at once), i.e. a budget of " +
                    std::to_string(budget_for_slots(need)) + " bytes");
    shard_count_ = slot_count_ == 0 ? 0 : shards_for(slot_count_);
    if (slot_count_ == 0) return;
    shard_shift_ = 32 - uint32_t(std::countr_zero(shard_count_));
    pool_.reset(new uint8_t[size_t(slot_count_) * kTileBytes]);
    slot_tile_.reset(new uint32_t[slot_count_]);
    slot_uses_.reset(new uint8_t[slot_count_]);
    std::fill_n(slot_tile_.get(), slot_count_, kNoTile);
    std::fill_n(slot_uses_.get(), slot_count_, uint8_t(0));
    shards_.reset(new Shard[shard_count_]);
    uint32_t first_slot = 0;
    for (uint32_t i = 0; i < shard_count_; ++i) {
        Shard& s = shards_[i];
        s.first_slot = first_slot;
        s.slot_count = slot_count_ / shard_count_ + (i < slot_count_ % shard_count_ ? 1 : 0);
        first_slot += s.slot_count;
        table_entries_ += table_capacity(s.slot_count);
        s.scratch.reserve(kTileBytes);
    }
    tables_.reset(new uint32_t[table_entries_]);
    std::fill_n(tables_.get(), table_entries_, kEmptyEntry);
    size_t at = 0;
    for (uint32_t i = 0; i < shard_count_; ++i) {
        Shard& s = shards_[i];
        const size_t capacity = table_capacity(s.slot_count);
        s.table = tables_.get() + at;
        s.table_mask = uint32_t(capacity - 1);
        at += capacity;
    }
}

TextureTileCache::~TextureTileCache() = default;

TextureTileCache::Shard& TextureTileCache::shard_of(uint32_t tile) const {
    return shards_[shard_count_ == 1 ? 0 : hash_tile(tile) >> shard_shift_];
}

uint32_t TextureTileCache::find(const Shard& s, uint32_t tile) const {
    for (uint32_t i = hash_tile(tile) & s.table_mask;; i = (i + 1) & s.table_mask) {
        const uint32_t slot = s.table[i];
        if (slot == kEmptyEntry || slot_tile_[slot] == tile) return slot;
    }
}

void TextureTileCache::insert(Shard& s, uint32_t tile, uint32_t slot) {
    uint32_t i = hash_tile(tile) & s.table_mask;
    while (s.table[i] != kEmptyEntry) i = (i + 1) & s.table_mask;
    s.table[i] = slot;
}

// Linear probing's deletion: later entries of the run move back into the
// hole unless their home lies cyclically after it.
void TextureTileCache::erase(Shard& s, uint32_t tile) {
    const uint32_t mask = s.table_mask;
    uint32_t hole = hash_tile(tile) & mask;
    while (slot_tile_[s.table[hole]] != tile) hole = (hole + 1) & mask;
    for (uint32_t next = (hole + 1) & mask; s.table[next] != kEmptyEntry; next = (next + 1) & mask) {
        const uint32_t home = hash_tile(slot_tile_[s.table[next]]) & mask;
        const bool stays = hole <= next ? (hole < home && home <= next) : (hole < home || home <= next);
        if (stays) continue;
        s.table[hole] = s.table[next];
        hole = next;
    }
    s.table[hole] = kEmptyEntry;
}

// The clock: the first empty slot or slot used 0 times since the hand last
// passed it; the counts of the others halve as it passes.
uint32_t TextureTileCache::take_victim(Shard& s) {
    for (;;) {
        const uint32_t slot = s.first_slot + s.hand;
        s.hand = s.hand + 1 == s.slot_count ? 0 : s.hand + 1;
        if (slot_tile_[slot] == kNoTile || slot_uses_[slot] == 0) return slot;
        slot_uses_[slot] >>= 1;
    }
}

// Reads `tile` into a victim's slot (shard locked). A failed read leaves the slot empty.
uint32_t TextureTileCache::load(Shard& s, uint32_t tile) {
    const uint32_t slot = take_victim(s);
    if (slot_tile_[slot] != kNoTile) {
        erase(s, slot_tile_[slot]);
        slot_tile_[slot] = kNoTile;
        --s.cached;
        ++s.stats.evictions;
    }
    slot_uses_[slot] = 0;
    const uint64_t page = first_page_ + tile;
    const Clock::time_point start = Clock::now();
    size_t bytes = 0;
    try {
        bytes = file_.read_page(page, std::span<uint8_t>(pool_.get() + size_t(slot) * kTileBytes, kTileBytes),
                                s.scratch);
    } catch (const Error& e) {
        s.stats.io_ms += ms_since(start);
        throw Error(name_ + ": texture tile " + std::to_string(tile) + " (page " + std::to_string(page) +
                    "): " + e.what());
    }
    s.stats.io_ms += ms_since(start);
    ++s.stats.pages_read;
    s.stats.bytes_read += bytes;
    slot_tile_[slot] = tile;
    insert(s, tile, slot);
    ++s.cached;
    return slot;
}

uint32_t TextureTileCache::lookup_or_load(Shard& s, uint32_t tile) {
    ++s.stats.requests;
    uint32_t slot = find(s, tile);
    if (slot != kEmptyEntry) {
        ++s.stats.hits;
    } else {
        ++s.stats.misses;
        slot = load(s, tile);
    }
    if (slot_uses_[slot] < kMaxUses) ++slot_uses_[slot];
    return slot;
}

void TextureTileCache::fetch(std::span<const TexelAddress> addresses, std::span<Texel8> out) {
    if (out.size() != addresses.size())
        throw Error(name_ + ": fetch of " + std::to_string(addresses.size()) + " texels into " +
                    std::to_string(out.size()));
    constexpr uint32_t kTexels = kTextureTileSide * kTextureTileSide;
    // One lock and lookup per distinct tile, in chunks of 64 addresses (a bit mask of those done).
    for (size_t chunk = 0; chunk < addresses.size(); chunk += 64) {
        const size_t n = std::min<size_t>(64, addresses.size() - chunk);
        uint64_t done = 0;
        for (size_t i = 0; i < n; ++i) {
            if ((done >> i) & 1) continue;
            const uint32_t tile = addresses[chunk + i].tile;
            if (tile >= page_count_)
                throw Error(name_ + ": texture tile " + std::to_string(tile) + " is past the file's " +
                            std::to_string(page_count_) + " tiles");
            Shard& s = shard_of(tile);
            const std::lock_guard<std::mutex> lock(s.mutex);
            const uint8_t* texels = pool_.get() + size_t(lookup_or_load(s, tile)) * kTileBytes;
            for (size_t j = i; j < n; ++j) {
                const TexelAddress a = addresses[chunk + j];
                if (a.tile != tile) continue;
                if (a.texel >= kTexels)
                    throw Error(name_ + ": texel " + std::to_string(a.texel) + " is past a tile's " +
                                std::to_string(kTexels));
                std::memcpy(out[chunk + j].data(), texels + size_t(a.texel) * 4, 4);
                done |= uint64_t(1) << j;
            }
        }
    }
}

Texel8 TextureTileCache::fetch(TexelAddress address) {
    Texel8 texel{};
    fetch(std::span<const TexelAddress>(&address, 1), std::span<Texel8>(&texel, 1));
    return texel;
}

uint32_t TextureTileCache::cached_count() const {
    uint32_t cached = 0;
    for (uint32_t i = 0; i < shard_count_; ++i) {
        const std::lock_guard<std::mutex> lock(shards_[i].mutex);
        cached += shards_[i].cached;
    }
    return cached;
}

void TextureTileCache::clear() {
    for (uint32_t i = 0; i < shard_count_; ++i) {
        Shard& s = shards_[i];
        const std::lock_guard<std::mutex> lock(s.mutex);
        std::fill_n(slot_tile_.get() + s.first_slot, s.slot_count, kNoTile);
        std::fill_n(slot_uses_.get() + s.first_slot, s.slot_count, uint8_t(0));
        std::fill_n(s.table, size_t(s.table_mask) + 1, kEmptyEntry);
        s.hand = 0;
        s.cached = 0;
    }
}

PageCacheStats TextureTileCache::stats() const {
    PageCacheStats sum;
    for (uint32_t i = 0; i < shard_count_; ++i) {
        const std::lock_guard<std::mutex> lock(shards_[i].mutex);
        const PageCacheStats& s = shards_[i].stats;
        sum.requests += s.requests;
        sum.hits += s.hits;
        sum.misses += s.misses;
        sum.pages_read += s.pages_read;
        sum.bytes_read += s.bytes_read;
        sum.evictions += s.evictions;
        sum.io_ms += s.io_ms;
    }
    return sum;
}

void TextureTileCache::reset_stats() {
    for (uint32_t i = 0; i < shard_count_; ++i) {
        const std::lock_guard<std::mutex> lock(shards_[i].mutex);
        shards_[i].stats = {};
    }
}

size_t TextureTileCache::memory_bytes() const {
    return size_t(slot_count_) * (kTileBytes + sizeof(uint32_t) + 1) + table_entries_ * sizeof(uint32_t) +
           size_t(shard_count_) * kBytesPerShard;
}

}  // namespace rf::pack
