// The streaming OBJ converter; the passes and the memory plan are described
// in obj_stream_convert.h.
#include "ooc/obj_stream_convert.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <unordered_map>
#include <vector>

#include "io/obj_parser.h"
#include "ooc/spill_file.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf::pack {

namespace {

using io::kObjAbsent;
using io::ObjCorner;

constexpr int kBinBits = 7;  // 128 bins on each axis
constexpr uint32_t kBinsPerAxis = 1u << kBinBits;
constexpr uint32_t kBins = 1u << (3 * kBinBits);
constexpr size_t kBinBytes = 3 * sizeof(uint32_t);  // count, first object, seen so far
constexpr size_t kDistributeBuffers = size_t(16) << 20;  // all the objects' write buffers together

// Pass 1's record of one triangle.
struct TriangleCorners {
    ObjCorner corner[3];
    uint32_t material;  // index into the used materials, or kObjAbsent
};
static_assert(sizeof(TriangleCorners) == 40);

// Pass 4's record: what an object needs of one triangle.
struct ObjectRecord {
    uint32_t v[3];  // OBJ position indices, for welding
    Vec3f p[3];
    unsigned char shading[sizeof(ShadingTriangle)];
};
static_assert(sizeof(ObjectRecord) == 112);

// Pass 1's sink (obj_parser.h): every array into its scratch file.
struct Spill {
    explicit Spill(const std::string& folder)
        : positions(folder, "OBJ vertex positions"), uvs(folder, "OBJ texture coordinates"),
          normals(folder, "OBJ normals"), triangles(folder, "OBJ faces") {}
    SpillFile positions, uvs, normals, triangles;
    Box3f bounds;
    bool any_uv = false, any_normal = false, missing_normal = false, default_material = false;

    void position(Vec3f p) {
        positions.append(&p, sizeof(p));
        bounds.extend(p);
    }
    void uv(Vec2f t) { uvs.append(&t, sizeof(t)); }
    void normal(Vec3f n) { normals.append(&n, sizeof(n)); }
    void triangle(const ObjCorner& a, const ObjCorner& b, const ObjCorner& c, uint32_t material) {
        const TriangleCorners t{{a, b, c}, material};
        triangles.append(&t, sizeof(t));
        for (const ObjCorner& k : t.corner) {
            any_uv |= k.vt != kObjAbsent;
            any_normal |= k.vn != kObjAbsent;
            missing_normal |= k.vn == kObjAbsent;
        }
        default_material |= material == kObjAbsent;
    }
    void flush() {
        for (SpillFile* f : {&positions, &uvs, &normals, &triangles}) f->flush();
    }
    [[nodiscard]] uint64_t triangle_count() const { return triangles.size() / sizeof(TriangleCorners); }
};

// Reads `path` in blocks, line by line, into the parser.
void parse_in_blocks(const std::string& path, size_t block_bytes, io::ObjParser<Spill>& parser,
                     const ProgressCallback& progress) {
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0) throw Error(path + ": " + std::strerror(errno));
    struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
    } closer{fd};
    std::error_code ec;
    const uint64_t size = std::filesystem::file_size(path, ec);
    std::vector<char> block(std::max<size_t>(1, block_bytes));
    std::string carry;  // a line cut by the block's end
    uint64_t done = 0;
    for (;;) {
        const ssize_t n = ::read(fd, block.data(), block.size());
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) throw Error(path + ": read failed: " + std::strerror(errno));
        if (n == 0) break;
        done += uint64_t(n);
        // Every '\n' ends a line, blank ones too (the parser counts them
        // for its messages); the piece after the last one waits in `carry`.
        std::string_view text(block.data(), size_t(n));
        for (size_t eol; (eol = text.find('\n')) != std::string_view::npos; text.remove_prefix(eol + 1)) {
            if (carry.empty()) {
                parser.line(text.substr(0, eol));
            } else {
                carry.append(text.substr(0, eol));
                parser.line(carry);
                carry.clear();
            }
        }
        carry.append(text);
        if (progress && size > 0) progress(double(done) / double(size));
    }
    if (!carry.empty()) parser.line(carry);
    parser.finish();
}

// The scene's materials, and each triangle's material id in it.
struct MaterialMap {
    Scene scene;
    std::vector<uint32_t> of_used;  // parser's index -> scene material
    uint32_t absent = 0;            // for faces before any usemtl
    [[nodiscard]] uint32_t of(uint32_t used) const { return used == kObjAbsent ? absent : of_used[used]; }
};

MaterialMap read_materials(const std::string& path, const io::ObjParser<Spill>& parser, const Spill& spill,
                           bool load_textures) {
    MaterialMap m;
    m.of_used = io::add_obj_materials(m.scene, path, parser.used_materials(), parser.libraries(), load_textures);
    if (spill.default_material || m.scene.materials.empty()) {
        m.absent = uint32_t(m.scene.materials.size());
        m.scene.materials.push_back(io::default_obj_material("default"));
    }
    return m;
}

// The vertex arrays through their caches.
struct Vertices {
    Vertices(Spill& spill, const io::ObjParser<Spill>& parser, size_t cache_bytes)
        : positions(spill.positions, parser.positions(), cache_bytes / 2),
          uvs(spill.uvs, parser.uvs(), cache_bytes / 4),
          normals(spill.normals, parser.normals(), cache_bytes / 4) {}
    CachedArray<Vec3f> positions;
    CachedArray<Vec2f> uvs;
    CachedArray<Vec3f> normals;
};

// Runs `visit(TriangleCorners, index)` over pass 1's triangles with progress.
template <class Visit>
void for_each_triangle(const Spill& spill, const ProgressCallback& progress, Visit&& visit) {
    SpillReader reader(spill.triangles, 0, spill.triangles.size());
    const uint64_t total = spill.triangle_count();
    TriangleCorners t;
    for (uint64_t i = 0; reader.next(t); ++i) {
        visit(t, i);
        if (progress && (i & 0xFFFFF) == 0) progress(double(i) / double(total));
    }
}

// Pass 2: area-weighted normals per position index, for corners without one.
std::unique_ptr<SpillFile> accumulate_normals(const Spill& spill, uint64_t position_count, Vertices& v,
                                              const std::string& folder, size_t cache_bytes,
                                              const ProgressCallback& progress) {
    auto file = std::make_unique<SpillFile>(folder, "computed normals");
    file->resize(position_count * sizeof(Vec3f));
    CachedArray<Vec3f> sum(*file, position_count, cache_bytes);
    for_each_triangle(spill, progress, [&](const TriangleCorners& t, uint64_t) {
        const Vec3f p0 = v.positions.get(t.corner[0].v), p1 = v.positions.get(t.corner[1].v),
                    p2 = v.positions.get(t.corner[2].v);
        const Vec3f face = cross(p1 - p0, p2 - p0);  // length: twice the area
        if (!is_finite(face)) return;
        for (const ObjCorner& c : t.corner)
            if (c.vn == kObjAbsent) sum.at(c.v) += face;
    });
    sum.flush();
    return file;
}

// Bins of a 128^3 grid over the vertices' bounds; objects are runs of bins
// in Morton order.
struct Bins {
    explicit Bins(const Box3f& b) : box(b), count(kBins, 0), first_object(kBins, 0), seen(kBins, 0) {
        const Vec3f e = box.extent();
        for (int a = 0; a < 3; ++a) scale[a] = e[a] > 0.0f ? float(kBinsPerAxis) / e[a] : 0.0f;
    }
    [[nodiscard]] uint32_t of(const Vec3f& p0, const Vec3f& p1, const Vec3f& p2) const {
        const Vec3f c = (p0 + p1 + p2) * (1.0f / 3.0f);
        uint32_t cell[3];
        for (int a = 0; a < 3; ++a) {
            const float x = (c[a] - box.lo[a]) * scale[a];
            cell[a] = x > 0.0f ? std::min(kBinsPerAxis - 1, uint32_t(x)) : 0u;
        }
        uint32_t code = 0;
        for (int i = 0; i < kBinBits; ++i)
            for (int a = 0; a < 3; ++a) code |= ((cell[a] >> i) & 1u) << (3 * i + (2 - a));
        return code;
    }
    Box3f box;
    float scale[3] = {0, 0, 0};
    std::vector<uint32_t> count, first_object, seen;
};

// Objects from the bin counts: consecutive bins until the next would pass
// `max_triangles`; a bin above it alone is cut into pieces in file order.
struct ObjectPlan {
    std::vector<uint64_t> begin;  // first record of each object; one more at the end
    [[nodiscard]] size_t objects() const { return begin.size() - 1; }
    [[nodiscard]] uint64_t size(size_t o) const { return begin[o + 1] - begin[o]; }
};

ObjectPlan plan_objects(Bins& bins, uint64_t max_triangles) {
    ObjectPlan plan;
    plan.begin.push_back(0);
    uint64_t total = 0, open = 0;  // records so far; in the object being filled
    for (uint32_t bin = 0; bin < kBins; ++bin) {
        const uint64_t n = bins.count[bin];
        if (n == 0) continue;
        if (open > 0 && open + n > max_triangles) {
            plan.begin.push_back(total);
            open = 0;
        }
        bins.first_object[bin] = uint32_t(plan.begin.size() - 1);
        for (uint64_t left = n; left > max_triangles; left -= max_triangles) {
            total += max_triangles;
            plan.begin.push_back(total);
        }
        const uint64_t rest = n - (n - 1) / max_triangles * max_triangles;
        total += rest;
        open += rest;
    }
    if (open > 0) plan.begin.push_back(total);
    return plan;
}

// Pass 4's per-object write buffers.
class ObjectWriter {
public:
    ObjectWriter(SpillFile& file, const ObjectPlan& plan)
        : file_(file), plan_(plan), cursor_(plan.begin.begin(), plan.begin.end() - 1), buffers_(plan.objects()) {
        capacity_ = std::clamp<size_t>(kDistributeBuffers / std::max<size_t>(1, plan.objects()) / sizeof(ObjectRecord),
                                       8, 256);
        file_.resize(plan.begin.back() * sizeof(ObjectRecord));
    }
    void add(size_t object, const ObjectRecord& r) {
        std::vector<ObjectRecord>& b = buffers_[object];
        b.push_back(r);
        if (b.size() >= capacity_) flush(object);
    }
    void flush_all() {
        for (size_t o = 0; o < buffers_.size(); ++o) flush(o);
    }

private:
    void flush(size_t o) {
        std::vector<ObjectRecord>& b = buffers_[o];
        if (b.empty()) return;
        if (cursor_[o] + b.size() > plan_.begin[o + 1]) throw Error("convert: object plan overflow (internal)");
        file_.write(cursor_[o] * sizeof(ObjectRecord), b.data(), b.size() * sizeof(ObjectRecord));
        cursor_[o] += b.size();
        b.clear();  // kept: at most capacity_ records, inside the planned kDistributeBuffers
    }
    SpillFile& file_;
    const ObjectPlan& plan_;
    std::vector<uint64_t> cursor_;
    std::vector<std::vector<ObjectRecord>> buffers_;
    size_t capacity_ = 8;
};

// The shading record of one triangle from its corners.
ObjectRecord resolve(const TriangleCorners& t, Vertices& v, CachedArray<Vec3f>* computed, bool any_uv,
                     bool any_normal_source, uint32_t material) {
    ObjectRecord r;
    Vec3f normals[3];
    Vec2f uvs[3];
    for (int k = 0; k < 3; ++k) {
        const ObjCorner& c = t.corner[k];
        r.v[k] = c.v;
        r.p[k] = v.positions.get(c.v);
        uvs[k] = c.vt != kObjAbsent ? v.uvs.get(c.vt) : Vec2f{0, 0};
        if (c.vn != kObjAbsent) normals[k] = v.normals.get(c.vn);
        else if (computed) normals[k] = computed->get(c.v);
        else normals[k] = Vec3f{0, 0, 0};
        // A zero sum of face normals is +z, as Mesh::compute_vertex_normals has it.
        if (c.vn == kObjAbsent && computed && !(length(normals[k]) > 0.0f)) normals[k] = Vec3f{0, 0, 1};
    }
    const uint32_t idx[3] = {0, 1, 2};
    const ShadingTriangle s = make_shading_triangle(
        any_normal_source ? std::span<const Vec3f>(normals, 3) : std::span<const Vec3f>(),
        any_uv ? std::span<const Vec2f>(uvs, 3) : std::span<const Vec2f>(), Affine3f::identity(),
        Triangle{r.p[0], r.p[1], r.p[2]}, idx, material);
    std::memcpy(r.shading, &s, sizeof(s));
    return r;
}

// Pass 5 for one object: weld, then hand to the writer.
void write_object(const SpillFile& records, uint64_t begin, uint64_t count, PackWriter& writer) {
    std::vector<ObjectRecord> rs(count);
    records.read(begin * sizeof(ObjectRecord), rs.data(), count * sizeof(ObjectRecord));
    std::unordered_map<uint32_t, uint32_t> local;
    local.reserve(count);
    std::vector<Vec3f> positions;
    std::vector<uint32_t> indices(3 * count);
    std::vector<ShadingTriangle> shading(count);
    for (uint64_t t = 0; t < count; ++t) {
        for (int k = 0; k < 3; ++k) {
            const auto [it, inserted] = local.try_emplace(rs[t].v[k], uint32_t(positions.size()));
            if (inserted) positions.push_back(rs[t].p[k]);
            indices[3 * t + uint64_t(k)] = it->second;
        }
        std::memcpy(&shading[t], rs[t].shading, sizeof(ShadingTriangle));
    }
    rs = {};
    writer.add_object({positions, indices, shading});
}

std::string scratch_folder(const std::string& out_path, const std::string& temp_dir) {
    if (!temp_dir.empty()) return temp_dir;
    const std::filesystem::path parent = std::filesystem::path(out_path).parent_path();
    return parent.empty() ? "." : parent.string();
}

// Progress of pass `k` of the weights below.
ProgressCallback stage(const ProgressCallback& progress, double from, double to) {
    if (!progress) return {};
    return [progress, from, to](double f) { progress(from + (to - from) * std::clamp(f, 0.0, 1.0)); };
}

}  // namespace

StreamBudget plan_stream_budget(size_t memory_budget) {
    if (memory_budget < kMinStreamBudget)
        throw Error("convert: a memory budget of " + std::to_string(memory_budget >> 20) +
                    " MiB is too small for streaming (at least " + std::to_string(kMinStreamBudget >> 20) + " MiB)");
    StreamBudget b;
    b.fixed_bytes = size_t(kBins) * kBinBytes + kStreamReadBlock + 5 * (size_t(1) << 20) + kDistributeBuffers;
    const size_t rest = memory_budget - b.fixed_bytes;
    b.cache_bytes = std::min(rest / 4, size_t(512) << 20);
    b.max_object_triangles = std::max<uint64_t>(1024, (rest - b.cache_bytes) / kObjectBytesPerTriangle);
    return b;
}

StreamConvertResult convert_obj_streaming(const std::string& obj_path, const std::string& out_path,
                                          const PackWriterOptions& options, const StreamConvertOptions& stream,
                                          const ProgressCallback& progress) {
    StreamConvertResult result;
    result.budget = plan_stream_budget(stream.memory_budget);
    if (stream.max_object_triangles > 0)
        result.budget.max_object_triangles = std::min(result.budget.max_object_triangles, stream.max_object_triangles);
    const std::string folder = scratch_folder(out_path, stream.temp_dir);
    Spill spill(folder);
    io::ObjParser<Spill> parser(obj_path, spill);
    parse_in_blocks(obj_path, stream.read_block_bytes, parser, stage(progress, 0.0, 0.35));
    spill.flush();
    if (spill.triangle_count() == 0) throw file_error(obj_path, 0, "no faces");
    checked_index_count(obj_path + ": OBJ triangle count", spill.triangle_count());
    const MaterialMap materials = read_materials(obj_path, parser, spill, stream.load_textures);

    const size_t cache = result.budget.cache_bytes;
    Vertices vertices(spill, parser, cache * 3 / 4);
    std::unique_ptr<SpillFile> computed_file;
    std::unique_ptr<CachedArray<Vec3f>> computed;
    if (spill.missing_normal && stream.compute_missing_normals) {
        computed_file = accumulate_normals(spill, parser.positions(), vertices, folder, cache / 4,
                                           stage(progress, 0.35, 0.4));
        computed = std::make_unique<CachedArray<Vec3f>>(*computed_file, parser.positions(), cache / 4);
    }

    // Pass 3: bins, and the referenced vertices' bounds for the camera.
    Bins bins(spill.bounds);
    Box3f used_bounds;
    for_each_triangle(spill, stage(progress, 0.4, 0.45), [&](const TriangleCorners& t, uint64_t) {
        const Vec3f p0 = vertices.positions.get(t.corner[0].v), p1 = vertices.positions.get(t.corner[1].v),
                    p2 = vertices.positions.get(t.corner[2].v);
        ++bins.count[bins.of(p0, p1, p2)];
        used_bounds.extend(p0);
        used_bounds.extend(p1);
        used_bounds.extend(p2);
    });
    const ObjectPlan plan = plan_objects(bins, result.budget.max_object_triangles);

    // Pass 4: distribute.
    SpillFile records(folder, "objects");
    {
        ObjectWriter objects(records, plan);
        const bool normal_source = spill.any_normal || computed != nullptr;
        for_each_triangle(spill, stage(progress, 0.45, 0.6), [&](const TriangleCorners& t, uint64_t) {
            const ObjectRecord r = resolve(t, vertices, computed.get(), spill.any_uv, normal_source,
                                           materials.of(t.material));
            const uint32_t bin = bins.of(r.p[0], r.p[1], r.p[2]);
            const uint32_t piece = bins.seen[bin]++ / uint32_t(result.budget.max_object_triangles);
            objects.add(bins.first_object[bin] + piece, r);
        });
        objects.flush_all();
    }
    uint64_t scratch = 0;
    for (const SpillFile* f : {&spill.positions, &spill.uvs, &spill.normals, &spill.triangles, &records})
        scratch += f->size();
    if (computed_file) scratch += computed_file->size();
    result.scratch_bytes = scratch;

    // Pass 5: the writer.
    PackWriter writer(out_path, options);
    write_scene_look(materials.scene, Scene::framing(used_bounds), writer, result.convert.notes);
    const ProgressCallback write_progress = stage(progress, 0.6, 0.97);
    for (size_t o = 0; o < plan.objects(); ++o) {
        write_object(records, plan.begin[o], plan.size(o), writer);
        if (write_progress) write_progress(double(plan.begin[o + 1]) / double(plan.begin.back()));
    }
    result.objects = plan.objects();
    result.convert.summary = writer.finish(stage(progress, 0.97, 1.0));
    if (parser.skipped_faces() > 0)
        result.convert.notes.push_back("skipped " + std::to_string(parser.skipped_faces()) +
                                       " faces with fewer than 3 vertices");
    return result;
}

}  // namespace rf::pack
