// The rf::Scene of a parsed AFF file with its animation kept (load_aff):
//   - one AnimatedNode per transform block that is animated (`x`), under an
//     animated block, or above one; static blocks among them carry their
//     matrix, so world = parent's world * local in the same order as the
//     still scene (aff_assemble.cpp); the rest stay static instances;
//   - `x` blocks get their `k` tracks (Kochanek-Bartels transl/scale, rot as
//     quaternions, step visibility), as aff_keyframes.h describes;
//   - tpa triangles: vertex keyframes of their block's loose mesh at the union
//     of their key times (linear between keys, as BART interpolates them);
//   - `k camera`: a node moving a camera that looks down -z (with rot) or
//     along the viewpoint's direction (without);
//   - the time range and frame rate from the first `a start end frames`.
// Scene::set_time(t) then gives what load_aff_at_time(t) gives, with hidden
// blocks kept as hidden instances (tests/aff_animation_test.cpp).
#include <algorithm>
#include <cmath>
#include <string>

#include "io/aff/aff_parser.h"
#include "rayforge/core/memory_budget.h"

namespace rf::io::aff {

Scene AffParser::assemble_animated(double t) {
    Scene scene;
    scene.source = root_;
    const BlockStates blocks = evaluate_blocks(t);  // singular transforms at the start are errors here
    const std::vector<int32_t> node_of = add_nodes(scene.animation);
    std::vector<size_t> static_vertices(pending_.size());
    for (size_t i = 0; i < pending_.size(); ++i) static_vertices[i] = pending_[i].mesh.positions.size();
    add_animated_triangles(t);
    place_meshes(scene, blocks, node_of, static_vertices);
    add_materials_and_settings(scene);
    if (animations_.count("camera")) add_camera_animation(scene);
    else if (view_) scene.camera = make_camera(t);
    set_time_range(scene.animation);
    scene.set_time(float(t));
    scene.animation.evaluated = false;  // the caller's first set_time reports everything animated
    if (scene.camera && !(is_finite(scene.camera->eye) && is_finite(scene.camera->target) && is_finite(scene.camera->up)))
        throw file_error(root_, view_ ? view_->line : 0, "the camera is not finite at time " + std::to_string(t));
    add_lights(scene);
    report(blocks.unanimated);
    return scene;
}

namespace {

// The bytes of an animation's tracks.
size_t track_bytes(const Animation& a) {
    size_t bytes = 0;
    for (const Track* t : {&a.transl, &a.rot, &a.scale, &a.visibility})
        bytes += (t->times.size() + t->values.size()) * sizeof(float) + t->tcb.size() * sizeof(Vec3f);
    return bytes;
}

}  // namespace

// Per parser node, its AnimatedNode (or -1: static, not under or above an animated block).
// Every `x` block of a name gets its own copy of the name's keys: they count
// against the budget with the geometry, or a small file with many blocks of
// one name and many keys would need gigabytes
// (tests/data/fuzz_repro/aff_keyframes_copied_per_transform_block.aff).
std::vector<int32_t> AffParser::add_nodes(rf::Animation& animation) {
    const size_t n = nodes_.size();
    std::vector<char> needed(n, 0);
    for (size_t i = 1; i < n; ++i)  // node 0, the world, is the identity
        needed[i] = char(nodes_[i].animated || (nodes_[i].parent > 0 && needed[size_t(nodes_[i].parent)]));
    for (size_t i = n; i-- > 1;)
        if (needed[i] && nodes_[i].parent > 0) needed[size_t(nodes_[i].parent)] = 1;
    std::vector<int32_t> node_of(n, -1);
    for (size_t i = 1; i < n; ++i) {
        if (!needed[i]) continue;
        const Node& node = nodes_[i];
        AnimatedNode an;
        an.name = node.name;
        if (!node.animated) {
            an.matrix = node.local;
        } else if (auto it = animations_.find(node.name); it != animations_.end()) {
            account(track_bytes(it->second));
            an = it->second.node(node.name);
        }
        an.parent = node.parent > 0 ? node_of[size_t(node.parent)] : -1;
        node_of[i] = int32_t(animation.nodes.size());
        budgeted_push_back(animation.nodes, std::move(an), root_ + ": AFF animation nodes");
    }
    return node_of;
}

// Non-empty meshes, each instanced in its block (hidden ones too: set_time shows them when their block does).
void AffParser::place_meshes(Scene& scene, const BlockStates& blocks, const std::vector<int32_t>& node_of,
                             const std::vector<size_t>& static_vertices) {
    std::vector<std::vector<size_t>> animated(pending_.size());  // per pending mesh, its tpa triangles in order
    for (size_t i = 0; i < animated_triangles_.size(); ++i) animated[animated_triangles_[i].mesh].push_back(i);
    for (size_t p = 0; p < pending_.size(); ++p) {
        PendingMesh& pending = pending_[p];
        if (pending.mesh.indices.empty()) continue;
        const size_t block = size_t(pending.node);
        const uint32_t mesh = uint32_t(scene.meshes.size());
        scene.meshes.push_back(std::move(pending.mesh));
        const uint32_t instance = uint32_t(scene.instances.size());
        scene.instances.push_back(Instance{mesh, blocks.world[block], blocks.visible[block] != 0});
        if (node_of[block] >= 0)
            scene.animation.instances.push_back(InstanceAnimation{instance, uint32_t(node_of[block]), Affine3f::identity()});
        if (!animated[p].empty()) add_vertex_keyframes(scene, mesh, static_vertices[p], animated[p]);
    }
    pending_.clear();
    if (scene.meshes.empty()) throw file_error(root_, 0, "no triangles");
    checked_index_count(root_ + ": AFF triangle count", scene.triangle_count());
}

// The mesh at every key time of its tpa triangles (vertices from first_vertex on, three per triangle).
void AffParser::add_vertex_keyframes(Scene& scene, uint32_t mesh_index, size_t first_vertex,
                                     const std::vector<size_t>& triangles) {
    const Mesh& mesh = scene.meshes[mesh_index];
    std::vector<float> times;
    for (size_t tri : triangles)
        for (const TriKey& k : animated_triangles_[tri].keys) budgeted_push_back(times, float(k.t), root_ + ": AFF keyframes");
    std::sort(times.begin(), times.end());
    times.erase(std::unique(times.begin(), times.end()), times.end());
    account(times.size() * mesh.positions.size() * 2 * sizeof(Vec3f));
    VertexKeyframes vk;
    vk.mesh = mesh_index;
    vk.interpolation = Interpolation::Linear;
    vk.times = times;
    for (float time : times) {
        std::vector<Vec3f> p = mesh.positions, n = mesh.normals;
        for (size_t j = 0; j < triangles.size(); ++j) {
            Vec3f* tp = &p[first_vertex + 3 * j];
            Vec3f* tn = &n[first_vertex + 3 * j];
            animated_triangle_at(animated_triangles_[triangles[j]], time, tp, tn);
            const Vec3f face = cross(tp[1] - tp[0], tp[2] - tp[0]);  // as append_triangle: zero normals take the face's
            for (int c = 0; c < 3; ++c)
                if (!(length(tn[c]) > 0.0f)) tn[c] = length(face) > 0.0f ? normalize(face) : Vec3f{0, 0, 1};
        }
        vk.positions.push_back(std::move(p));
        vk.normals.push_back(std::move(n));
    }
    scene.animation.vertex_keyframes.push_back(std::move(vk));
}

// `k camera`: a node at the viewpoint (or on the transl keys), turned by the rot keys.
void AffParser::add_camera_animation(Scene& scene) const {
    const Animation& anim = animations_.at("camera");
    const ViewDef view = view_ ? *view_ : ViewDef{};
    AnimatedNode node;
    node.name = "camera";
    node.translation = view.from;
    node.translation_track = anim.transl;
    node.rotation_track = anim.rot;
    CameraAnimation camera;
    camera.node = int32_t(scene.animation.nodes.size());
    scene.animation.nodes.push_back(std::move(node));
    Camera rest;
    rest.eye = Vec3f{0, 0, 0};
    const Vec3f dir = view.at - view.from;
    // Without rot keys the camera keeps the viewpoint's direction and up; with them
    // the viewer looks down -z with +y up, as make_camera does.
    rest.target = anim.rot.empty() ? dir : Vec3f{0, 0, -length(dir)};
    rest.up = anim.rot.empty() ? view.up : Vec3f{0, 1, 0};
    rest.vfov_degrees = view.angle;
    camera.rest = rest;
    scene.animation.camera = std::move(camera);
}

// The first `a` line's range; without one, from 0 to the last key. BART's
// frames run from start to end inclusive: frames_per_second = (frames - 1) / (end - start).
void AffParser::set_time_range(rf::Animation& animation) const {
    if (anim_start_) {
        animation.start = float(*anim_start_);
        animation.end = float(anim_end_);
        if (anim_frames_ > 1 && anim_end_ > *anim_start_)
            animation.frames_per_second = float(double(anim_frames_ - 1) / (anim_end_ - *anim_start_));
        return;
    }
    float end = 0.0f;
    auto extend = [&](const Track& tr) {
        for (float time : tr.times) end = std::max(end, time);
    };
    for (const AnimatedNode& n : animation.nodes) extend(n.translation_track), extend(n.rotation_track), extend(n.scale_track);
    for (const VertexKeyframes& vk : animation.vertex_keyframes) end = std::max(end, vk.times.back());
    animation.start = 0.0f;
    animation.end = end;
}

}  // namespace rf::io::aff
