#!/usr/bin/env python3
"""Writes the animation reproducers of this directory (python3 stdlib only).

Both multiply little input into much animation data in many allocations,
each under the memory budget; the loaders now count them together
(tests/fuzz_regressions_test.cpp loads them under a 16 MiB budget).
  gltf_morph_targets_copied_per_node.gltf: 120 nodes share a mesh of 120
    vertices with 120 morph targets; each node gets its own copy (~20 MB).
  aff_keyframes_copied_per_transform_block.aff: 1500 `x` blocks of one name
    whose `k` block has 400 keys; each block gets its own copy (~17 MB).
"""
import base64
import json
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


def morph_copies(targets=120, nodes=120, vertices=120):
    pos = struct.pack("<%df" % (3 * vertices), *[float((i * 7) % 13) for i in range(3 * vertices)])
    return {"asset": {"version": "2.0"},
            "buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(pos).decode(),
                         "byteLength": len(pos)}],
            "bufferViews": [{"buffer": 0, "byteLength": len(pos)}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": vertices, "type": "VEC3"}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "targets": [{"POSITION": 0}] * targets}],
                        "weights": [0.01] * targets}],
            "nodes": [{"children": list(range(1, nodes + 1))}] + [{"mesh": 0}] * nodes,
            "scenes": [{"nodes": [0]}], "scene": 0}


def keyframe_copies(keys=400, blocks=1500):
    lines = ["a 0 1 10", "x a", "{", "p 3", "0 0 0", "1 0 0", "0 1 0", "}"]
    lines += ["x a {\n}"] * blocks
    lines += ["k a", "{", "transl %d" % keys] + ["%d %d 0 0 0 0 0" % (i, i % 5) for i in range(keys)] + ["}"]
    return "\n".join(lines) + "\n"


with open(os.path.join(HERE, "gltf_morph_targets_copied_per_node.gltf"), "w") as f:
    f.write(json.dumps(morph_copies(), separators=(",", ":")))
with open(os.path.join(HERE, "aff_keyframes_copied_per_transform_block.aff"), "w") as f:
    f.write(keyframe_copies())
