// Textures of a paged scene (Garanzha 2014, §6.5) sampled on the CPU: the
// in-core lookup's arithmetic (render/texture_sampling.h: bilinear taps and
// weights, wrap modes, the mip blend; render/texture_lod.h: the level) over
// texels copied out of the texture tile cache (ooc/texture_cache.h), which
// reads missing tiles on demand. For the same texture it gives the in-core
// result exactly (tiles hold the same 8-bit codes as the texture and its
// MipChain); float textures differ by their 8-bit storage.
#pragma once

#include <vector>

#include "ooc/pack_file.h"
#include "ooc/pack_format.h"
#include "ooc/texture_cache.h"
#include "rayforge/math/vec.h"

namespace rf {

// A view of one texture of a pack file and the cache its tiles go through
// (both must outlive it). In namespace rf so that the material templates of
// render/material_eval.h find sample_texture_at below by argument-dependent lookup.
struct PagedTexture {
    const pack::TextureInfo* info = nullptr;
    pack::TextureTileCache* cache = nullptr;
};

// One per texture of `file`, in its order (material texture ids index it).
std::vector<PagedTexture> make_paged_textures(const pack::PackFile& file, pack::TextureTileCache& cache);

// Bilinearly filtered linear RGBA of mip level `level` at uv (as
// sample_texture(const TextureView&, Vec2f) on that level).
Vec4f sample_texture(const PagedTexture& t, int level, Vec2f uv);
// Trilinear lookup at `lod` (as sample_texture(const MipTextureView&, Vec2f, float)).
Vec4f sample_texture(const PagedTexture& t, Vec2f uv, float lod);
// The lookup of material_eval.h at `lod_base` (texture_lod.h). A view
// without a texture or cache samples as white, as an invalid TextureView.
// rf::Error when a tile cannot be read.
Vec4f sample_texture_at(const PagedTexture& t, Vec2f uv, float lod_base);

}  // namespace rf
