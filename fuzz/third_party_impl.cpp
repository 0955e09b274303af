// The implementations of the header-only parsers the loaders use, compiled
// here (instrumented) instead of linking Debian's prebuilt libstb, libtinyexr,
// libtinygltf and libtinyobjloader, so that libFuzzer's coverage and ASan see
// inside them. The same system headers are used: nothing is vendored.
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image.h>
#include <stb_image_write.h>

#define TINYEXR_IMPLEMENTATION
#include <tinyexr.h>

#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_INCLUDE_STB_IMAGE
#define TINYGLTF_NO_INCLUDE_STB_IMAGE_WRITE
#include <tiny_gltf.h>

#define TINYOBJLOADER_IMPLEMENTATION
#include <tiny_obj_loader.h>
