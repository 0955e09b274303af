#include "ooc/page_builder.h"

#include "ooc/shared_attributes.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "accel/bvh/builders/morton_code.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "ooc/attribute_records.h"
#include "ooc/shared_attributes.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf::pack {

namespace {

constexpr int kBranchBins = 16;

struct QuadBox {
    Box3f box;
    Vec3f centre;
};

Box3f quad_bounds(std::span<const Vec3f> positions, const QuadRef& q) {
    Box3f b;
    for (uint32_t v : q.v) b.extend(positions[v]);
    return b;
}

// Splits `ids` (quad indices) by the best binned SAH plane of their centres;
// returns the size of the left part (half the quads when no plane separates them).
size_t sah_split(std::span<uint32_t> ids, std::span<const QuadBox> boxes) {
    Box3f centres;
    for (uint32_t i : ids) centres.extend(boxes[i].centre);
    float best_cost = INFINITY;
    int best_axis = -1, best_bin = 0;
    for (int axis = 0; axis < 3; ++axis) {
        const float lo = centres.lo[axis], extent = centres.hi[axis] - lo;
        if (!(extent > 0.0f)) continue;
        Box3f bin_box[kBranchBins];
        size_t bin_count[kBranchBins] = {};
        const auto bin_of = [&](uint32_t i) {
            return std::min(kBranchBins - 1, int(float(kBranchBins) * (boxes[i].centre[axis] - lo) / extent));
        };
        for (uint32_t i : ids) {
            const int b = bin_of(i);
            bin_box[b].extend(boxes[i].box);
            ++bin_count[b];
        }
        Box3f right_box[kBranchBins];
        size_t right_count[kBranchBins] = {};
        Box3f acc;
        size_t n = 0;
        for (int b = kBranchBins - 1; b > 0; --b) {
            acc.extend(bin_box[b]);
            n += bin_count[b];
            right_box[b] = acc;
            right_count[b] = n;
        }
        Box3f left;
        size_t left_n = 0;
        for (int b = 1; b < kBranchBins; ++b) {
            left.extend(bin_box[b - 1]);
            left_n += bin_count[b - 1];
            if (left_n == 0 || right_count[b] == 0) continue;
            const float cost = left.surface_area() * float(left_n) + right_box[b].surface_area() * float(right_count[b]);
            if (cost < best_cost) {
                best_cost = cost;
                best_axis = axis;
                best_bin = b;
            }
        }
    }
    if (best_axis < 0) return ids.size() / 2;
    const float lo = centres.lo[best_axis], extent = centres.hi[best_axis] - lo;
    const auto middle = std::stable_partition(ids.begin(), ids.end(), [&](uint32_t i) {
        return std::min(kBranchBins - 1, int(float(kBranchBins) * (boxes[i].centre[best_axis] - lo) / extent)) < best_bin;
    });
    return size_t(middle - ids.begin());
}

// The SAH branches of §6.3 (b), in depth-first order.
void collect_branches(std::span<uint32_t> ids, std::span<const QuadBox> boxes, std::vector<std::span<uint32_t>>& out) {
    if (ids.size() <= kBranchQuads) {
        out.push_back(ids);
        return;
    }
    const size_t left = sah_split(ids, boxes);
    collect_branches(ids.first(left), boxes, out);
    collect_branches(ids.subspan(left), boxes, out);
}

void sort_by_morton(std::span<uint32_t> ids, std::span<const QuadBox> boxes) {
    Box3f centres;
    for (uint32_t i : ids) centres.extend(boxes[i].centre);
    const MortonQuantizer quantizer(centres, 10);
    std::vector<std::pair<uint32_t, uint32_t>> keyed(ids.size());
    for (size_t k = 0; k < ids.size(); ++k) keyed[k] = {quantizer.code30(boxes[ids[k]].centre), ids[k]};
    std::sort(keyed.begin(), keyed.end());
    for (size_t k = 0; k < ids.size(); ++k) ids[k] = keyed[k].second;
}

// The smallest power of two >= x (x > 0, normal).
float power_of_two_at_least(float x) {
    int e = 0;
    const float m = std::frexp(x, &e);  // x = m 2^e, m in [0.5, 1)
    return std::ldexp(1.0f, m == 0.5f ? e - 1 : e);
}

Box3f page_box(std::span<const Vec3f> positions, std::span<const QuadRef> quads, std::span<const uint32_t> page_quads) {
    Box3f box;
    for (uint32_t q : page_quads) box.extend(quad_bounds(positions, quads[q]));
    return box;
}

// The decode transform of a page on the object's lattice: scale = the
// lattice step, offset = the lattice point nearest the box's centre, so
// offset + scale * q spans the box with |q| <= kQuantMax (the step leaves
// half a step of room: see lattice_steps).
void quantisation_for(const Box3f& box, const Vec3f& step, Vec3f& offset, Vec3f& scale) {
    const Vec3f centre = (box.lo + box.hi) * 0.5f;
    for (int a = 0; a < 3; ++a) offset[a] = step[a] * std::nearbyint(centre[a] / step[a]);
    scale = step;
}

int16_t quantise(float p, float offset, float scale) {
    const float q = std::nearbyint((p - offset) / scale);
    return int16_t(std::clamp(q, -float(kQuantMax), float(kQuantMax)));
}

// The page's wide BVH over its quantised quads; returns the quads' leaf
// order (slot -> index into `quads`).
std::vector<uint32_t> build_page_bvh(const std::vector<Quad>& quads, std::vector<PageNode>& nodes) {
    std::vector<Box3f> boxes(quads.size());
    for (size_t i = 0; i < quads.size(); ++i)
        for (const auto& v : quads[i].v) boxes[i].extend(Vec3f(float(v[0]), float(v[1]), float(v[2])));
    WideTree tree = build_wide_tree(boxes);
    nodes = std::move(tree.nodes);
    return std::move(tree.items);
}

ShadingTriangle corner_record(const ShadingTriangle& source, const uint8_t corner_of[3]) {
    ShadingTriangle r = source;
    for (int k = 0; k < 3; ++k) {
        r.normals[k] = source.normals[corner_of[k]];
        r.uv[k] = source.uv[corner_of[k]];
    }
    return r;
}

}  // namespace

WideTree build_wide_tree(std::span<const Box3f> boxes) {
    WideTree tree;
    if (boxes.empty()) return tree;
    // Each box as a "triangle" with the box's bounds and its centre as centroid.
    std::vector<Triangle> shapes(boxes.size());
    for (size_t i = 0; i < boxes.size(); ++i) shapes[i] = {boxes[i].lo, boxes[i].hi, boxes[i].center()};
    BuildOptions options;
    options.builder = Builder::BinnedSah;
    options.max_leaf_size = int(kCwbvhMaxLeafTriangles);
    const Bvh bvh = build_bvh(shapes, options);
    CwbvhBvh wide = build_cwbvh(bvh, shapes);
    if (wide.triangles.size() != boxes.size()) throw Error("paged scene writer: a wide BVH lost or repeated boxes");
    tree.nodes = std::move(wide.nodes);
    tree.items.resize(wide.triangles.size());
    for (size_t i = 0; i < tree.items.size(); ++i) tree.items[i] = float_to_bits(wide.triangles[i].v0.w);
    return tree;
}

std::vector<std::vector<uint32_t>> partition_into_pages(std::span<const Vec3f> positions,
                                                        std::span<const QuadRef> quads, uint32_t quads_per_page) {
    std::vector<QuadBox> boxes(quads.size());
    for (size_t i = 0; i < quads.size(); ++i) {
        boxes[i].box = quad_bounds(positions, quads[i]);
        boxes[i].centre = boxes[i].box.center();
    }
    std::vector<uint32_t> ids(quads.size());
    for (size_t i = 0; i < ids.size(); ++i) ids[i] = uint32_t(i);
    std::vector<std::span<uint32_t>> branches;
    collect_branches(ids, boxes, branches);
    std::vector<std::vector<uint32_t>> pages;
    for (std::span<uint32_t> branch : branches) {
        sort_by_morton(branch, boxes);
        for (size_t first = 0; first < branch.size(); first += quads_per_page) {
            const size_t n = std::min<size_t>(quads_per_page, branch.size() - first);
            pages.emplace_back(branch.begin() + first, branch.begin() + first + n);
        }
    }
    return pages;
}

Vec3f lattice_steps(std::span<const Vec3f> positions, std::span<const QuadRef> quads,
                    std::span<const std::vector<uint32_t>> page_quads) {
    Vec3f half(0.0f);
    for (const std::vector<uint32_t>& page : page_quads) {
        const Box3f box = page_box(positions, quads, page);
        if (box.is_empty()) continue;
        const Vec3f h = (box.hi - box.lo) * 0.5f;
        for (int a = 0; a < 3; ++a) half[a] = std::max(half[a], h[a]);
    }
    // A flat axis still needs an invertible transform: a floor relative to the largest half extent.
    const float largest = std::max(half.x, std::max(half.y, half.z));
    const float floor_step = std::max(largest * 1e-6f, 1e-30f) / float(kQuantMax - 1);
    Vec3f step;
    for (int a = 0; a < 3; ++a) step[a] = power_of_two_at_least(std::max(half[a] / float(kQuantMax - 1), floor_step));
    return step;
}

BuiltPage build_page(std::span<const Vec3f> positions, std::span<const ShadingTriangle> shading,
                     std::span<const QuadRef> quads, std::span<const uint32_t> page_quads, const Vec3f& step) {
    BuiltPage page;
    Vec3f offset, scale;
    quantisation_for(page_box(positions, quads, page_quads), step, offset, scale);

    // Quantised quads, each remembering its source quad for the attributes.
    std::vector<Quad> qquads(page_quads.size());
    for (size_t k = 0; k < page_quads.size(); ++k)
        for (int c = 0; c < 4; ++c)
            for (int a = 0; a < 3; ++a)
                qquads[k].v[c][a] = quantise(positions[quads[page_quads[k]].v[c]][a], offset[a], scale[a]);
    std::vector<PageNode> nodes;
    const std::vector<uint32_t> order = build_page_bvh(qquads, nodes);
    if (order.size() != qquads.size()) throw Error("paged scene writer: the page BVH lost quads");

    const GeometryPageHeader header{uint32_t(qquads.size()), uint32_t(nodes.size())};
    page.geometry.resize(sizeof(header) + nodes.size() * sizeof(PageNode) + qquads.size() * sizeof(Quad));
    uint8_t* out = page.geometry.data();
    std::memcpy(out, &header, sizeof(header));
    std::memcpy(out + sizeof(header), nodes.data(), nodes.size() * sizeof(PageNode));
    auto* out_quads = reinterpret_cast<Quad*>(out + sizeof(header) + nodes.size() * sizeof(PageNode));

    page.shading.assign(2 * qquads.size(), ShadingTriangle{});
    Box3f decoded_box;
    for (size_t slot = 0; slot < order.size(); ++slot) {
        const Quad& q = qquads[order[slot]];
        const QuadRef& source = quads[page_quads[order[slot]]];
        out_quads[slot] = q;
        for (int c = 0; c < 4; ++c) {
            Vec3f decoded;
            for (int a = 0; a < 3; ++a) decoded[a] = offset[a] + scale[a] * float(q.v[c][a]);
            decoded_box.extend(decoded);
            const Vec3f error = abs(decoded - positions[source.v[c]]);
            page.max_error = std::max(page.max_error, double(std::max(error.x, std::max(error.y, error.z))));
        }
        page.shading[2 * slot] = corner_record(shading[source.first], source.corner_of[0]);
        if (source.second != QuadRef::kNoTriangle)
            page.shading[2 * slot + 1] = corner_record(shading[source.second], source.corner_of[1]);
    }
    // Padded so that a ray hitting the decoded quads in the page's own
    // coordinates never misses the box in world space by rounding.
    const Vec3f extent = decoded_box.hi - decoded_box.lo;
    const float pad = std::max(extent.x, std::max(extent.y, extent.z)) * 1e-5f + 1e-30f;
    page.info.bounds = {decoded_box.lo - Vec3f(pad), decoded_box.hi + Vec3f(pad)};
    page.info.offset = offset;
    page.info.scale = scale;
    page.info.quad_count = uint32_t(qquads.size());
    return page;
}

namespace {

// Shared runs: the largest run length whose every page fits, searched down
// from the length the whole page's density suggests (runs share fewer
// vertices than the whole page, so that guess is a little long).
uint32_t shared_run_length(std::span<const ShadingTriangle> shading, uint32_t page_bytes) {
    const auto fits = [&](size_t run) {
        for (size_t at = 0; at < shading.size(); at += run)
            if (shared_page_bytes(shading.subspan(at, std::min(run, shading.size() - at))) > page_bytes) return false;
        return true;
    };
    const size_t whole = shared_page_bytes(shading);
    size_t run = std::clamp<size_t>(shading.size() * page_bytes / std::max<size_t>(whole, 1), 1, shading.size());
    while (run > 1 && !fits(run)) run = std::min(run - 1, run * 15 / 16);
    if (!fits(run)) throw Error("paged scene writer: one triangle's shared attributes exceed the attribute page");
    return uint32_t(run);
}

}  // namespace

AttributePages cut_attribute_pages(std::span<const ShadingTriangle> shading, AttributeFormat format,
                                   uint32_t page_bytes) {
    AttributePages out;
    if (format == AttributeFormat::Shared) {
        out.triangles_per_page = shared_run_length(shading, page_bytes);
        for (size_t at = 0; at < shading.size(); at += out.triangles_per_page)
            out.pages.push_back(
                encode_shared_page(shading.subspan(at, std::min<size_t>(out.triangles_per_page, shading.size() - at))));
        return out;
    }
    const uint32_t record = attribute_record_bytes(format);
    out.triangles_per_page = page_bytes / record;
    for (size_t at = 0; at < shading.size(); at += out.triangles_per_page) {
        const size_t n = std::min<size_t>(out.triangles_per_page, shading.size() - at);
        std::vector<uint8_t>& page = out.pages.emplace_back(n * record);
        for (size_t i = 0; i < n; ++i) encode_attribute_record(shading[at + i], format, page.data() + i * record);
    }
    return out;
}

}  // namespace rf::pack
