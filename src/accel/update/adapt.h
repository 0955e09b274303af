// The per-frame BVH update of Garanzha 2014 ch. 2 ("adapt"): refit with
// detection of migrating and exploded nodes, parallel local rebuilds of
// exploded subtrees, migration of coherently moving subtrees by recursive
// SAH insertion, over nodes kept local by the node memory manager. The
// algorithm and its choices are described at the top of adapt.cpp.
// make_adapt_updater (accel/update/bvh_updater.h) returns an AdaptBvh; the
// tests also reach its internal tree through the accessors below.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "accel/update/node_memory_manager.h"
#include "accel/update/bvh_updater.h"

namespace rf {

// One node of the dynamic tree (48 bytes). Leaves hold leaf_size triangles
// in the slot block leaf_slots(node).
struct AdaptNode {
    Box3f box;
    uint32_t child[2] = {0, 0};   // inner node: the children
    uint32_t parent = 0;          // kNone for the root (or a migration tag while detached)
    uint32_t count = 0;           // Count(N): triangles under the node
    float saved_cost = 0.0f;      // SavedSAHCost(N): eq. 1.3 when built or last inserted into (leaf: its area when built)
    uint16_t leaf_size = 0;       // triangles in a leaf; 0 for inner nodes
    uint8_t locked = 0;           // Locked(N), during one update only
    [[nodiscard]] bool is_leaf() const { return leaf_size != 0; }
};

// Wall time of the last update's stages (the measurements print them).
struct AdaptStageTimes {
    double refit_ms = 0.0;    // stage 1: refit + detection
    double rebuild_ms = 0.0;  // stage 2: regions collected, built, linked
    double link_ms = 0.0;     // of which: the regions linked into the tree (serial)
    double migrate_ms = 0.0;  // stage 3: the four passes
    double export_ms = 0.0;   // the canonical Bvh (boxes only, or re-emitted)
};

class AdaptBvh final : public BvhUpdater {
public:
    static constexpr uint32_t kNone = 0xffffffffu;

    AdaptBvh(std::span<const Triangle> triangles, const BuildOptions& build, const AdaptOptions& options);

    [[nodiscard]] const Bvh& bvh() const override { return bvh_; }
    bool update(std::span<const Triangle> triangles, UpdateStats& stats) override;

    // The internal tree (tests).
    [[nodiscard]] uint32_t root() const { return root_; }
    [[nodiscard]] const AdaptNode& node(uint32_t id) const { return nodes_[id]; }
    [[nodiscard]] std::span<const uint32_t> leaf_triangles(uint32_t id) const {
        return {slots_.data() + size_t(id) * leaf_capacity_, nodes_[id].leaf_size};
    }
    [[nodiscard]] const NodeMemoryManager& memory() const { return memory_; }
    [[nodiscard]] const AdaptStageTimes& stage_times() const { return times_; }
    // Eq. 1.3 over the node's current children, with the build's SAH costs.
    [[nodiscard]] float sah_cost(uint32_t id) const;

private:
    struct Buffers;
    struct Region;
    struct Pending;

    // Stage 1.
    void adapt(uint32_t id, Buffers& out, std::span<const Triangle> triangles);
    void detect(uint32_t id, Buffers& out, size_t migrate_start, size_t rebuild_start);
    // Stage 2.
    [[nodiscard]] bool leaf_intact(uint32_t id) const;
    void collect_region(uint32_t root, Region& region) const;
    void build_region(Region& region, std::span<const Triangle> triangles) const;
    uint32_t apply_region(Region& region, uint32_t scratch, uint32_t id, uint32_t parent, size_t& reused);
    uint64_t rebuild(std::span<const uint32_t> roots, std::span<const Triangle> triangles);
    // Stage 3.
    uint64_t migrate(std::vector<uint32_t>& nodes);
    void detach(uint32_t id, std::vector<Pending>& pending);
    void refit_upward(uint32_t id);
    uint32_t find_start(uint32_t id, const Box3f& box, const std::vector<Pending>& pending) const;
    void insert(uint32_t at, uint32_t id, const std::vector<Pending>& pending);
    void descend(uint32_t at, uint32_t id);
    void merge_at(uint32_t at, uint32_t id);
    void release(uint32_t id, uint32_t replacement);
    [[nodiscard]] uint32_t resolve(uint32_t id) const;
    void replace_child(uint32_t parent, uint32_t old_child, uint32_t new_child, std::vector<Pending>* pending);
    // Import and export.
    void import(const Bvh& bvh);
    uint32_t finish_import(uint32_t id);
    uint32_t count_leaves(uint32_t id);
    int emit(uint32_t id, uint32_t index, uint32_t pair, uint32_t slot, int depth);
    int export_bvh();
    void full_rebuild(std::span<const Triangle> triangles);
    void refresh_boxes();

    std::span<const Triangle> triangles_;  // during update() only
    BuildOptions build_;
    AdaptOptions options_;
    uint32_t triangle_count_ = 0;
    uint32_t leaf_capacity_ = 1;  // max_leaf_size
    uint32_t root_ = kNone;
    std::vector<AdaptNode> nodes_;
    std::vector<uint32_t> slots_;      // leaf triangles, leaf_capacity_ per node
    NodeMemoryManager memory_;
    std::vector<uint32_t> forward_;    // stage 3: a node freed -> the node that took its place
    std::vector<uint32_t> forwarded_;  // the entries of forward_ to clear
    Bvh bvh_;
    std::vector<uint32_t> source_;     // bvh_ node -> dynamic node
    std::vector<uint32_t> leaves_;     // leaves under each node (places subtrees in the export)
    AdaptStageTimes times_;
};

}  // namespace rf
