// BART AFF ("Animated File Format") loader.
//
// AFF is the scene format of BART, "A Benchmark for Animated Ray Tracing"
// (J. Lext, U. Assarsson, T. Möller, IEEE CG&A 2001); it extends Eric Haines's
// NFF 3.9 with meshes, textured and animated triangles, includes, static and
// keyframe-animated transform blocks. rayforge is static, so the loader
// evaluates the animation at one time: the start of the animation (`a
// start end frames`), or 0 when the file has no `a` line; load_aff_at_time
// picks another time.
//
// Supported (see docs/scene-format.md for the mapping onto rf::Scene):
//   comments (# and %, to the end of the line), v (from/at/up/angle/hither/
//   resolution), b, l (point lights, world space), am (ignored: no ambient
//   term), a, d (detail level), f and fm materials, p and pp polygons (fan-
//   triangulated), tt / ttp textured triangles, tpa animated triangles
//   (linear in time, clamped), m meshes, i includes (relative to the including
//   file; cycles and nesting deeper than 64 are errors; each occurrence is
//   expanded again), xs static transforms T*R*S, x animated transforms
//   evaluated from their k keyframes (Kochanek-Bartels splines for transl and
//   scale, squad of quaternions for rot, step visibility, as in BART's
//   reference code), k camera (animates the viewpoint), s spheres and c cones
//   (tessellated, counted in a note).
// Every problem in the input is an rf::Error "file:line: reason". Guards:
// counts are checked against what is left of the file before allocating,
// arrays against the memory budget, and the geometry of all expansions
// together too; at most 100,000 include expansions and 1 GiB of parsed text
// per load (a file that includes the next one twice, 30 deep, would be 2^30).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "io/file_reader.h"
#include "io/number_parsing.h"
#include "io/path_utils.h"
#include "io/texture_batch.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"

namespace rf {

namespace {

namespace fs = std::filesystem;

constexpr int kMaxIncludeDepth = 64;
constexpr size_t kMaxExpansions = 100'000;              // include expansions in one load
constexpr size_t kMaxParsedBytes = size_t(1) << 30;     // text parsed, includes counted each time
constexpr int kConeSegments = 16;                        // 32 triangles per cone
constexpr int kSphereStacks = 12, kSphereSlices = 24;    // 528 triangles per sphere
constexpr uint32_t kAbsent = 0xFFFFFFFFu;
constexpr double kPi = 3.14159265358979323846;

void warn(const std::string& message) { std::cerr << "rayforge: warning: " << message << '\n'; }
void note(const std::string& message) { std::cerr << "rayforge: note: " << message << '\n'; }

// ---------------------------------------------------------------------------
// Tokens: whitespace-separated words; '{' and '}' are words of their own;
// '#' and '%' start a comment that runs to the end of the line.

struct Token {
    std::string_view text;
    long line = 0;
};

class Tokenizer {
public:
    explicit Tokenizer(std::string_view text) : text_(text) {}

    bool next(Token& out) {
        if (!peek(out)) return false;
        pos_ = peek_end_;
        line_ = peek_line_after_;
        has_peek_ = false;
        return true;
    }
    bool peek(Token& out) {
        if (!has_peek_) compute_peek();
        if (peek_token_.text.empty()) return false;
        out = peek_token_;
        return true;
    }
    [[nodiscard]] long line() const { return line_; }
    [[nodiscard]] size_t remaining() const { return text_.size() - pos_; }

private:
    static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }
    void compute_peek() {
        size_t p = pos_;
        long line = line_;
        for (;;) {
            while (p < text_.size() && is_space(text_[p])) {
                if (text_[p] == '\n') ++line;
                ++p;
            }
            if (p < text_.size() && (text_[p] == '#' || text_[p] == '%')) {
                while (p < text_.size() && text_[p] != '\n') ++p;
                continue;
            }
            break;
        }
        size_t start = p;
        if (p < text_.size() && (text_[p] == '{' || text_[p] == '}')) {
            ++p;
        } else {
            while (p < text_.size() && !is_space(text_[p]) && text_[p] != '{' && text_[p] != '}' && text_[p] != '#' &&
                   text_[p] != '%')
                ++p;
        }
        peek_token_ = Token{text_.substr(start, p - start), line};
        peek_end_ = p;
        peek_line_after_ = line;
        has_peek_ = true;
    }

    std::string_view text_;
    size_t pos_ = 0;
    long line_ = 1;
    bool has_peek_ = false;
    Token peek_token_;
    size_t peek_end_ = 0;
    long peek_line_after_ = 1;
};

// ---------------------------------------------------------------------------
// Keyframe animation (BART: T*R*S from Kochanek-Bartels splines).

struct Quat {
    double w = 1, x = 0, y = 0, z = 0;
};
Quat operator*(const Quat& a, const Quat& b) {
    return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
            a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
Quat scaled(const Quat& q, double s) { return {q.w * s, q.x * s, q.y * s, q.z * s}; }
Quat added(const Quat& a, const Quat& b) { return {a.w + b.w, a.x + b.x, a.y + b.y, a.z + b.z}; }
double qdot(const Quat& a, const Quat& b) { return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z; }
Quat conjugate(const Quat& q) { return {q.w, -q.x, -q.y, -q.z}; }
Quat from_axis_angle(double ax, double ay, double az, double radians) {
    const double len = std::sqrt(ax * ax + ay * ay + az * az);
    if (!(len > 0.0)) return {};
    const double s = std::sin(radians / 2) / len;
    return {std::cos(radians / 2), ax * s, ay * s, az * s};
}
Quat qlog(const Quat& q) {  // unit q -> pure quaternion
    const double angle = std::acos(std::clamp(q.w, -1.0, 1.0));
    const double s = std::sin(angle);
    if (std::fabs(s) > 1e-9) {
        const double k = angle / s;
        return {0, q.x * k, q.y * k, q.z * k};
    }
    return {0, q.x, q.y, q.z};
}
Quat qexp(const Quat& q) {  // pure q -> unit quaternion
    const double angle = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    const double s = std::sin(angle);
    if (std::fabs(s) > 1e-9) {
        const double k = s / angle;
        return {std::cos(angle), q.x * k, q.y * k, q.z * k};
    }
    return {std::cos(angle), q.x, q.y, q.z};
}
Quat slerp(double t, const Quat& p, const Quat& q) {
    const double angle = std::acos(std::clamp(qdot(p, q), -1.0, 1.0));
    const double s = std::sin(angle);
    if (std::fabs(s) < 1e-9) return p;
    return added(scaled(p, std::sin((1 - t) * angle) / s), scaled(q, std::sin(t * angle) / s));
}

struct Key {
    double t = 0;
    double v[4] = {0, 0, 0, 0};  // xyz (transl, scale) or axis xyz + angle in radians (rot)
    double tension = 0, continuity = 0, bias = 0;
};

// Tangent multipliers of the BART/Eberly KB spline for the segment key[i1] -> key[i2].
struct KbWeights {
    double out0, out1, in0, in1;
};
KbWeights kb_weights(const std::vector<Key>& k, size_t i0) {
    const Key &k0 = k[i0], &k1 = k[i0 + 1], &k2 = k[i0 + 2], &k3 = k[i0 + 3];
    auto ratio = [](double num, double den) { return den > 0.0 ? 2.0 * num / den : 0.0; };
    const double adj0 = ratio(k2.t - k1.t, k2.t - k0.t);
    const double adj1 = ratio(k2.t - k1.t, k3.t - k1.t);
    KbWeights w;
    w.out0 = 0.5 * adj0 * (1 - k1.tension) * (1 + k1.continuity) * (1 + k1.bias);
    w.out1 = 0.5 * adj0 * (1 - k1.tension) * (1 - k1.continuity) * (1 - k1.bias);
    w.in0 = 0.5 * adj1 * (1 - k2.tension) * (1 - k2.continuity) * (1 + k2.bias);
    w.in1 = 0.5 * adj1 * (1 - k2.tension) * (1 + k2.continuity) * (1 - k2.bias);
    return w;
}

// The segment (first key index i0; the curve runs from key i0+1 to i0+2) and the
// parameter in [0,1] for time t, clamped to the inner keys.
std::pair<size_t, double> kb_segment(const std::vector<Key>& k, double t) {
    const size_t polys = k.size() - 3;
    if (!(k[1].t < t)) return {0, 0.0};
    if (!(t < k[polys + 1].t)) return {polys - 1, 1.0};
    for (size_t i = 0; i < polys; ++i) {
        if (t < k[i + 2].t) {
            const double range = k[i + 2].t - k[i + 1].t;
            return {i, range > 0 ? std::clamp((t - k[i + 1].t) / range, 0.0, 1.0) : 0.0};
        }
    }
    return {polys - 1, 1.0};
}

Vec3f kb_position(const std::vector<Key>& k, double t) {
    auto [i, u] = kb_segment(k, t);
    const KbWeights w = kb_weights(k, i);
    double out[3];
    for (int c = 0; c < 3; ++c) {
        const double p0 = k[i].v[c], p1 = k[i + 1].v[c], p2 = k[i + 2].v[c], p3 = k[i + 3].v[c];
        const double dp = p2 - p1;
        const double tout = w.out1 * dp + w.out0 * (p1 - p0);
        const double tin = w.in1 * (p3 - p2) + w.in0 * dp;
        const double c2 = 3 * dp - 2 * tout - tin;
        const double c3 = -2 * dp + tout + tin;
        out[c] = p1 + u * (tout + u * (c2 + u * c3));
    }
    return {float(out[0]), float(out[1]), float(out[2])};
}

Quat kb_rotation(const std::vector<Key>& k, double t) {
    std::vector<Quat> q(k.size());
    for (size_t i = 0; i < k.size(); ++i) q[i] = from_axis_angle(k[i].v[0], k[i].v[1], k[i].v[2], k[i].v[3]);
    // Consecutive inner keys on the same hemisphere (as the reference code does).
    for (size_t i = 1; i + 2 < k.size(); ++i)
        if (qdot(q[i], q[i + 1]) < 0.0) q[i + 1] = scaled(q[i + 1], -1.0);
    auto [i, s] = kb_segment(k, t);
    const KbWeights w = kb_weights(k, i);
    const Quat &q0 = q[i], &q1 = q[i + 1], &q2 = q[i + 2], &q3 = q[i + 3];
    const Quat logdq = qlog(conjugate(q1) * q2);
    const Quat tout = added(scaled(logdq, w.out1), scaled(qlog(conjugate(q0) * q1), w.out0));
    const Quat tin = added(scaled(logdq, w.in0), scaled(qlog(conjugate(q2) * q3), w.in1));
    const Quat a = q1 * qexp(scaled(added(tout, scaled(logdq, -1.0)), 0.5));
    const Quat b = q2 * qexp(scaled(added(logdq, scaled(tin, -1.0)), 0.5));
    return slerp(2 * s * (1 - s), slerp(s, q1, q2), slerp(s, a, b));
}

Affine3f quat_matrix(Quat q) {
    const double n = std::sqrt(qdot(q, q));
    if (n > 0) q = scaled(q, 1.0 / n);
    Affine3f r;
    const double w = q.w, x = q.x, y = q.y, z = q.z;
    r.m[0][0] = float(1 - 2 * (y * y + z * z)); r.m[0][1] = float(2 * (x * y - w * z)); r.m[0][2] = float(2 * (x * z + w * y));
    r.m[1][0] = float(2 * (x * y + w * z)); r.m[1][1] = float(1 - 2 * (x * x + z * z)); r.m[1][2] = float(2 * (y * z - w * x));
    r.m[2][0] = float(2 * (x * z - w * y)); r.m[2][1] = float(2 * (y * z + w * x)); r.m[2][2] = float(1 - 2 * (x * x + y * y));
    return r;
}

struct Animation {
    std::vector<Key> transl, rot, scale;
    std::vector<std::pair<double, bool>> visibility;
    std::string file;
    long line = 0;

    [[nodiscard]] Affine3f matrix(double t) const {
        Affine3f m = rot.empty() ? Affine3f::identity() : quat_matrix(kb_rotation(rot, t));
        if (!scale.empty()) m = m * Affine3f::scale(kb_position(scale, t));
        if (!transl.empty()) {
            const Vec3f p = kb_position(transl, t);
            m.m[0][3] = p.x;
            m.m[1][3] = p.y;
            m.m[2][3] = p.z;
        }
        return m;
    }
    [[nodiscard]] bool visible(double t) const {
        bool visible = true;  // visible until the first key
        for (const auto& [time, flag] : visibility) {
            if (t < time) break;
            visible = flag;
        }
        return visible;
    }
};

// ---------------------------------------------------------------------------
// The parser.

struct Node {  // a transform block; node 0 is the world
    int parent = -1;
    bool animated = false;
    Affine3f local = Affine3f::identity();
    std::string name;  // animated: the k name
    std::string file;
    long line = 0;
};

struct MaterialDef {
    Vec3f diffuse{0.8f, 0.8f, 0.8f}, specular{0, 0, 0};
    float shine = 0, transmittance = 0, ior = 1.5f;
    bool operator<(const MaterialDef& o) const {
        auto key = [](const MaterialDef& m) {
            return std::make_tuple(m.diffuse.x, m.diffuse.y, m.diffuse.z, m.specular.x, m.specular.y, m.specular.z,
                                   m.shine, m.transmittance, m.ior);
        };
        return key(*this) < key(o);
    }
};

struct PendingMesh {
    Mesh mesh;
    int node = 0;
};

struct TriKey {  // tpa: one key of an animated triangle
    double t = 0;
    Vec3f p[3], n[3];
};

struct AnimatedTriangle {
    std::vector<TriKey> keys;
    uint32_t material = 0;
    size_t mesh = 0;  // pending_ index of the loose mesh it goes into
};

struct LightDef {
    Vec3f position, color;
};

struct ViewDef {
    Vec3f from{0, 0, 5}, at{0, 0, 0}, up{0, 1, 0};
    float angle = 45.0f;
    long line = 0;
};

class AffParser {
public:
    AffParser(std::string root, const LoadOptions& options)
        : root_(std::move(root)), options_(options), polygon_what_(root_ + ": AFF polygon array"),
          geometry_what_(root_ + ": AFF geometry with all includes expanded") {}

    Scene load(std::optional<double> time) {
        nodes_.push_back(Node{});
        std::error_code ec;
        std::string canonical = fs::weakly_canonical(root_, ec).string();
        if (ec) canonical = root_;
        parse_file(root_, canonical, 0);
        const double t = time ? *time : (anim_start_ ? *anim_start_ : 0.0);
        return assemble(t);
    }

private:
    // --- per-file state ------------------------------------------------------
    struct FileState {
        std::string path;
        Tokenizer tokens;
        size_t block_base = 0;  // node stack size on entry
    };

    [[nodiscard]] Error error(long line, const std::string& reason) const {
        return file_error(file_->path, line, reason);
    }

    Token expect_token(const char* what) {
        Token t;
        if (!file_->tokens.next(t)) throw error(file_->tokens.line(), std::string("unexpected end of file, expected ") + what);
        return t;
    }
    float read_float(const char* what) {
        Token t = expect_token(what);
        float value = 0.0f;
        const char* end = t.text.data() + t.text.size();
        const char* after = io::parse_float(t.text.data(), end, value);
        if (after != end) throw error(t.line, "bad number '" + std::string(t.text.substr(0, 24)) + "' in " + what);
        if (!std::isfinite(value)) throw error(t.line, std::string("non-finite number in ") + what);
        return value;
    }
    Vec3f read_vec3(const char* what) {
        float x = read_float(what);
        float y = read_float(what);
        float z = read_float(what);
        return {x, y, z};
    }
    int64_t read_int(const char* what, long* line = nullptr) {
        Token t = expect_token(what);
        int64_t value = 0;
        const char* end = t.text.data() + t.text.size();
        const char* after = io::parse_int(t.text.data(), end, value);
        if (after != end) throw error(t.line, "bad integer '" + std::string(t.text.substr(0, 24)) + "' in " + what);
        if (line) *line = t.line;
        return value;
    }
    // A count of items of `numbers_each` numbers each, checked against what is left of the file.
    size_t read_count(const char* what, size_t numbers_each) {
        long line = 0;
        int64_t n = read_int(what, &line);
        if (n < 0) throw error(line, std::string("negative ") + what);
        if (uint64_t(n) > 0xFFFFFFFFull) throw error(line, std::string(what) + " " + std::to_string(n) + " exceed 32-bit indices");
        // Each number takes at least one character and one separator.
        const uint64_t min_bytes = uint64_t(n) * numbers_each * 2;
        if (min_bytes > file_->tokens.remaining() + 1)
            throw error(line, std::string(what) + " " + std::to_string(n) + " exceeds what is left of the file (" +
                                  std::to_string(file_->tokens.remaining()) + " bytes)");
        return size_t(n);
    }
    uint32_t read_index(const char* what, size_t count) {
        long line = 0;
        int64_t i = read_int(what, &line);
        if (i < 0 || uint64_t(i) >= count)
            throw error(line, std::string(what) + " index " + std::to_string(i) + " out of range (" +
                                  std::to_string(count) + " defined)");
        return uint32_t(i);
    }
    std::string read_word(const char* what) {
        Token t = expect_token(what);
        if (t.text == "{" || t.text == "}") throw error(t.line, std::string("expected ") + what + ", found '" + std::string(t.text) + "'");
        return std::string(t.text);
    }
    void expect_open_brace(const char* what) {
        Token t = expect_token("'{'");
        if (t.text != "{") throw error(t.line, std::string("expected '{' after ") + what + ", found '" + std::string(t.text.substr(0, 24)) + "'");
    }
    bool next_is_number() {
        Token t;
        if (!file_->tokens.peek(t)) return false;
        float v;
        const char* end = t.text.data() + t.text.size();
        return io::parse_float(t.text.data(), end, v) == end;
    }

    // --- files and includes ----------------------------------------------------
    std::string_view file_text(const std::string& path) {
        auto it = texts_.find(path);
        if (it == texts_.end()) it = texts_.emplace(path, io::read_file(path)).first;
        return it->second;
    }

    void parse_file(const std::string& path, const std::string& canonical, int depth) {
        std::string_view text = file_text(path);
        parsed_bytes_ += text.size();
        if (++expansions_ > kMaxExpansions || parsed_bytes_ > kMaxParsedBytes)
            throw file_error(path, 0, "too many include expansions (" + std::to_string(expansions_) + " files, " +
                                          std::to_string(parsed_bytes_) + " bytes; exponential include nesting?)");
        include_stack_.push_back(canonical);
        FileState state{path, Tokenizer(text), node_stack_.size()};
        FileState* outer = file_;
        file_ = &state;
        parse_statements(depth);
        if (node_stack_.size() > state.block_base)
            throw file_error(path, nodes_[size_t(node_stack_.back())].line, "transform block '{' is not closed");
        file_ = outer;
        include_stack_.pop_back();
    }

    void parse_statements(int depth) {
        Token t;
        while (file_->tokens.next(t)) {
            const std::string_view k = t.text;
            const long line = t.line;
            if (k == "v") parse_view(line);
            else if (k == "b") background_ = read_vec3("background color");
            else if (k == "l") parse_light();
            else if (k == "am") (void)read_vec3("ambient light");  // no ambient term in rayforge
            else if (k == "a") parse_anim_params(line);
            else if (k == "d") detail_level_ = read_int("detail level");
            else if (k == "f") parse_nff_material();
            else if (k == "fm") parse_fm_material();
            else if (k == "p") parse_polygon(false);
            else if (k == "pp") parse_polygon(true);
            else if (k == "tt") parse_textured_triangle(false);
            else if (k == "ttp") parse_textured_triangle(true);
            else if (k == "tpa") parse_animated_triangle(line);
            else if (k == "m") parse_mesh(line);
            else if (k == "s") parse_sphere(line);
            else if (k == "c") parse_cone(line);
            else if (k == "i") parse_include(depth, line);
            else if (k == "xs") parse_static_transform(line);
            else if (k == "x") parse_animated_transform(line);
            else if (k == "k") parse_keyframes(line);
            else if (k == "}") {
                if (node_stack_.size() <= file_->block_base) throw error(line, "'}' without an open transform block");
                node_stack_.pop_back();
            } else {
                throw error(line, "unknown keyword '" + std::string(k.substr(0, 32)) + "'");
            }
        }
    }

    void parse_include(int depth, long line) {
        const int64_t detail = read_int("include detail level");
        const std::string name = read_word("include file name");
        if (detail > detail_level_) return;  // above the scene's detail level
        if (depth + 1 > kMaxIncludeDepth)
            throw error(line, "includes nested deeper than " + std::to_string(kMaxIncludeDepth) + " levels");
        // Resolved once per (including file, name): robots include the same parts hundreds of times.
        const std::string cache_key = file_->path + '\n' + name;
        auto cached = include_lookup_.find(cache_key);
        if (cached == include_lookup_.end()) {
            const std::string resolved = io::resolve_relative(file_->path, name);
            std::optional<std::string> found = io::find_file_case_insensitive(resolved);
            std::error_code ec;
            if (!found || !fs::is_regular_file(*found, ec)) throw error(line, "included file '" + name + "' not found");
            std::string canonical = fs::weakly_canonical(*found, ec).string();
            if (ec) canonical = *found;
            cached = include_lookup_.emplace(cache_key, std::make_pair(*found, canonical)).first;
        }
        const auto& [found, canonical] = cached->second;
        if (std::find(include_stack_.begin(), include_stack_.end(), canonical) != include_stack_.end())
            throw error(line, "include cycle: '" + name + "' includes itself");
        // Errors inside the included file name that file and line.
        parse_file(found, canonical, depth + 1);
    }

    // --- camera, lights, settings --------------------------------------------
    void parse_view(long line) {
        ViewDef view;
        view.line = line;
        Token t;
        std::set<std::string> seen;
        while (file_->tokens.peek(t)) {
            const std::string_view w = t.text;
            if (w != "from" && w != "at" && w != "up" && w != "angle" && w != "hither" && w != "resolution") break;
            file_->tokens.next(t);
            if (!seen.insert(std::string(w)).second) throw error(t.line, "'" + std::string(w) + "' given twice in viewpoint");
            if (w == "from") view.from = read_vec3("viewpoint from");
            else if (w == "at") view.at = read_vec3("viewpoint at");
            else if (w == "up") view.up = read_vec3("viewpoint up");
            else if (w == "angle") {
                view.angle = read_float("viewpoint angle");
                if (!(view.angle > 0.0f && view.angle < 180.0f)) throw error(t.line, "viewpoint angle must be in (0, 180) degrees");
            } else if (w == "hither") {
                (void)read_float("viewpoint hither");
            } else {
                long rline = 0;
                const int64_t w0 = read_int("resolution", &rline);
                const int64_t h0 = read_int("resolution", &rline);
                if (w0 < 1 || h0 < 1 || w0 > 65536 || h0 > 65536)
                    throw error(rline, "resolution " + std::to_string(w0) + " x " + std::to_string(h0) + " out of range");
                resolution_ = {int(w0), int(h0)};
            }
        }
        if (!(length(view.at - view.from) > 0.0f)) throw error(line, "viewpoint 'from' and 'at' are the same point");
        if (!(length(cross(view.at - view.from, view.up)) > 0.0f))
            throw error(line, "viewpoint 'up' is zero or parallel to the view direction");
        view_ = view;
    }

    void parse_light() {
        LightDef light;
        light.position = read_vec3("light position");
        light.color = Vec3f{1, 1, 1};
        if (next_is_number()) light.color = read_vec3("light color");
        budgeted_push_back(lights_, light, file_->path + ": AFF light array");
    }

    void parse_anim_params(long line) {
        const float start = read_float("animation start time");
        const float end = read_float("animation end time");
        long fline = 0;
        const int64_t frames = read_int("animation frame count", &fline);
        if (frames < 1) throw error(fline, "animation frame count must be at least 1");
        if (end < start) throw error(line, "animation ends before it starts");
        if (!anim_start_) anim_start_ = start;
    }

    // --- materials -------------------------------------------------------------
    void set_material(const MaterialDef& def) {
        auto [it, inserted] = material_defs_.try_emplace(def, uint32_t(material_defs_.size()));
        if (inserted) def_list_.push_back(def);
        current_def_ = int(it->second);
    }
    static Vec3f clamp01(Vec3f c) {
        return {std::clamp(c.x, 0.0f, 1.0f), std::clamp(c.y, 0.0f, 1.0f), std::clamp(c.z, 0.0f, 1.0f)};
    }
    // NFF: f red green blue Kd Ks Shine T index_of_refraction
    void parse_nff_material() {
        const Vec3f color = read_vec3("material color");
        const float kd = read_float("material Kd");
        const float ks = read_float("material Ks");
        MaterialDef def;
        def.diffuse = clamp01(color * kd);
        def.specular = clamp01(Vec3f(ks));
        def.shine = read_float("material shine");
        def.transmittance = read_float("material transmittance");
        def.ior = read_float("material index of refraction");
        set_material(def);
    }
    // AFF: fm ambient(rgb) diffuse(rgb) specular(rgb) shine T index_of_refraction
    void parse_fm_material() {
        (void)read_vec3("material ambient color");
        MaterialDef def;
        def.diffuse = clamp01(read_vec3("material diffuse color"));
        def.specular = clamp01(read_vec3("material specular color"));
        def.shine = read_float("material shine");
        def.transmittance = read_float("material transmittance");
        def.ior = read_float("material index of refraction");
        set_material(def);
    }

    // The scene material for the current definition and a texture ("" = none).
    uint32_t material_index(const std::string& texture_name) {
        std::string texture;
        if (!texture_name.empty() && options_.load_textures) texture = find_texture(texture_name);
        const auto key = std::make_pair(current_def_, texture);
        auto it = material_index_.find(key);
        if (it != material_index_.end()) return it->second;
        const uint32_t index = uint32_t(materials_.size());
        Material m;
        if (current_def_ < 0) {
            m.name = "default";
        } else {
            const MaterialDef& d = def_list_[size_t(current_def_)];
            m.name = "aff" + std::to_string(current_def_);
            // Phong-era values onto metallic-roughness (as the OBJ loader does for MTL):
            // diffuse is the base color; the highlight exponent gives the roughness;
            // a strong specular that dominates the diffuse is a mirror-like metal;
            // transmittance T > 0 is glass with that transmission and index.
            m.base_color = d.diffuse;
            m.roughness = max_component(d.specular) < 0.01f
                              ? 1.0f
                              : std::clamp(std::sqrt(2.0f / (std::max(0.0f, d.shine) + 2.0f)), 0.0f, 1.0f);
            if (d.transmittance > 0.0f) {
                m.transmission = std::clamp(d.transmittance, 0.0f, 1.0f);
                m.base_color = Vec3f{1, 1, 1};
                m.roughness = 0.0f;
                if (d.ior >= 1.01f) m.ior = d.ior;
            } else if (max_component(d.specular) >= 0.5f && max_component(d.specular) >= max_component(d.diffuse)) {
                m.metallic = 1.0f;
                m.base_color = d.specular;
            }
        }
        fallback_color_.push_back(m.base_color);
        if (!texture.empty()) {
            m.name += "+" + fs::path(texture).filename().string();
            if (m.metallic == 0.0f && m.transmission == 0.0f) m.base_color = Vec3f{1, 1, 1};  // the map replaces the color
        }
        materials_.push_back(m);
        material_texture_.push_back(texture);
        material_index_.emplace(key, index);
        return index;
    }

    // A texture name: next to the file, in ../TextureFiles, or the same next to the root file.
    std::string find_texture(const std::string& name) {
        auto cached = texture_lookup_.find(name + "\n" + file_->path);
        if (cached != texture_lookup_.end()) return cached->second;
        std::string found;
        for (const std::string& base : {file_->path, root_}) {
            for (const std::string& candidate : {name, "../TextureFiles/" + name, "TextureFiles/" + name}) {
                std::optional<std::string> f = io::find_file_case_insensitive(io::resolve_relative(base, candidate));
                if (f && fs::is_regular_file(*f)) {
                    found = *f;
                    break;
                }
            }
            if (!found.empty()) break;
        }
        if (found.empty() && missing_textures_.insert(name).second)
            warn(file_->path + ": texture '" + name + "' not found; using the material's color");
        texture_lookup_[name + "\n" + file_->path] = found;
        return found;
    }

    // --- geometry ----------------------------------------------------------------
    [[nodiscard]] int current_node() const { return node_stack_.empty() ? 0 : node_stack_.back(); }

    void account(size_t bytes) {
        total_bytes_ += bytes;
        checked_array_bytes(geometry_what_, total_bytes_, 1);
    }

    // Loose triangles (p, pp, tt, ttp, tpa, s, c) of one transform block share a mesh.
    Mesh& loose_mesh() {
        const int node = current_node();
        auto it = loose_.find(node);
        if (it == loose_.end()) {
            PendingMesh pending;
            pending.node = node;
            pending.mesh.name = fs::path(file_->path).stem().string() + "#polygons" + std::to_string(pending_.size());
            budgeted_push_back(pending_, std::move(pending), root_ + ": AFF mesh array");
            it = loose_.emplace(node, pending_.size() - 1).first;
        }
        return pending_[it->second].mesh;
    }

    void add_triangle(const Vec3f p[3], const Vec3f* n, const Vec2f* uv, uint32_t material) {
        Mesh& mesh = loose_mesh();
        const std::string& what = polygon_what_;
        Vec3f normals[3];
        const Vec3f face = cross(p[1] - p[0], p[2] - p[0]);
        const float face_len = length(face);
        const Vec3f face_n = face_len > 0.0f ? face / face_len : Vec3f{0, 0, 1};
        for (int c = 0; c < 3; ++c) {
            Vec3f v = n ? n[c] : face_n;
            const float len = length(v);
            normals[c] = (len > 0.0f && std::isfinite(len)) ? v / len : face_n;
        }
        const uint32_t base = checked_index_count(what, uint64_t(mesh.positions.size()) + 3) - 3;
        for (int c = 0; c < 3; ++c) {
            budgeted_push_back(mesh.positions, p[c], what);
            budgeted_push_back(mesh.normals, normals[c], what);
            budgeted_push_back(mesh.uvs, uv ? uv[c] : Vec2f{0, 0}, what);
            budgeted_push_back(mesh.indices, base + uint32_t(c), what);
        }
        budgeted_push_back(mesh.material_ids, material, what);
        account(3 * (2 * sizeof(Vec3f) + sizeof(Vec2f) + sizeof(uint32_t)) + sizeof(uint32_t));
    }

    void parse_polygon(bool with_normals) {
        const size_t n = read_count(with_normals ? "polygon patch vertex count" : "polygon vertex count", with_normals ? 6 : 3);
        std::vector<Vec3f> points, normals;
        budgeted_reserve(points, n, root_ + ": AFF polygon");
        if (with_normals) budgeted_reserve(normals, n, root_ + ": AFF polygon");
        for (size_t i = 0; i < n; ++i) {
            points.push_back(read_vec3("polygon vertex"));
            if (with_normals) normals.push_back(read_vec3("polygon normal"));
        }
        if (n < 3) {
            ++skipped_polygons_;
            return;
        }
        const uint32_t material = material_index("");
        for (size_t k = 2; k < n; ++k) {  // fan: NFF polygons are planar and convex
            const Vec3f p[3] = {points[0], points[k - 1], points[k]};
            if (with_normals) {
                const Vec3f nn[3] = {normals[0], normals[k - 1], normals[k]};
                add_triangle(p, nn, nullptr, material);
            } else {
                add_triangle(p, nullptr, nullptr, material);
            }
        }
    }

    void parse_textured_triangle(bool with_normals) {
        const std::string texture = read_word("texture name");
        Vec3f p[3], n[3];
        Vec2f uv[3];
        for (int c = 0; c < 3; ++c) {
            p[c] = read_vec3("textured triangle vertex");
            if (with_normals) n[c] = read_vec3("textured triangle normal");
            const float u = read_float("texture coordinate");
            const float v = read_float("texture coordinate");
            uv[c] = Vec2f{u, v};
        }
        add_triangle(p, with_normals ? n : nullptr, uv, material_index(texture));
    }

    // tpa: keyframed triangle; linear between the two keys around the time, clamped.
    void parse_animated_triangle(long line) {
        const size_t keys = read_count("animated triangle key count", 19);
        if (keys < 1) throw error(line, "animated triangle needs at least one key");
        std::vector<TriKey> k;
        budgeted_reserve(k, keys, root_ + ": AFF animated triangle");
        for (size_t i = 0; i < keys; ++i) {
            TriKey key;
            key.t = read_float("animated triangle time");
            for (int c = 0; c < 3; ++c) {
                key.p[c] = read_vec3("animated triangle vertex");
                key.n[c] = read_vec3("animated triangle normal");
            }
            k.push_back(key);
        }
        account(keys * sizeof(TriKey));
        // Evaluated at the end, once the time is known; it goes into this block's loose mesh.
        AnimatedTriangle tri;
        tri.keys = std::move(k);
        tri.material = material_index("");
        (void)loose_mesh();
        tri.mesh = loose_.at(current_node());
        budgeted_push_back(animated_triangles_, std::move(tri), root_ + ": AFF animated triangle array");
    }

    void parse_mesh(long line) {
        Token t = expect_token("'vertices'");
        if (t.text != "vertices") throw error(t.line, "mesh: expected 'vertices', found '" + std::string(t.text.substr(0, 24)) + "'");
        const std::string where = root_ + ": AFF mesh";
        const size_t nv = read_count("mesh vertex count", 3);
        std::vector<Vec3f> verts, norms;
        std::vector<Vec2f> txts;
        budgeted_reserve(verts, nv, where + " vertex array");
        for (size_t i = 0; i < nv; ++i) verts.push_back(read_vec3("mesh vertex"));
        std::string texture_name;
        bool has_normals = false, has_uvs = false;
        t = expect_token("'normals', 'texturecoords' or 'triangles'");
        if (t.text == "normals") {
            has_normals = true;
            const size_t nn = read_count("mesh normal count", 3);
            budgeted_reserve(norms, nn, where + " normal array");
            for (size_t i = 0; i < nn; ++i) norms.push_back(read_vec3("mesh normal"));
            t = expect_token("'texturecoords' or 'triangles'");
        }
        if (t.text == "texturecoords") {
            has_uvs = true;
            const size_t nt = read_count("mesh texture coordinate count", 2);
            texture_name = read_word("mesh texture name");
            budgeted_reserve(txts, nt, where + " texture coordinate array");
            for (size_t i = 0; i < nt; ++i) {
                const float u = read_float("mesh texture coordinate");
                const float v = read_float("mesh texture coordinate");
                txts.push_back(Vec2f{u, v});
            }
            t = expect_token("'triangles'");
        }
        if (t.text != "triangles") throw error(t.line, "mesh: expected 'triangles', found '" + std::string(t.text.substr(0, 24)) + "'");
        const size_t per_triangle = 3 + (has_normals ? 3 : 0) + (has_uvs ? 3 : 0);
        const size_t nt = read_count("mesh triangle count", per_triangle);
        checked_index_count(where + " triangle count", uint64_t(nt) * 3);

        // One vertex per distinct (vertex, normal, texcoord) triple, chained per position.
        struct Corner {
            uint32_t v, n, t;
        };
        std::vector<uint32_t> first_variant(verts.size(), kAbsent), next_variant;
        std::vector<Corner> keys;
        Mesh mesh;
        budgeted_resize(mesh.indices, nt * 3, where + " index array");
        for (size_t tri = 0; tri < nt; ++tri) {
            Corner c[3];
            for (auto& corner : c) corner = {read_index("mesh vertex", verts.size()), kAbsent, kAbsent};
            if (has_normals) for (auto& corner : c) corner.n = read_index("mesh normal", norms.size());
            if (has_uvs) for (auto& corner : c) corner.t = read_index("mesh texture coordinate", txts.size());
            for (int k = 0; k < 3; ++k) {
                uint32_t found = first_variant[c[k].v];
                while (found != kAbsent && (keys[found].n != c[k].n || keys[found].t != c[k].t)) found = next_variant[found];
                if (found == kAbsent) {
                    found = uint32_t(keys.size());
                    budgeted_push_back(keys, c[k], where + " vertex array");
                    budgeted_push_back(next_variant, first_variant[c[k].v], where + " vertex array");
                    first_variant[c[k].v] = found;
                }
                mesh.indices[tri * 3 + size_t(k)] = found;
            }
        }
        const size_t n = keys.size();
        budgeted_resize(mesh.positions, n, where + " vertex array");
        for (size_t i = 0; i < n; ++i) mesh.positions[i] = verts[keys[i].v];
        if (has_uvs) {
            budgeted_resize(mesh.uvs, n, where + " texture coordinate array");
            for (size_t i = 0; i < n; ++i) mesh.uvs[i] = txts[keys[i].t];
        }
        if (has_normals) {
            budgeted_resize(mesh.normals, n, where + " normal array");
            bool any_zero = false;
            for (size_t i = 0; i < n; ++i) {
                const Vec3f v = norms[keys[i].n];
                const float len = length(v);
                if (len > 0.0f && std::isfinite(len)) mesh.normals[i] = v / len;
                else any_zero = true;
            }
            if (any_zero) {  // zero normals get the computed ones
                Mesh computed;
                computed.positions = mesh.positions;
                computed.indices = mesh.indices;
                computed.compute_vertex_normals();
                for (size_t i = 0; i < n; ++i) {
                    const Vec3f v = norms[keys[i].n];
                    if (!(length(v) > 0.0f)) mesh.normals[i] = computed.normals[i];
                }
            }
        } else if (options_.compute_missing_normals && nt > 0) {
            mesh.compute_vertex_normals();
        }
        if (nt == 0) return;  // an empty mesh adds nothing
        budgeted_resize(mesh.material_ids, nt, where + " material array");
        std::fill(mesh.material_ids.begin(), mesh.material_ids.end(), material_index(texture_name));
        mesh.name = fs::path(file_->path).stem().string() + ":" + std::to_string(line);
        account(mesh.memory_bytes());
        PendingMesh pending;
        pending.mesh = std::move(mesh);
        pending.node = current_node();
        budgeted_push_back(pending_, std::move(pending), root_ + ": AFF mesh array");
    }

    // s center.x center.y center.z radius (negative radius: inside visible)
    void parse_sphere(long line) {
        const Vec3f c = read_vec3("sphere center");
        const float r = read_float("sphere radius");
        if (r == 0.0f) {
            ++skipped_primitives_;
            return;
        }
        (void)line;
        const uint32_t material = material_index("");
        const float radius = std::fabs(r);
        auto point = [&](int stack, int slice) {
            const double theta = kPi * stack / kSphereStacks, phi = 2 * kPi * slice / kSphereSlices;
            return Vec3f{float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)), float(std::sin(theta) * std::sin(phi))};
        };
        for (int i = 0; i < kSphereStacks; ++i) {
            for (int j = 0; j < kSphereSlices; ++j) {
                const Vec3f a = point(i, j), b = point(i + 1, j), cc = point(i + 1, j + 1), d = point(i, j + 1);
                auto emit = [&](Vec3f u, Vec3f v, Vec3f w) {
                    Vec3f p[3] = {c + u * radius, c + v * radius, c + w * radius};
                    Vec3f nn[3] = {u, v, w};
                    if (r < 0) {
                        std::swap(p[1], p[2]);
                        nn[0] = -u; nn[1] = -w; nn[2] = -v;
                    }
                    add_triangle(p, nn, nullptr, material);
                };
                if (i != 0) emit(a, d, b);                  // outward winding (counter-clockwise seen from outside)
                if (i != kSphereStacks - 1) emit(b, d, cc);
            }
        }
        ++spheres_;
    }

    // c base.xyz base_radius apex.xyz apex_radius: an open cone or cylinder.
    void parse_cone(long line) {
        (void)line;
        const Vec3f base = read_vec3("cone base");
        const float r0 = std::fabs(read_float("cone base radius"));
        const Vec3f apex = read_vec3("cone apex");
        const float r1 = std::fabs(read_float("cone apex radius"));
        const Vec3f axis_v = apex - base;
        const float h = length(axis_v);
        if (!(h > 0.0f) || (r0 == 0.0f && r1 == 0.0f)) {
            ++skipped_primitives_;
            return;
        }
        const Vec3f axis = axis_v / h;
        const Vec3f helper = std::fabs(axis.x) < 0.9f ? Vec3f{1, 0, 0} : Vec3f{0, 1, 0};
        const Vec3f u = normalize(cross(axis, helper));
        const Vec3f v = cross(axis, u);
        const uint32_t material = material_index("");
        auto radial = [&](int s) {
            const double phi = 2 * kPi * s / kConeSegments;
            return u * float(std::cos(phi)) + v * float(std::sin(phi));
        };
        for (int s = 0; s < kConeSegments; ++s) {
            const Vec3f d0 = radial(s), d1 = radial(s + 1);
            const Vec3f n0 = normalize(d0 * h + axis * (r0 - r1)), n1 = normalize(d1 * h + axis * (r0 - r1));
            const Vec3f b0 = base + d0 * r0, b1 = base + d1 * r0, a0 = apex + d0 * r1, a1 = apex + d1 * r1;
            const Vec3f p1[3] = {b0, b1, a1}, q1[3] = {n0, n1, n1};
            const Vec3f p2[3] = {b0, a1, a0}, q2[3] = {n0, n1, n0};
            add_triangle(p1, q1, nullptr, material);
            add_triangle(p2, q2, nullptr, material);
        }
        ++cones_;
    }

    // --- transforms and keyframes ----------------------------------------------
    void push_node(Node node) {
        node.parent = current_node();
        node.file = file_->path;
        budgeted_push_back(nodes_, std::move(node), root_ + ": AFF transform array");
        budgeted_push_back(node_stack_, int(nodes_.size() - 1), root_ + ": AFF transform stack");
    }

    // xs sx sy sz  rx ry rz angle_deg  tx ty tz { ... }: T*R*S
    void parse_static_transform(long line) {
        const Vec3f s = read_vec3("static transform scale");
        const Vec3f axis = read_vec3("static transform rotation axis");
        const float degrees = read_float("static transform rotation angle");
        const Vec3f tr = read_vec3("static transform translation");
        expect_open_brace("xs");
        if (s.x == 0.0f || s.y == 0.0f || s.z == 0.0f) throw error(line, "static transform has a zero scale");
        Affine3f r = Affine3f::identity();
        if (length(axis) > 0.0f) r = Affine3f::rotation(axis, degrees * float(kPi / 180.0));
        else if (degrees != 0.0f) throw error(line, "static transform rotates about a zero axis");
        Node node;
        node.local = Affine3f::translation(tr) * r * Affine3f::scale(s);
        node.line = line;
        push_node(std::move(node));
    }

    void parse_animated_transform(long line) {
        Node node;
        node.animated = true;
        node.name = read_word("transform name");
        node.line = line;
        expect_open_brace("x");
        push_node(std::move(node));
    }

    void read_keys(std::vector<Key>& keys, size_t count, bool rotation) {
        keys.clear();
        budgeted_reserve(keys, count, root_ + ": AFF keyframes");
        for (size_t i = 0; i < count; ++i) {
            Key k;
            // Times that go back (Robot1.aff has some) are kept: the segment search
            // below, like BART's, takes the first segment that ends after t.
            k.t = read_float("keyframe time");
            for (int c = 0; c < (rotation ? 4 : 3); ++c) k.v[c] = read_float("keyframe value");
            if (rotation) k.v[3] *= kPi / 180.0;
            k.tension = read_float("keyframe tension");
            k.continuity = read_float("keyframe continuity");
            k.bias = read_float("keyframe bias");
            keys.push_back(k);
        }
    }

    // k name { transl N ... rot N ... scale N ... visibility N ... }
    void parse_keyframes(long line) {
        const std::string name = read_word("animation name");
        expect_open_brace("k");
        Animation anim;
        anim.file = file_->path;
        anim.line = line;
        std::set<std::string> seen;
        for (;;) {
            Token t = expect_token("keyframe type or '}'");
            if (t.text == "}") break;
            const std::string type(t.text);
            if (type != "transl" && type != "rot" && type != "scale" && type != "visibility")
                throw error(t.line, "unknown keyframe type '" + type.substr(0, 32) + "' (transl, rot, scale or visibility)");
            if (!seen.insert(type).second) throw error(t.line, "'" + type + "' given twice in animation '" + name + "'");
            const size_t numbers = type == "rot" ? 8 : type == "visibility" ? 2 : 7;
            const size_t count = read_count("keyframe count", numbers);
            if (type == "visibility") {
                for (size_t i = 0; i < count; ++i) {
                    const float time = read_float("visibility time");
                    long vline = 0;
                    const int64_t flag = read_int("visibility flag", &vline);
                    if (flag != 0 && flag != 1) throw error(vline, "visibility flag must be 0 or 1");
                    budgeted_push_back(anim.visibility, std::make_pair(double(time), flag == 1), root_ + ": AFF keyframes");
                }
                continue;
            }
            if (count < 4)
                throw error(t.line, "'" + type + "' of animation '" + name +
                                        "' needs at least 4 keyframes (the first and last only shape the spline)");
            read_keys(type == "transl" ? anim.transl : type == "rot" ? anim.rot : anim.scale, count, type == "rot");
        }
        animations_[name] = std::move(anim);  // a later definition replaces an earlier one
    }

    // --- the scene at time t ------------------------------------------------------
    Scene assemble(double t) {
        Scene scene;
        scene.source = root_;

        // Transform blocks: parents come before their children.
        std::vector<Affine3f> world(nodes_.size());
        std::vector<char> visible(nodes_.size(), 1);
        std::set<std::string> unanimated;
        for (size_t i = 0; i < nodes_.size(); ++i) {
            const Node& node = nodes_[i];
            Affine3f local = node.local;
            bool vis = true;
            if (node.animated) {
                auto it = animations_.find(node.name);
                if (it == animations_.end()) {
                    unanimated.insert(node.name);  // BART: an animation that is not there is the identity
                } else {
                    local = it->second.matrix(t);
                    vis = it->second.visible(t);
                }
            }
            world[i] = node.parent < 0 ? local : world[size_t(node.parent)] * local;
            visible[i] = char(vis && (node.parent < 0 || visible[size_t(node.parent)]));
            const float det = world[i].determinant();
            if (visible[i] && (!std::isfinite(det) || std::fabs(det) < 1e-30f))
                throw file_error(node.file, node.line, "transform is singular at time " + std::to_string(t));
        }

        // Animated triangles at time t.
        for (const AnimatedTriangle& tri : animated_triangles_) {
            const auto& k = tri.keys;
            size_t a = 0, b = 0;
            double w = 0.0;
            if (t <= k.front().t) a = b = 0;
            else if (t >= k.back().t) a = b = k.size() - 1;
            else {
                while (b + 1 < k.size() && k[b + 1].t <= t) ++b;
                a = b;
                if (b + 1 < k.size()) {
                    b = a + 1;
                    const double range = k[b].t - k[a].t;
                    w = range > 0 ? (t - k[a].t) / range : 0.0;
                }
            }
            Vec3f p[3], n[3];
            for (int c = 0; c < 3; ++c) {
                p[c] = k[a].p[c] * float(1 - w) + k[b].p[c] * float(w);
                n[c] = k[a].n[c] * float(1 - w) + k[b].n[c] * float(w);
            }
            Mesh& mesh = pending_[tri.mesh].mesh;
            const std::string& what = polygon_what_;
            const Vec3f face = cross(p[1] - p[0], p[2] - p[0]);
            const Vec3f face_n = length(face) > 0.0f ? normalize(face) : Vec3f{0, 0, 1};
            const uint32_t base = checked_index_count(what, uint64_t(mesh.positions.size()) + 3) - 3;
            for (int c = 0; c < 3; ++c) {
                budgeted_push_back(mesh.positions, p[c], what);
                budgeted_push_back(mesh.normals, length(n[c]) > 0.0f ? normalize(n[c]) : face_n, what);
                budgeted_push_back(mesh.uvs, Vec2f{0, 0}, what);
                budgeted_push_back(mesh.indices, base + uint32_t(c), what);
            }
            budgeted_push_back(mesh.material_ids, tri.material, what);
        }

        for (PendingMesh& pending : pending_) {
            if (pending.mesh.indices.empty() || !visible[size_t(pending.node)]) continue;
            scene.meshes.push_back(std::move(pending.mesh));
            scene.instances.push_back(Instance{uint32_t(scene.meshes.size() - 1), world[size_t(pending.node)]});
        }
        pending_.clear();
        if (scene.meshes.empty()) throw file_error(root_, 0, "no triangles");
        checked_index_count(root_ + ": AFF triangle count", scene.triangle_count());

        scene.materials = std::move(materials_);
        if (options_.load_textures) attach_textures(scene);

        // Camera: the viewpoint, animated by 'k camera' when there is one.
        if (view_ || animations_.count("camera")) {
            ViewDef view = view_ ? *view_ : ViewDef{};
            Camera camera;
            camera.eye = view.from;
            Vec3f dir = view.at - view.from;
            const float distance = length(dir);
            Vec3f up = view.up;
            if (auto it = animations_.find("camera"); it != animations_.end()) {
                const Animation& anim = it->second;
                if (!anim.transl.empty()) camera.eye = kb_position(anim.transl, t);
                if (!anim.rot.empty()) {
                    const Affine3f r = quat_matrix(kb_rotation(anim.rot, t));
                    dir = r.transform_vector(Vec3f{0, 0, -1});  // the viewer looks down -z with +y up
                    up = r.transform_vector(Vec3f{0, 1, 0});
                }
            }
            camera.target = camera.eye + normalize(dir) * (distance > 0.0f ? distance : 1.0f);
            camera.up = up;
            camera.vfov_degrees = view.angle;
            auto finite = [](Vec3f v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); };
            if (!finite(camera.eye) || !finite(camera.target) || !finite(camera.up))
                throw file_error(root_, view.line, "the camera is not finite at time " + std::to_string(t));
            scene.camera = camera;
        }
        if (resolution_) {
            scene.render_settings.width = resolution_->first;
            scene.render_settings.height = resolution_->second;
        }
        if (background_) scene.environment.color = *background_;

        // NFF lights do not fall off; a point light of intensity diagonal^2/4 gives
        // its color as irradiance at half the scene's diagonal.
        if (!lights_.empty()) {
            const Box3f bounds = scene.bounds();
            const float diagonal = length(bounds.hi - bounds.lo);
            const float intensity = diagonal > 0.0f && std::isfinite(diagonal) ? diagonal * diagonal / 4.0f : 1.0f;
            for (const LightDef& l : lights_) {
                Light light;
                light.type = LightType::Point;
                light.position = l.position;
                light.color = l.color;
                light.intensity = intensity;
                scene.lights.push_back(light);
            }
        }
        if (!unanimated.empty())
            note(root_ + ": " + std::to_string(unanimated.size()) + " animated transforms (e.g. '" +
                 *unanimated.begin() + "') have no keyframes; they are the identity");
        if (skipped_polygons_ > 0)
            warn(root_ + ": skipped " + std::to_string(skipped_polygons_) + " polygons with fewer than 3 vertices");
        if (spheres_ + cones_ > 0)
            note(root_ + ": tessellated " + std::to_string(spheres_) + " spheres (" +
                 std::to_string(2 * kSphereSlices * (kSphereStacks - 1)) + " triangles each) and " +
                 std::to_string(cones_) + " cones (" + std::to_string(2 * kConeSegments) + " triangles each)");
        if (skipped_primitives_ > 0)
            warn(root_ + ": skipped " + std::to_string(skipped_primitives_) + " degenerate spheres or cones");
        return scene;
    }

    void attach_textures(Scene& scene) {
        std::vector<std::string> paths;
        std::map<std::string, size_t> slot;
        for (const std::string& p : material_texture_)
            if (!p.empty() && slot.emplace(p, paths.size()).second) paths.push_back(p);
        std::vector<std::optional<Texture>> decoded = decode_textures(paths, "the material's color");
        std::vector<int32_t> scene_index(paths.size(), kNoTexture);
        for (size_t m = 0; m < scene.materials.size() && m < material_texture_.size(); ++m) {
            const std::string& p = material_texture_[m];
            if (p.empty()) continue;
            const size_t s = slot.at(p);
            if (scene_index[s] == kNoTexture && decoded[s]) {
                scene.textures.push_back(std::move(*decoded[s]));
                decoded[s].reset();
                scene_index[s] = int32_t(scene.textures.size() - 1);
            }
            if (scene_index[s] != kNoTexture) {
                scene.materials[m].base_color_texture = scene_index[s];
            } else {
                scene.materials[m].base_color = fallback_color_[m];  // the map could not be read
            }
        }
    }

    std::string root_;
    LoadOptions options_;
    const std::string polygon_what_, geometry_what_;  // budget error prefixes
    FileState* file_ = nullptr;
    std::map<std::string, std::string> texts_;
    std::map<std::string, std::pair<std::string, std::string>> include_lookup_;  // -> (path, canonical)
    std::vector<std::string> include_stack_;
    size_t expansions_ = 0, parsed_bytes_ = 0, total_bytes_ = 0;
    int64_t detail_level_ = 0;

    std::vector<Node> nodes_;
    std::vector<int> node_stack_;
    std::map<std::string, Animation> animations_;
    std::optional<double> anim_start_;

    std::map<MaterialDef, uint32_t> material_defs_;
    std::vector<MaterialDef> def_list_;
    int current_def_ = -1;
    std::vector<Material> materials_;
    std::vector<std::string> material_texture_;  // per material: resolved texture path or ""
    std::vector<Vec3f> fallback_color_;          // per material: base color without its texture
    std::map<std::pair<int, std::string>, uint32_t> material_index_;
    std::map<std::string, std::string> texture_lookup_;
    std::set<std::string> missing_textures_;

    std::vector<PendingMesh> pending_;
    std::vector<AnimatedTriangle> animated_triangles_;
    std::unordered_map<int, size_t> loose_;  // node -> pending_ index of its loose mesh
    std::vector<LightDef> lights_;
    std::optional<ViewDef> view_;
    std::optional<std::pair<int, int>> resolution_;
    std::optional<Vec3f> background_;
    size_t skipped_polygons_ = 0, skipped_primitives_ = 0, spheres_ = 0, cones_ = 0;
};

}  // namespace

Scene load_aff_at_time(const std::string& path, double time, const LoadOptions& options) {
    if (!std::isfinite(time)) throw file_error(path, 0, "animation time is not finite");
    return AffParser(path, options).load(time);
}

Scene load_aff(const std::string& path, const LoadOptions& options) {
    return AffParser(path, options).load(std::nullopt);
}

}  // namespace rf
