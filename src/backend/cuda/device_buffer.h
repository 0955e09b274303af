// RAII device memory. Allocation failures name the buffer and the bytes asked
// for, so an out-of-memory report says what did not fit.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <utility>

#include "backend/cuda/cuda_check.h"

namespace rf::cuda {

template <class T>
class DeviceBuffer {
public:
    DeviceBuffer() = default;
    explicit DeviceBuffer(std::string name) : name_(std::move(name)) {}
    DeviceBuffer(std::string name, size_t count) : name_(std::move(name)) { allocate(count); }
    ~DeviceBuffer() { release(); }
    DeviceBuffer(const DeviceBuffer&) = delete;
    DeviceBuffer& operator=(const DeviceBuffer&) = delete;
    DeviceBuffer(DeviceBuffer&& o) noexcept { swap(o); }
    DeviceBuffer& operator=(DeviceBuffer&& o) noexcept { swap(o); return *this; }

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
    }
    std::string name_;
    T* data_ = nullptr;
    size_t count_ = 0;
};

}  // namespace rf::cuda
