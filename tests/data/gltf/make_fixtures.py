#!/usr/bin/env python3
"""Writes the small glTF 2.0 fixtures used by tests/gltf_loader_test.cpp.

python3 stdlib only; run from anywhere: `python3 tests/data/gltf/make_fixtures.py`.
The output is deterministic, so re-running it leaves git clean.
"""
import base64
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125


class Buffer:
    """Accumulates binary data, buffer views and accessors for one glTF buffer."""

    def __init__(self):
        self.data = bytearray()
        self.views = []
        self.accessors = []

    def align(self):
        while len(self.data) % 4:
            self.data.append(0)

    def view(self, payload, stride=None, target=None):
        self.align()
        v = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload)}
        if stride:
            v["byteStride"] = stride
        if target:
            v["target"] = target
        self.data += payload
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, view, ctype, count, type_, offset=0, normalized=False, lo=None, hi=None):
        a = {"bufferView": view, "componentType": ctype, "count": count, "type": type_}
        if offset:
            a["byteOffset"] = offset
        if normalized:
            a["normalized"] = True
        if lo is not None:
            a["min"], a["max"] = lo, hi
        self.accessors.append(a)
        return len(self.accessors) - 1

    def vec3s(self, points):
        payload = b"".join(struct.pack("<3f", *p) for p in points)
        lo = [min(p[i] for p in points) for i in range(3)]
        hi = [max(p[i] for p in points) for i in range(3)]
        return self.accessor(self.view(payload, target=34962), FLOAT, len(points), "VEC3", lo=lo, hi=hi)

    def indices(self, values, ctype):
        fmt = {UBYTE: "B", USHORT: "H", UINT: "I"}[ctype]
        payload = struct.pack("<%d%s" % (len(values), fmt), *values)
        return self.accessor(self.view(payload, target=34963), ctype, len(values), "SCALAR")


def gltf_doc(buf, meshes, nodes, scenes=None, **extra):
    doc = {"asset": {"version": "2.0", "generator": "rayforge make_fixtures.py"},
           "scene": 0, "scenes": scenes or [{"nodes": [0]}], "nodes": nodes, "meshes": meshes,
           "accessors": buf.accessors, "bufferViews": buf.views}
    doc.update(extra)
    return doc


def data_uri(data):
    return "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()


def write_json(name, doc):
    with open(os.path.join(HERE, name), "w") as f:
        json.dump(doc, f, indent=1, sort_keys=True)
        f.write("\n")


def write_bytes(name, data):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(bytes(data))


def png(width, height, rgba_rows):
    """A minimal RGBA8 PNG."""
    raw = b"".join(b"\x00" + bytes(row) for row in rgba_rows)

    def chunk(kind, payload):
        c = kind + payload
        return struct.pack(">I", len(payload)) + c + struct.pack(">I", zlib.crc32(c) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


QUAD = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
QUAD_INDICES = [0, 1, 2, 0, 2, 3]


def quad_external():
    """quad_external.gltf + .bin: indexed (ushort) unit quad in z=0, no normals, node translated (1,2,3)."""
    buf = Buffer()
    pos = buf.vec3s(QUAD)
    idx = buf.indices(QUAD_INDICES, USHORT)
    doc = gltf_doc(buf, [{"name": "quad", "primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}],
                   [{"mesh": 0, "translation": [1, 2, 3]}],
                   buffers=[{"uri": "quad_external.bin", "byteLength": len(buf.data)}])
    write_bytes("quad_external.bin", buf.data)
    write_json("quad_external.gltf", doc)


def embedded():
    """embedded.gltf: data-URI buffer; interleaved POSITION/NORMAL (byteStride 24) with normalized
    ushort UVs, non-indexed; a triangle strip (ubyte indices, 2 triangles); a points primitive (skipped)."""
    buf = Buffer()
    tri = [((0, 0, 0), (0, 0, 1)), ((2, 0, 0), (0, 0, 1)), ((0, 2, 0), (0, 0, 1))]
    inter = b"".join(struct.pack("<6f", *p, *n) for p, n in tri)
    v = buf.view(inter, stride=24, target=34962)
    pos = buf.accessor(v, FLOAT, 3, "VEC3", 0, lo=[0, 0, 0], hi=[2, 2, 0])
    nor = buf.accessor(v, FLOAT, 3, "VEC3", 12)
    uvs = buf.accessor(buf.view(struct.pack("<6H", 0, 0, 65535, 0, 0, 65535)), USHORT, 3, "VEC2",
                       normalized=True)
    strip_pos = buf.vec3s([(0, 0, 5), (1, 0, 5), (0, 1, 5), (1, 1, 5)])
    strip_idx = buf.indices([0, 1, 2, 3], UBYTE)
    doc = gltf_doc(buf, [{"name": "mixed", "primitives": [
        {"attributes": {"POSITION": pos, "NORMAL": nor, "TEXCOORD_0": uvs}},
        {"attributes": {"POSITION": strip_pos}, "indices": strip_idx, "mode": 5},
        {"attributes": {"POSITION": strip_pos}, "mode": 0}]}],
        [{"mesh": 0}], buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}])
    write_json("embedded.gltf", doc)


def cube_positions():
    pts, idx = [], []
    faces = [((1, 0, 0), (0, 1, 0)), ((-1, 0, 0), (0, 1, 0)), ((0, 1, 0), (0, 0, 1)),
             ((0, -1, 0), (0, 0, 1)), ((0, 0, 1), (1, 0, 0)), ((0, 0, -1), (1, 0, 0))]
    for n, u in faces:
        w = (n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0])
        base = len(pts)
        for su, sw in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            pts.append(tuple(0.5 * (n[i] + su * u[i] + sw * w[i]) for i in range(3)))
        idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return pts, idx


def cube_glb():
    """cube.glb: unit cube (12 triangles, uint32 indices) under a node whose matrix scales by 2
    and translates by (0, 0, -5)."""
    buf = Buffer()
    pts, idx = cube_positions()
    pos = buf.vec3s(pts)
    ind = buf.indices(idx, UINT)
    buf.align()
    doc = gltf_doc(buf, [{"name": "cube", "primitives": [{"attributes": {"POSITION": pos}, "indices": ind}]}],
                   [{"mesh": 0, "matrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, -5, 1]}],
                   buffers=[{"byteLength": len(buf.data)}])
    js = json.dumps(doc, sort_keys=True).encode()
    while len(js) % 4:
        js += b" "
    body = bytes(buf.data)
    total = 12 + 8 + len(js) + 8 + len(body)
    glb = struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
    glb += struct.pack("<I4s", len(body), b"BIN\x00") + body
    write_bytes("cube.glb", glb)


def hierarchy():
    """hierarchy.gltf: node tree (root rotates 90 deg about +y and translates (0,0,-2); child scales
    by 3), a camera node, KHR_lights_punctual point/spot/directional, material extensions and a
    2x2 external PNG texture with a sampler."""
    buf = Buffer()
    pos = buf.vec3s(QUAD)
    uvs = buf.accessor(buf.view(struct.pack("<8f", 0, 0, 1, 0, 1, 1, 0, 1)), FLOAT, 4, "VEC2")
    idx = buf.indices(QUAD_INDICES, UBYTE)
    s = math.sqrt(0.5)
    nodes = [
        {"name": "root", "rotation": [0, s, 0, s], "translation": [0, 0, -2], "children": [1, 2]},
        {"name": "child", "scale": [3, 3, 3], "mesh": 0},
        {"name": "point_holder", "translation": [0, 1, 0],
         "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"name": "camera", "translation": [0, 1, 10], "camera": 0},
        {"name": "spot", "translation": [0, 4, 0], "rotation": [-s, 0, 0, s],  # -90 deg about x: -Z -> -Y
         "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"name": "sun", "extensions": {"KHR_lights_punctual": {"light": 2}}},
        {"name": "unused_camera", "translation": [5, 5, 5], "camera": 0},
    ]
    materials = [{
        "name": "fancy",
        "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 0.75], "baseColorTexture": {"index": 0},
                                 "metallicFactor": 0.2, "roughnessFactor": 0.7,
                                 "metallicRoughnessTexture": {"index": 1}},
        "normalTexture": {"index": 1, "scale": 0.5},
        "emissiveFactor": [1.0, 0.5, 0.25], "emissiveTexture": {"index": 0},
        "alphaMode": "MASK", "alphaCutoff": 0.3, "doubleSided": True,
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0},
                       "KHR_materials_transmission": {"transmissionFactor": 0.9},
                       "KHR_materials_ior": {"ior": 1.33}}}]
    doc = gltf_doc(buf, [{"name": "quad", "primitives": [
        {"attributes": {"POSITION": pos, "TEXCOORD_0": uvs}, "indices": idx, "material": 0}]}],
        nodes, scenes=[{"nodes": [0, 3, 4, 5]}, {"nodes": [6]}],
        buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}],
        materials=materials,
        textures=[{"source": 0, "sampler": 0}, {"source": 0}],
        samplers=[{"wrapS": 33071, "wrapT": 33648}],
        images=[{"uri": "checker.png"}],
        cameras=[{"type": "perspective", "perspective": {"yfov": math.radians(30), "znear": 0.1}}],
        extensionsUsed=["KHR_lights_punctual", "KHR_materials_emissive_strength",
                        "KHR_materials_transmission", "KHR_materials_ior"],
        extensions={"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1, 0.5, 0.25], "intensity": 20},
            {"type": "spot", "intensity": 5, "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.5}},
            {"type": "directional", "intensity": 2}]}})
    doc["scene"] = 0
    write_json("hierarchy.gltf", doc)
    # 2x2 RGBA: red, green / blue, white.
    write_bytes("checker.png", png(2, 2, [[255, 0, 0, 255, 0, 255, 0, 255], [0, 0, 255, 255, 255, 255, 255, 255]]))


def broken():
    """Malformed files: each must fail with a one-line rf::Error naming the file."""
    # A buffer file that does not exist.
    buf = Buffer()
    pos = buf.vec3s(QUAD[:3])
    write_json("missing_buffer.gltf", gltf_doc(
        buf, [{"primitives": [{"attributes": {"POSITION": pos}}]}], [{"mesh": 0}],
        buffers=[{"uri": "does_not_exist.bin", "byteLength": len(buf.data)}]))

    # An accessor whose count runs past the end of its buffer view.
    buf = Buffer()
    pos = buf.vec3s(QUAD[:3])
    buf.accessors[pos]["count"] = 1000
    write_json("accessor_out_of_range.gltf", gltf_doc(
        buf, [{"primitives": [{"attributes": {"POSITION": pos}}]}], [{"mesh": 0}],
        buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}]))

    # A buffer view that runs past the end of its buffer.
    buf = Buffer()
    pos = buf.vec3s(QUAD[:3])
    buf.views[0]["byteOffset"] = 4096
    write_json("view_out_of_range.gltf", gltf_doc(
        buf, [{"primitives": [{"attributes": {"POSITION": pos}}]}], [{"mesh": 0}],
        buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}]))

    # An index that names a vertex that does not exist.
    buf = Buffer()
    pos = buf.vec3s(QUAD[:3])
    idx = buf.indices([0, 1, 7], USHORT)
    write_json("index_out_of_range.gltf", gltf_doc(
        buf, [{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}], [{"mesh": 0}],
        buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}]))

    # A NaN coordinate.
    buf = Buffer()
    payload = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, float("nan"), 0)
    pos = buf.accessor(buf.view(payload), FLOAT, 3, "VEC3")
    write_json("nan_position.gltf", gltf_doc(
        buf, [{"primitives": [{"attributes": {"POSITION": pos}}]}], [{"mesh": 0}],
        buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}]))

    # A node that is its own grandchild.
    buf = Buffer()
    pos = buf.vec3s(QUAD[:3])
    write_json("node_cycle.gltf", gltf_doc(
        buf, [{"primitives": [{"attributes": {"POSITION": pos}}]}],
        [{"mesh": 0, "children": [1]}, {"children": [0]}],
        buffers=[{"uri": data_uri(buf.data), "byteLength": len(buf.data)}]))

    # Not JSON at all.
    with open(os.path.join(HERE, "syntax_error.gltf"), "w") as f:
        f.write('{"asset": {"version": "2.0"},\n "nodes": [ }\n')


if __name__ == "__main__":
    quad_external()
    embedded()
    cube_glb()
    hierarchy()
    broken()
