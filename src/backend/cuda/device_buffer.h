// RAII device memory. Allocation failures name the buffer and the bytes asked
// for, so an out-of-memory report says what did not fit. A buffer made with
// a MemoryMeter counts its bytes there for as long as it holds them: the
// device builders' peak memory (DeviceBuildStages::peak_device_bytes) is
// that meter's maximum, so a buffer leaves the count when its scope ends.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "backend/cuda/cuda_check.h"

namespace rf::cuda {

template <class T>
class DeviceBuffer;

// Sum of the live metered buffers, and its maximum.
class MemoryMeter {
public:
    [[nodiscard]] size_t peak() const { return peak_; }

private:
    template <class T>
    friend class DeviceBuffer;
    void add(size_t bytes) {
        live_ += bytes;
        if (live_ > peak_) peak_ = live_;
    }
    void remove(size_t bytes) { live_ -= bytes; }
    size_t live_ = 0, peak_ = 0;
};

template <class T>
class DeviceBuffer {
public:
    DeviceBuffer() = default;
    explicit DeviceBuffer(std::string name) : name_(std::move(name)) {}
    DeviceBuffer(std::string name, size_t count) : name_(std::move(name)) { allocate(count); }
    // Counted by `meter` while it holds memory (none for count 0).
    DeviceBuffer(MemoryMeter& meter, std::string name, size_t count = 0) : name_(std::move(name)), meter_(&meter) {
        allocate(count);
    }
    ~DeviceBuffer() { release(); }
    DeviceBuffer(const DeviceBuffer&) = delete;
    DeviceBuffer& operator=(const DeviceBuffer&) = delete;
    DeviceBuffer(DeviceBuffer&& o) noexcept { swap(o); }
    // Frees what this buffer held, then takes o's memory, name and meter.
    DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
        if (this != &o) {
            release();
            swap(o);
        }
        return *this;
    }

    void allocate(size_t count) {
        release();
        if (count == 0) return;
        const size_t bytes = count * sizeof(T);
        if (bytes / sizeof(T) != count) throw Error("device buffer '" + name_ + "': size overflows");
        cudaError_t status = cudaMalloc(reinterpret_cast<void**>(&data_), bytes);
        if (status != cudaSuccess) {
            (void)cudaGetLastError();  // clear the sticky-free error so later calls work
            data_ = nullptr;
            throw Error("out of device memory: buffer '" + name_ + "' asked for " + std::to_string(bytes) +
                        " bytes (" + cudaGetErrorString(status) + ")");
        }
        count_ = count;
        if (meter_) meter_->add(bytes);
    }
    // Grows (never shrinks) to hold at least `count` elements; contents are lost when it grows.
    void reserve(size_t count) {
        if (count > count_) allocate(count);
    }
    void upload(std::span<const T> host) {
        if (host.size() != count_) allocate(host.size());
        if (!host.empty()) RF_CUDA_CHECK(cudaMemcpy(data_, host.data(), host.size_bytes(), cudaMemcpyHostToDevice));
    }
    void download(std::span<T> host) const {
        if (host.size() > count_) throw Error("device buffer '" + name_ + "': download larger than the buffer");
        if (!host.empty()) RF_CUDA_CHECK(cudaMemcpy(host.data(), data_, host.size_bytes(), cudaMemcpyDeviceToHost));
    }
    void release() {
        if (meter_) meter_->remove(bytes());
        if (data_) cudaFree(data_);
        data_ = nullptr;
        count_ = 0;
    }
    [[nodiscard]] T* data() const { return data_; }
    [[nodiscard]] const std::string& name() const { return name_; }
    [[nodiscard]] size_t size() const { return count_; }
    [[nodiscard]] size_t bytes() const { return count_ * sizeof(T); }

private:
    void swap(DeviceBuffer& o) noexcept {
        std::swap(name_, o.name_);
        std::swap(data_, o.data_);
        std::swap(count_, o.count_);
        std::swap(meter_, o.meter_);
    }
    std::string name_;
    T* data_ = nullptr;
    size_t count_ = 0;
    MemoryMeter* meter_ = nullptr;
};

// Page-locked host memory for `count` values: the target of asynchronous
// device-to-host copies, read by the host once an event says they landed.
template <class T>
class PinnedValues {
public:
    explicit PinnedValues(size_t count) {
        RF_CUDA_CHECK(cudaHostAlloc(reinterpret_cast<void**>(&data_), count * sizeof(T), cudaHostAllocDefault));
        count_ = count;
    }
    ~PinnedValues() {
        if (data_) cudaFreeHost(data_);
    }
    PinnedValues(const PinnedValues&) = delete;
    PinnedValues& operator=(const PinnedValues&) = delete;
    [[nodiscard]] T* data() const { return data_; }
    [[nodiscard]] size_t size() const { return count_; }
    T& operator[](size_t i) const { return data_[i]; }

private:
    T* data_ = nullptr;
    size_t count_ = 0;
};

// The first `count` elements, on the host.
template <class T>
std::vector<T> download_all(const DeviceBuffer<T>& buffer, size_t count) {
    std::vector<T> host(count);
    buffer.download(host);
    return host;
}

// One element, on the host.
template <class T>
T download_value(const T* device_value) {
    T value{};
    RF_CUDA_CHECK(cudaMemcpy(&value, device_value, sizeof value, cudaMemcpyDeviceToHost));
    return value;
}

}  // namespace rf::cuda
