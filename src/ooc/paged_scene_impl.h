// What rf::PagedScene is made of inside the library: the file, the query
// engine (geometry and attribute managers), the texture tile cache, and the
// engine behind rf::Accel. The paged renderer reaches the engine and the
// textures through it.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "ooc/pack_file.h"
#include "ooc/paged_engine.h"
#include "ooc/paged_texture.h"
#include "ooc/texture_cache.h"
#include "rayforge/ooc/paged_scene.h"

namespace rf::pack {

// Batches run the engine's query loop; a single ray is a batch of one.
class PagedAccel final : public Accel {
public:
    explicit PagedAccel(PagedEngine& engine);
    [[nodiscard]] Hit intersect(const Ray& ray) const override;
    [[nodiscard]] bool occluded(const Ray& ray) const override;
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override;
    [[nodiscard]] AccelStats stats() const override;

private:
    PagedEngine& engine_;
};

class PagedSceneImpl final : public PagedScene {
public:
    PagedSceneImpl(const std::string& path, const PagedSceneOptions& options);

    [[nodiscard]] const PagedSceneInfo& info() const override { return info_; }
    [[nodiscard]] Camera camera() const override;
    [[nodiscard]] std::vector<Light> lights() const override { return {file_->lights().begin(), file_->lights().end()}; }
    [[nodiscard]] Environment environment() const override { return file_->environment(); }
    [[nodiscard]] const Accel& accel() const override { return *accel_; }
    void intersect(std::span<const Ray> rays, std::span<Hit> hits, std::span<uint32_t> instances) const override {
        engine_->intersect(rays, hits, instances);
    }
    [[nodiscard]] std::vector<PageCacheReport> caches() const override;
    [[nodiscard]] PagedQueryStats query_stats() const override;
    void reset_stats() override;
    void clear_caches(bool os_cache = false) override;
    [[nodiscard]] size_t memory_bytes() const override;

    [[nodiscard]] const PackFile& file() const { return *file_; }
    [[nodiscard]] PagedEngine& engine() { return *engine_; }
    [[nodiscard]] const std::vector<PagedTexture>& textures() const { return paged_textures_; }
    [[nodiscard]] uint32_t batch_paths() const { return batch_paths_; }

private:
    void fill_info(const std::string& path);

    std::shared_ptr<const PackFile> file_;
    std::unique_ptr<PagedEngine> engine_;
    std::unique_ptr<TextureTileCache> textures_;
    std::vector<PagedTexture> paged_textures_;
    std::unique_ptr<PagedAccel> accel_;
    size_t budgets_[3] = {0, 0, 0};
    uint32_t batch_paths_ = 0;
    PagedSceneInfo info_;
};

}  // namespace rf::pack
