// Device and GPU-kernel names (rayforge/backend/device.h): what `--device`
// and `--gpu-kernel` accept in every build, with or without the CUDA backend.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "rayforge/backend/device.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

TEST(Device, ParsesCpuAndCudaOrdinals) {
    EXPECT_EQ(parse_device("cpu"), (Device{Device::Kind::Cpu, 0}));
    EXPECT_FALSE(parse_device("cpu").is_cuda());
    EXPECT_EQ(parse_device("cuda"), (Device{Device::Kind::Cuda, 0}));
    EXPECT_EQ(parse_device("cuda:0"), (Device{Device::Kind::Cuda, 0}));
    const Device third = parse_device("cuda:3");
    EXPECT_TRUE(third.is_cuda());
    EXPECT_EQ(third.index, 3);
    EXPECT_EQ(to_string(third), "cuda:3");
    EXPECT_EQ(to_string(parse_device("cpu")), "cpu");
    EXPECT_EQ(parse_device(to_string(third)), third);
}

TEST(Device, RejectsMalformedNames) {
    for (const char* name : {"", "gpu", "CPU", "cuda:", "cuda:x", "cuda:-1", "cuda:1a", "cuda3", " cuda", "cuda:0 "})
        EXPECT_THROW(parse_device(name), Error) << "'" << name << "'";
    try {
        parse_device("bogus");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("bogus"), std::string::npos) << e.what();
    }
}

TEST(DeviceGpuKernel, NamesRoundTripAndAreDistinct) {
    const auto kernels = all_gpu_kernels();
    EXPECT_EQ(kernels.size(), 9u);
    std::set<std::string> names;
    for (GpuKernel kernel : kernels) {
        const std::string name = to_string(kernel);
        EXPECT_EQ(parse_gpu_kernel(name), kernel) << name;
        names.insert(name);
    }
    EXPECT_EQ(names.size(), kernels.size());
    for (const char* name : {"bvh2", "aila-laine", "aila-laine-fma", "cwbvh", "cwbvh-fma", "kd-short-stack", "kd-restart", "grid", "grid-proximity"})
        EXPECT_EQ(names.count(name), 1u) << name;
    EXPECT_EQ(to_string(kDefaultGpuKernel), "aila-laine");
}

TEST(DeviceGpuKernel, RejectsUnknownNames) {
    for (const char* name : {"", "bogus", "CWBVH", "kdtree", "bvh"}) EXPECT_THROW(parse_gpu_kernel(name), Error) << name;
}

}  // namespace
}  // namespace rf
