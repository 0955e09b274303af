// The rf::Scene of a parsed AFF file at one time (load_aff_at_time: a still
// snapshot, without Scene::animation): transform blocks and animated
// triangles evaluated, meshes of visible blocks instanced in their blocks,
// materials and textures, the camera (animated by `k camera`), lights, and
// the notes and warnings about what was approximated or skipped. The pieces
// load_aff's animated scene (aff_animation.cpp) shares are here too.
#include <cmath>
#include <string>

#include "io/aff/aff_parser.h"
#include "rayforge/core/memory_budget.h"
#include "scene/animation_eval.h"

namespace rf::io::aff {

namespace {

// The two keys around t and the weight of the second; clamped to the first and last key.
struct KeyBlend {
    size_t a = 0, b = 0;
    double w = 0.0;
};
KeyBlend blend_at(const std::vector<TriKey>& k, double t) {
    KeyBlend blend;
    size_t& a = blend.a;
    size_t& b = blend.b;
    if (t <= k.front().t) a = b = 0;
    else if (t >= k.back().t) a = b = k.size() - 1;
    else {
        while (b + 1 < k.size() && k[b + 1].t <= t) ++b;
        a = b;
        if (b + 1 < k.size()) {
            b = a + 1;
            const double range = k[b].t - k[a].t;
            blend.w = range > 0 ? (t - k[a].t) / range : 0.0;
        }
    }
    return blend;
}

}  // namespace

void animated_triangle_at(const AnimatedTriangle& tri, double t, Vec3f p[3], Vec3f n[3]) {
    const auto& k = tri.keys;
    const KeyBlend blend = blend_at(k, t);
    const double w = blend.w;
    for (int c = 0; c < 3; ++c) {
        p[c] = k[blend.a].p[c] * float(1 - w) + k[blend.b].p[c] * float(w);
        n[c] = k[blend.a].n[c] * float(1 - w) + k[blend.b].n[c] * float(w);
    }
}

namespace {

void append_triangle(Mesh& mesh, const Vec3f p[3], const Vec3f n[3], uint32_t material, const std::string& what) {
    const Vec3f face = cross(p[1] - p[0], p[2] - p[0]);
    const Vec3f face_n = length(face) > 0.0f ? normalize(face) : Vec3f{0, 0, 1};
    const uint32_t base = checked_index_count(what, uint64_t(mesh.positions.size()) + 3) - 3;
    for (int c = 0; c < 3; ++c) {
        budgeted_push_back(mesh.positions, p[c], what);
        budgeted_push_back(mesh.normals, length(n[c]) > 0.0f ? normalize(n[c]) : face_n, what);
        budgeted_push_back(mesh.uvs, Vec2f{0, 0}, what);
        budgeted_push_back(mesh.indices, base + uint32_t(c), what);
    }
    budgeted_push_back(mesh.material_ids, material, what);
}

}  // namespace

Scene AffParser::assemble(double t) {
    Scene scene;
    scene.source = root_;
    const BlockStates blocks = evaluate_blocks(t);
    add_animated_triangles(t);
    move_meshes(scene, blocks);
    add_materials_and_settings(scene);
    if (view_ || animations_.count("camera")) scene.camera = make_camera(t);
    add_lights(scene);
    report(blocks.unanimated);
    return scene;
}

void AffParser::add_materials_and_settings(Scene& scene) {
    scene.materials = std::move(materials_);
    for (Material& m : scene.materials) m.ambient = m.ambient * ambient_light_;  // k_a * I_a
    if (options_.load_textures) attach_textures(scene);
    if (resolution_) {
        scene.render_settings.width = resolution_->first;
        scene.render_settings.height = resolution_->second;
    }
    if (background_) scene.environment.color = *background_;
}

// Transform blocks: parents come before their children.
AffParser::BlockStates AffParser::evaluate_blocks(double t) const {
    BlockStates blocks;
    blocks.world.resize(nodes_.size());
    blocks.visible.assign(nodes_.size(), 1);
    for (size_t i = 0; i < nodes_.size(); ++i) {
        const Node& node = nodes_[i];
        Affine3f local = node.local;
        bool vis = true;
        if (node.animated) {
            auto it = animations_.find(node.name);
            if (it == animations_.end()) {
                blocks.unanimated.insert(node.name);  // BART: an animation that is not there is the identity
            } else {
                local = it->second.matrix(t);
                vis = it->second.visible(t);
            }
        }
        blocks.world[i] = node.parent < 0 ? local : blocks.world[size_t(node.parent)] * local;
        blocks.visible[i] = char(vis && (node.parent < 0 || blocks.visible[size_t(node.parent)]));
        const float det = blocks.world[i].determinant();
        if (blocks.visible[i] && (!std::isfinite(det) || std::fabs(det) < 1e-30f))
            throw file_error(node.file, node.line, "transform is singular at time " + std::to_string(t));
    }
    return blocks;
}

// Animated triangles at time t, into their blocks' loose meshes.
void AffParser::add_animated_triangles(double t) {
    for (const AnimatedTriangle& tri : animated_triangles_) {
        Vec3f p[3], n[3];
        animated_triangle_at(tri, t, p, n);
        append_triangle(pending_[tri.mesh].mesh, p, n, tri.material, polygon_what_);
    }
}

// Non-empty meshes of visible blocks, each instanced with its block's transform.
void AffParser::move_meshes(Scene& scene, const BlockStates& blocks) {
    for (PendingMesh& pending : pending_) {
        if (pending.mesh.indices.empty() || !blocks.visible[size_t(pending.node)]) continue;
        scene.meshes.push_back(std::move(pending.mesh));
        scene.instances.push_back(Instance{uint32_t(scene.meshes.size() - 1), blocks.world[size_t(pending.node)]});
    }
    pending_.clear();
    if (scene.meshes.empty()) throw file_error(root_, 0, "no triangles");
    checked_index_count(root_ + ": AFF triangle count", scene.triangle_count());
}

// Camera: the viewpoint, animated by 'k camera' when there is one.
Camera AffParser::make_camera(double t) const {
    ViewDef view = view_ ? *view_ : ViewDef{};
    Camera camera;
    camera.eye = view.from;
    Vec3f dir = view.at - view.from;
    const float distance = length(dir);
    Vec3f up = view.up;
    if (auto it = animations_.find("camera"); it != animations_.end()) {
        const Animation& anim = it->second;
        if (!anim.transl.empty()) evaluate_track(anim.transl, float(t), &camera.eye.x, false);
        if (!anim.rot.empty()) {
            float q[4];
            evaluate_track(anim.rot, float(t), q, true);
            const Affine3f r = quaternion_matrix(q);
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
    return camera;
}

// NFF lights do not fall off; a point light of intensity diagonal^2/4 gives
// its color as irradiance at half the scene's diagonal.
void AffParser::add_lights(Scene& scene) const {
    if (lights_.empty()) return;
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

void AffParser::report(const std::set<std::string>& unanimated) const {
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
}

}  // namespace rf::io::aff
