// Scratch files for the streaming converter (obj_stream_convert.cpp): arrays
// too large for its memory budget live on disk, appended through a buffer
// and read back either in sequence or through a small block cache.
//
// A SpillFile is created in a given folder and unlinked at once, so it
// disappears when the process ends, also on a crash. CachedArray<T> reads
// (and, for accumulation, writes back) fixed-size blocks of a SpillFile with
// clock replacement; OBJ faces reference vertices written shortly before
// them, so a few blocks cover almost every access.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <algorithm>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace rf::pack {

class SpillFile {
public:
    // A new empty file in `folder` ("what" names it in errors).
    SpillFile(const std::string& folder, const std::string& what);
    ~SpillFile();
    SpillFile(const SpillFile&) = delete;
    SpillFile& operator=(const SpillFile&) = delete;

    // Appends through a 1 MiB buffer; flush() before reading.
    void append(const void* data, size_t bytes);
    void flush();
    // pread/pwrite of exactly `bytes`; rf::Error on a short read or a failed write.
    void read(uint64_t offset, void* data, size_t bytes) const;
    void write(uint64_t offset, const void* data, size_t bytes);
    // Grows the file to `bytes` (zeros), for arrays written at random offsets.
    void resize(uint64_t bytes);

    [[nodiscard]] uint64_t size() const { return size_ + buffer_.size(); }
    [[nodiscard]] const std::string& what() const { return what_; }

private:
    int fd_ = -1;
    std::string what_;
    uint64_t size_ = 0;  // bytes in the file
    std::vector<unsigned char> buffer_;
};

// Reads a SpillFile from the start in pieces of at most `bytes`.
class SpillReader {
public:
    SpillReader(const SpillFile& file, uint64_t begin, uint64_t end, size_t buffer_bytes = size_t(1) << 20);
    // The next element of type T, false at the end.
    template <class T>
    bool next(T& out) {
        static_assert(std::is_trivially_copyable_v<T>);
        if (pos_ + sizeof(T) > filled_ && !refill(sizeof(T))) return false;
        std::memcpy(&out, buffer_.data() + pos_, sizeof(T));
        pos_ += sizeof(T);
        return true;
    }
    [[nodiscard]] uint64_t offset() const { return file_offset_ - (filled_ - pos_); }

private:
    bool refill(size_t need);
    const SpillFile& file_;
    uint64_t file_offset_, end_;
    std::vector<unsigned char> buffer_;
    size_t pos_ = 0, filled_ = 0;
};

// The blocks of a SpillFile seen as an array of T, at most `cache_bytes` of
// them in memory.
template <class T>
class CachedArray {
public:
    static_assert(std::is_trivially_copyable_v<T>);
    static constexpr size_t kBlockBytes = size_t(64) << 10;
    static constexpr size_t kPerBlock = kBlockBytes / sizeof(T);

    CachedArray(SpillFile& file, uint64_t count, size_t cache_bytes)
        : file_(file), count_(count), slots_(std::max<size_t>(2, cache_bytes / kBlockBytes)) {}
    ~CachedArray() noexcept(false) { flush(); }

    [[nodiscard]] T get(uint64_t i) { return slot_for(i).data[i % kPerBlock]; }
    // For read-modify-write; the block is written back when it leaves.
    T& at(uint64_t i) {
        Slot& s = slot_for(i);
        s.dirty = true;
        return s.data[i % kPerBlock];
    }
    void flush() {
        for (Slot& s : slots_) write_back(s);
    }
    [[nodiscard]] uint64_t misses() const { return misses_; }

private:
    struct Slot {
        uint64_t block = ~uint64_t(0);
        bool used = false, dirty = false;
        std::vector<T> data;
    };
    uint64_t elements_in(uint64_t block) const { return std::min<uint64_t>(kPerBlock, count_ - block * kPerBlock); }
    void write_back(Slot& s) {
        if (!s.dirty) return;
        file_.write(s.block * kPerBlock * sizeof(T), s.data.data(), size_t(elements_in(s.block)) * sizeof(T));
        s.dirty = false;
    }
    Slot& slot_for(uint64_t i) {
        const uint64_t block = i / kPerBlock;
        if (last_ < slots_.size() && slots_[last_].block == block) return slots_[last_];
        if (const auto it = slot_of_.find(block); it != slot_of_.end()) {
            slots_[it->second].used = true;
            last_ = it->second;
            return slots_[it->second];
        }
        // Clock: the first slot not used since the hand last passed it.
        while (slots_[hand_].used) {
            slots_[hand_].used = false;
            hand_ = (hand_ + 1) % slots_.size();
        }
        Slot& s = slots_[hand_];
        last_ = hand_;
        hand_ = (hand_ + 1) % slots_.size();
        write_back(s);
        slot_of_.erase(s.block);
        slot_of_[block] = last_;
        s.data.resize(kPerBlock);
        file_.read(block * kPerBlock * sizeof(T), s.data.data(), size_t(elements_in(block)) * sizeof(T));
        s.block = block;
        s.used = true;
        ++misses_;
        return s;
    }

    SpillFile& file_;
    uint64_t count_;
    std::vector<Slot> slots_;
    std::unordered_map<uint64_t, size_t> slot_of_;  // block -> slot
    size_t hand_ = 0, last_ = ~size_t(0);
    uint64_t misses_ = 0;
};

}  // namespace rf::pack
