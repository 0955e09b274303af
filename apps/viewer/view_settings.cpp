#include "view_settings.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include "rayforge/core/error.h"
#include "text.h"

namespace rf::viewer {
namespace {

using Getter = std::function<std::string(const ViewSettings&)>;
using Setter = std::function<void(ViewSettings&, const std::string&)>;

struct Setting {
    SettingInfo info;
    Getter get;
    Setter set;
};

int parse_int(const std::string& text, int lo, int hi) {
    const double v = parse_number(text);
    if (v != std::floor(v) || v < lo || v > hi)
        throw Error("expected a whole number in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got '" + text +
                    "'");
    return int(v);
}

float parse_float(const std::string& text, double lo, double hi) {
    const double v = parse_number(text);
    if (v < lo || v > hi) throw Error("expected a number in " + number_text(lo) + ".." + number_text(hi) + ", got '" + text + "'");
    return float(v);
}

bool parse_bool(const std::string& text) {
    if (text == "on" || text == "true" || text == "1" || text == "yes") return true;
    if (text == "off" || text == "false" || text == "0" || text == "no") return false;
    throw Error("expected on or off, got '" + text + "'");
}

std::string bool_text(bool b) { return b ? "on" : "off"; }

// A setting over an int field.
Setting int_setting(std::string key, std::string group, Effect effect, int lo, int hi, std::string help,
                    std::function<int&(ViewSettings&)> field) {
    return {{std::move(key), std::move(group), effect, {}, std::move(help)},
            [field](const ViewSettings& s) { return std::to_string(field(const_cast<ViewSettings&>(s))); },
            [field, lo, hi](ViewSettings& s, const std::string& v) { field(s) = parse_int(v, lo, hi); }};
}

Setting float_setting(std::string key, std::string group, Effect effect, double lo, double hi, std::string help,
                      std::function<float&(ViewSettings&)> field) {
    return {{std::move(key), std::move(group), effect, {}, std::move(help)},
            [field](const ViewSettings& s) { return number_text(field(const_cast<ViewSettings&>(s))); },
            [field, lo, hi](ViewSettings& s, const std::string& v) { field(s) = parse_float(v, lo, hi); }};
}

Setting bool_setting(std::string key, std::string group, Effect effect, std::string help,
                     std::function<bool&(ViewSettings&)> field) {
    return {{std::move(key), std::move(group), effect, {"on", "off"}, std::move(help)},
            [field](const ViewSettings& s) { return bool_text(field(const_cast<ViewSettings&>(s))); },
            [field](ViewSettings& s, const std::string& v) { field(s) = parse_bool(v); }};
}

// A setting over an enumeration with the engine's own parse / to_string.
template <class Enum, class Parse, class Print>
Setting enum_setting(std::string key, std::string group, Effect effect, std::vector<std::string> choices,
                     std::string help, std::function<Enum&(ViewSettings&)> field, Parse parse, Print print) {
    return {{std::move(key), std::move(group), effect, std::move(choices), std::move(help)},
            [field, print](const ViewSettings& s) { return print(field(const_cast<ViewSettings&>(s))); },
            [field, parse](ViewSettings& s, const std::string& v) { field(s) = parse(v); }};
}

std::vector<std::string> builder_names() {
    return {"binned", "sweep", "sbvh", "lbvh30", "lbvh63", "hlbvh2", "gridbvh", "gridbvh-split", "ploc", "hploc"};
}

std::vector<std::string> gpu_kernel_names() {
    std::vector<std::string> names;
    for (GpuKernel k : all_gpu_kernels()) names.push_back(to_string(k));
    return names;
}

void set_device(ViewSettings& s, const std::string& value) { s.world.device = parse_device(value); }

void set_resolution(ViewSettings& s, const std::string& value) {
    const size_t x = value.find_first_of("xX");
    if (x == std::string::npos) throw Error("expected WxH, e.g. 640x360, got '" + value + "'");
    s.render.width = parse_int(value.substr(0, x), 1, 16384);
    s.render.height = parse_int(value.substr(x + 1), 1, 16384);
}

constexpr Effect rebuild = Effect::Rebuild, restart = Effect::Restart, retone = Effect::Retone;

// The structure's settings: any of them changed builds a new structure.
void add_structure_settings(std::vector<Setting>& t) {
    t.push_back(enum_setting<Structure>(
        "accel", "structure", rebuild, {"bvh", "grid", "grid-proximity", "kdtree", "brute"}, "acceleration structure",
        [](ViewSettings& s) -> Structure& { return s.world.build.structure; },
        [](const std::string& v) { return parse_structure(v); }, [](Structure v) { return to_string(v); }));
    t.push_back(enum_setting<Builder>(
        "builder", "structure", rebuild, builder_names(), "BVH builder",
        [](ViewSettings& s) -> Builder& { return s.world.build.builder; },
        [](const std::string& v) { return parse_builder(v); }, [](Builder v) { return to_string(v); }));
    t.push_back(enum_setting<Layout>(
        "layout", "structure", rebuild, {"bvh2", "bvh4", "bvh8"}, "BVH layout traced on the CPU",
        [](ViewSettings& s) -> Layout& { return s.world.build.layout; },
        [](const std::string& v) { return parse_layout(v); }, [](Layout v) { return to_string(v); }));
    t.push_back({{"update", "structure", rebuild, {"scene", "refit", "adapt", "rebuild", "clusters", "two-level"},
                  "animated scenes: how the structure follows the motion each frame (scene: the scene's own, "
                  "else " + to_string(kDefaultUpdateMethod) + ")"},
                 [](const ViewSettings& s) {
                     return s.world.update.method ? to_string(*s.world.update.method) : std::string("scene");
                 },
                 [](ViewSettings& s, const std::string& v) {
                     s.world.update.method = v == "scene" ? std::nullopt : std::optional(parse_update_method(v));
                 }});
    t.push_back(bool_setting("optimize", "structure", rebuild, "reinsertion optimizer after the build",
                             [](ViewSettings& s) -> bool& { return s.world.build.reinsertion.enabled; }));
    t.push_back(int_setting("optimize-iterations", "structure", rebuild, 0, 1000, "reinsertion rounds (0 = until no gain)",
                            [](ViewSettings& s) -> int& { return s.world.build.reinsertion.iterations; }));
    t.push_back(int_setting("leaf-size", "structure", rebuild, 1, 64, "most triangles per BVH leaf",
                            [](ViewSettings& s) -> int& { return s.world.build.max_leaf_size; }));
    t.push_back(int_setting("bins", "structure", rebuild, 2, 256, "SAH bins per axis (binned builders)",
                            [](ViewSettings& s) -> int& { return s.world.build.binned.bin_count; }));
    t.push_back(float_setting("sbvh-alpha", "structure", rebuild, 0.0, 1.0, "SBVH spatial-split threshold",
                              [](ViewSettings& s) -> float& { return s.world.build.sbvh.alpha; }));
    t.push_back(int_setting("ploc-radius", "structure", rebuild, 1, 256, "PLOC search radius",
                            [](ViewSettings& s) -> int& { return s.world.build.ploc.radius; }));
    t.push_back(float_setting("split-budget", "structure", rebuild, 0.0, 4.0, "GridBvhSplit partial-triangle budget",
                              [](ViewSettings& s) -> float& { return s.world.build.grid_bvh.split_budget; }));
    t.push_back(int_setting("grid-res", "structure", rebuild, 0, 2048, "grid cells on the longest axis (0 = auto)",
                            [](ViewSettings& s) -> int& { return s.world.build.grid.resolution; }));
    t.push_back(enum_setting<KdTraversal>(
        "kd-traversal", "structure", rebuild, {"stack", "short-stack", "restart", "pushdown"}, "kd-tree traversal",
        [](ViewSettings& s) -> KdTraversal& { return s.world.build.kdtree.traversal; },
        [](const std::string& v) { return parse_kd_traversal(v); }, [](KdTraversal v) { return to_string(v); }));
    t.push_back(enum_setting<GpuKernel>(
        "gpu-kernel", "structure", rebuild, gpu_kernel_names(), "GPU traversal kernel (CUDA device)",
        [](ViewSettings& s) -> GpuKernel& { return s.world.build.gpu_kernel; },
        [](const std::string& v) { return parse_gpu_kernel(v); }, [](GpuKernel v) { return to_string(v); }));
}

// The integrators' settings: a change restarts the accumulation.
void add_integrator_settings(std::vector<Setting>& t) {
    t.push_back(enum_setting<IntegratorKind>(
        "integrator", "integrator", restart, {"whitted", "path", "ao", "normals"}, "integrator",
        [](ViewSettings& s) -> IntegratorKind& { return s.render.integrator; },
        [](const std::string& v) { return parse_integrator(v); }, [](IntegratorKind v) { return integrator_name(v); }));
    t.push_back(int_setting("max-depth", "integrator", restart, 0, 1024, "path: bounces after the camera ray",
                            [](ViewSettings& s) -> int& { return s.render.max_depth; }));
    t.push_back(int_setting("rr-depth", "integrator", restart, 0, 1024, "path: Russian roulette from this bounce",
                            [](ViewSettings& s) -> int& { return s.render.rr_depth; }));
    t.push_back(enum_setting<LightSampling>(
        "light-sampling", "integrator", restart, {"mis", "nee", "bsdf"}, "path: light sampling",
        [](ViewSettings& s) -> LightSampling& { return s.render.light_sampling; },
        [](const std::string& v) { return parse_light_sampling(v); }, [](LightSampling v) { return to_string(v); }));
    t.push_back(float_setting("clamp", "integrator", restart, 0.0, 1e30, "path: sample clamp (0 = off)",
                              [](ViewSettings& s) -> float& { return s.render.max_sample_value; }));
    t.push_back(enum_setting<WhittedShading>(
        "shading", "integrator", restart, {"lambert", "phong", "blinn"}, "whitted: highlights",
        [](ViewSettings& s) -> WhittedShading& { return s.render.whitted_shading; },
        [](const std::string& v) { return parse_whitted_shading(v); }, [](WhittedShading v) { return to_string(v); }));
    t.push_back(int_setting("reflection-depth", "integrator", restart, 0, 30, "whitted: reflections per path",
                            [](ViewSettings& s) -> int& { return s.render.reflection_depth; }));
    t.push_back(int_setting("refraction-depth", "integrator", restart, 0, 30, "whitted: refractions per path",
                            [](ViewSettings& s) -> int& { return s.render.refraction_depth; }));
    t.push_back(float_setting("ao-radius", "integrator", restart, 0.0, 1e30, "ao: ray length (0 = 10% of the diagonal)",
                              [](ViewSettings& s) -> float& { return s.render.ao_radius; }));
    t.push_back(int_setting("ao-samples", "integrator", restart, 1, 65536, "ao: rays per sample",
                            [](ViewSettings& s) -> int& { return s.render.ao_samples; }));
    t.push_back(bool_setting("wavefront", "integrator", restart, "path on the CPU: wavefront passes",
                             [](ViewSettings& s) -> bool& { return s.render.wavefront; }));
    t.push_back({{"seed", "integrator", restart, {}, "random seed"},
                 [](const ViewSettings& s) { return std::to_string(s.render.seed); },
                 [](ViewSettings& s, const std::string& v) { s.render.seed = uint32_t(parse_int(v, 0, 2147483647)); }});
}

// The film's size and passes, the display's tone mapping, the device.
void add_image_display_and_device_settings(std::vector<Setting>& t) {
    t.push_back({{"res", "image", restart, {}, "full resolution WxH"},
                 [](const ViewSettings& s) {
                     return std::to_string(s.render.width) + "x" + std::to_string(s.render.height);
                 },
                 set_resolution});
    t.push_back(float_setting("scale", "image", restart, 0.05, 4.0, "resolution scale of the film",
                              [](ViewSettings& s) -> float& { return s.resolution_scale; }));
    t.push_back({{"motion-scale", "image", restart, {}, "divisor of each side while moving (auto or 1..8)"},
                 [](const ViewSettings& s) {
                     return s.motion_divisor == 0 ? std::string("auto") : std::to_string(s.motion_divisor);
                 },
                 [](ViewSettings& s, const std::string& v) { s.motion_divisor = v == "auto" ? 0 : parse_int(v, 1, 8); }});
    t.push_back(int_setting("spp", "image", restart, 1, 1 << 20, "passes to accumulate, then stop",
                            [](ViewSettings& s) -> int& { return s.render.spp; }));

    t.push_back(enum_setting<ToneCurve>(
        "tonemap", "display", retone, {"clamp", "reinhard", "aces"}, "tone curve",
        [](ViewSettings& s) -> ToneCurve& { return s.tone.curve; },
        [](const std::string& v) { return parse_tone_curve(v); }, [](ToneCurve v) { return to_string(v); }));
    t.push_back(float_setting("exposure", "display", retone, 0.0, 1e6, "linear scale before the curve",
                              [](ViewSettings& s) -> float& { return s.tone.exposure; }));

    t.push_back({{"device", "device", rebuild, {}, "cpu, cuda or cuda:N"},
                 [](const ViewSettings& s) { return to_string(s.world.device); }, set_device});
    t.push_back({{"threads", "device", restart, {}, "worker threads (0 = all cores)"},
                 [](const ViewSettings& s) { return std::to_string(s.render.threads); },
                 [](ViewSettings& s, const std::string& v) {
                     s.render.threads = parse_int(v, 0, 4096);
                     s.world.build.threads = s.world.paged.threads = s.render.threads;
                 }});
}

std::vector<Setting> make_settings() {
    std::vector<Setting> table;
    add_structure_settings(table);
    add_integrator_settings(table);
    add_image_display_and_device_settings(table);
    return table;
}

const std::vector<Setting>& settings_table() {
    static const std::vector<Setting> table = make_settings();
    return table;
}

// A paged scene's structure is in its file, and the library says which
// devices render one: refuse what would not apply rather than accept and
// ignore it.
void check_paged(const SettingInfo& info, const ViewSettings& changed) {
    if (!applies_to(info, SceneKind::Paged))
        throw Error("structure settings do not apply to a paged scene (its structure is in the file)");
    if (!renders_paged_scenes(changed.world.device))
        throw Error("paged scenes render on the CPU in this version (device cpu)");
}

const Setting& setting_or_throw(const std::string& key) {
    for (const Setting& s : settings_table())
        if (s.info.key == key) return s;
    std::string known;
    for (const Setting& s : settings_table()) known += (known.empty() ? "" : ", ") + s.info.key;
    throw Error("unknown setting '" + key + "' (known: " + known + ")");
}

}  // namespace

const std::vector<SettingInfo>& setting_infos() {
    static const std::vector<SettingInfo> infos = [] {
        std::vector<SettingInfo> v;
        for (const Setting& s : settings_table()) v.push_back(s.info);
        return v;
    }();
    return infos;
}

const SettingInfo* find_setting(const std::string& key) {
    for (const SettingInfo& info : setting_infos())
        if (info.key == key) return &info;
    return nullptr;
}

bool applies_to(const SettingInfo& info, SceneKind scene) {
    return scene == SceneKind::InCore || info.group != "structure";
}

std::string get_setting(const ViewSettings& settings, const std::string& key) {
    return setting_or_throw(key).get(settings);
}

void set_setting(ViewSettings& settings, const std::string& key, const std::string& value, SceneKind scene) {
    const Setting& setting = setting_or_throw(key);
    ViewSettings changed = settings;
    try {
        setting.set(changed, value);
        if (scene == SceneKind::Paged) check_paged(setting.info, changed);
        check_world_options(changed.world);
        validate_render_options(film_options(changed, false, 1));
    } catch (const Error& e) {
        throw Error("set " + key + " " + value + ": " + e.what());
    }
    settings = changed;
}

unsigned changes_between(const ViewSettings& from, const ViewSettings& to) {
    unsigned effects = 0;
    for (const Setting& s : settings_table())
        if (s.get(from) != s.get(to)) effects |= unsigned(s.info.effect);
    return effects;
}

RenderOptions film_options(const ViewSettings& settings, bool preview, int motion_divisor) {
    RenderOptions o = settings.render;
    const auto side = [&](int full) {
        const int divisor = preview ? std::max(motion_divisor, 1) : 1;
        const double scaled = double(full) * double(settings.resolution_scale) / double(divisor);
        return std::max(1, int(std::lround(scaled)));
    };
    o.width = side(settings.render.width);
    o.height = side(settings.render.height);
    o.time_budget_s = 0.0;
    if (preview) o.spp = 1;
    return o;
}

int auto_motion_divisor(double full_pass_ms, double target_ms) {
    if (!(full_pass_ms > 0.0) || !(target_ms > 0.0)) return 2;
    return std::clamp(int(std::ceil(std::sqrt(full_pass_ms / target_ms))), 1, 8);
}

}  // namespace rf::viewer
