#!/usr/bin/env python3
"""Writes anim_basic.gltf, the hand-checkable animated glTF of
tests/gltf_animation_test.cpp (one embedded base64 buffer):

  node 0 root      translation (1,0,0), LINEAR translation track t=0..2 -> (1..3,0,0)
    node 1 joint0  at the root
      node 2 joint1  (0,1,0), LINEAR rotation track t=0..1: 0 -> 90 deg about z
    node 3 box     mesh 1 (a static triangle), CUBICSPLINE scale track t=0..1: 1 -> 2, zero tangents
  node 4 skinned   mesh 0, skin 0 (joints 1, 2); its translation (5,5,5) is ignored
  node 5 morphed   mesh 2 (2 morph targets, mesh weights 0.5 0.5), translation (0,0,-2),
                   STEP weights track t=0: (0, 0.5), t=1: (1, 0.25)

Mesh 0 vertices (bind space): (1,0,0) on joint0, (1,2,0) on joint1, (2,1,0)
half and half (normalised unsigned byte weights 255, 255: renormalised);
joints are unsigned shorts. Two unused accessors serve the malformed-input
tests: decreasing float times (accessor 'bad_times') and the unsigned short
indices (a non-float sampler input).
"""
import base64, json, struct, os

buf = bytearray()
views, accessors = [], []

def add(data, component, type_, count, normalized=False, minmax=None):
    while len(buf) % 4: buf.append(0)
    views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": len(data)})
    buf.extend(data)
    a = {"bufferView": len(views) - 1, "componentType": component, "type": type_, "count": count}
    if normalized: a["normalized"] = True
    if minmax: a["min"], a["max"] = minmax
    accessors.append(a)
    return len(accessors) - 1

F, UB, US = 5126, 5121, 5123
def floats(*v): return struct.pack("<%df" % len(v), *v)

tri = floats(0, 0, 0, 1, 0, 0, 0, 1, 0)
skin_pos = add(floats(1, 0, 0, 1, 2, 0, 2, 1, 0), F, "VEC3", 3, minmax=([1, 0, 0], [2, 2, 0]))
skin_joints = add(struct.pack("<12H", 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0), US, "VEC4", 3)
skin_weights = add(bytes([255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 0, 0]), UB, "VEC4", 3, normalized=True)
indices = add(struct.pack("<3H", 0, 1, 2) + b"\0\0", US, "SCALAR", 3)
views[-1]["byteLength"] = 6
box_pos = add(tri, F, "VEC3", 3, minmax=([0, 0, 0], [1, 1, 0]))
morph_pos = add(tri, F, "VEC3", 3, minmax=([0, 0, 0], [1, 1, 0]))
target0 = add(floats(0, 0, 1, 0, 0, 0, 0, 0, 0), F, "VEC3", 3, minmax=([0, 0, 0], [0, 0, 1]))
target1 = add(floats(0, 0, 0, 0, 0, 2, 0, 0, 0), F, "VEC3", 3, minmax=([0, 0, 0], [0, 0, 2]))
inverse_bind = add(floats(1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1,
                          1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, -1, 0, 1), F, "MAT4", 2)
t02 = add(floats(0, 2), F, "SCALAR", 2, minmax=([0], [2]))
t01 = add(floats(0, 1), F, "SCALAR", 2, minmax=([0], [1]))
root_translation = add(floats(1, 0, 0, 3, 0, 0), F, "VEC3", 2)
s = 0.7071067811865476
joint_rotation = add(floats(0, 0, 0, 1, 0, 0, s, s), F, "VEC4", 2)
box_scale = add(floats(0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0, 2, 2, 2, 0, 0, 0), F, "VEC3", 6)
morph_weights = add(floats(0, 0.5, 1, 0.25), F, "SCALAR", 4)
bad_times = add(floats(1, 0), F, "SCALAR", 2)
assert bad_times == 15 and indices == 3

doc = {
    "asset": {"version": "2.0", "generator": "tests/data/gltf_anim/make_fixture.py"},
    "scene": 0,
    "scenes": [{"nodes": [0, 4, 5]}],
    "nodes": [
        {"name": "root", "translation": [1, 0, 0], "children": [1, 3]},
        {"name": "joint0", "children": [2]},
        {"name": "joint1", "translation": [0, 1, 0]},
        {"name": "box", "mesh": 1},
        {"name": "skinned", "mesh": 0, "skin": 0, "translation": [5, 5, 5]},
        {"name": "morphed", "mesh": 2, "translation": [0, 0, -2]},
    ],
    "meshes": [
        {"name": "skinned", "primitives": [{"attributes": {"POSITION": skin_pos, "JOINTS_0": skin_joints,
                                                           "WEIGHTS_0": skin_weights}, "indices": indices}]},
        {"name": "box", "primitives": [{"attributes": {"POSITION": box_pos}}]},
        {"name": "morphed", "weights": [0.5, 0.5],
         "primitives": [{"attributes": {"POSITION": morph_pos},
                         "targets": [{"POSITION": target0}, {"POSITION": target1}]}]},
    ],
    "skins": [{"joints": [1, 2], "inverseBindMatrices": inverse_bind}],
    "animations": [{
        "name": "test",
        "samplers": [
            {"input": t02, "output": root_translation, "interpolation": "LINEAR"},
            {"input": t01, "output": joint_rotation},
            {"input": t01, "output": box_scale, "interpolation": "CUBICSPLINE"},
            {"input": t01, "output": morph_weights, "interpolation": "STEP"},
        ],
        "channels": [
            {"sampler": 0, "target": {"node": 0, "path": "translation"}},
            {"sampler": 1, "target": {"node": 2, "path": "rotation"}},
            {"sampler": 2, "target": {"node": 3, "path": "scale"}},
            {"sampler": 3, "target": {"node": 5, "path": "weights"}},
        ],
    }],
    "bufferViews": views,
    "accessors": accessors,
    "buffers": [{"byteLength": len(buf),
                 "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}],
}
here = os.path.dirname(os.path.abspath(__file__))
with open(os.path.join(here, "anim_basic.gltf"), "w") as f:
    json.dump(doc, f, indent=1)
    f.write("\n")
