#!/usr/bin/env python3
"""Writes the generated seeds of the fuzz corpora (python3 stdlib only).

Run from anywhere: python3 tests/fuzz/make_seeds.py
The other seeds are copies of tests/data fixtures. The fuzz harnesses
(fuzz/fuzz_*.cpp) put t.ppm, buf.bin, m.obj and m.ply next to the input, so
the seeds below reference them. texture/seed.jpg was written by
stb_image_write (stbi_write_jpg, 8x8 gradient, quality 90); JPEG cannot be
encoded with the standard library, so it is committed as is.
"""
import json
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


def write(path, data):
    full = os.path.join(HERE, path)
    os.makedirs(os.path.dirname(full), exist_ok=True)
    with open(full, "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


# --- textures: one small image per stb_image format ---------------------------
W, H = 4, 3
RGB = b"".join(bytes((x * 60, y * 80, (x + y) * 30)) for y in range(H) for x in range(W))


def bmp24():
    row = (W * 3 + 3) & ~3
    pixels = b"".join(
        b"".join(bytes(reversed(RGB[(y * W + x) * 3:(y * W + x) * 3 + 3])) for x in range(W)).ljust(row, b"\0")
        for y in reversed(range(H)))
    header = struct.pack("<2sIHHI", b"BM", 54 + len(pixels), 0, 0, 54)
    info = struct.pack("<IiiHHIIiiII", 40, W, H, 1, 24, 0, len(pixels), 2835, 2835, 0, 0)
    return header + info + pixels


def bmp8_palette():
    row = (W + 3) & ~3
    palette = b"".join(bytes((i * 16, i * 8, 255 - i * 16, 0)) for i in range(16))
    pixels = b"".join(bytes((x + y * W) % 16 for x in range(W)).ljust(row, b"\0") for y in range(H))
    offset = 54 + len(palette)
    header = struct.pack("<2sIHHI", b"BM", offset + len(pixels), 0, 0, offset)
    info = struct.pack("<IiiHHIIiiII", 40, W, H, 1, 8, 0, len(pixels), 2835, 2835, 16, 0)
    return header + info + palette + pixels


def tga_rle():
    header = struct.pack("<BBBHHBHHHHBB", 0, 0, 10, 0, 0, 0, 0, 0, W, H, 24, 0x20)
    body = bytes([0x80 | (W - 1), 10, 20, 30]) * H  # one run per row
    return header + body


def hdr_flat():
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (H, W)
    return header + bytes((128, 64, 32, 129)) * (W * H)


write("texture/seed24.bmp", bmp24())
write("texture/seed8.bmp", bmp8_palette())
write("texture/seed.pgm", b"P5\n%d %d\n255\n" % (W, H) + bytes(range(0, W * H * 20, 20)))
write("texture/seed_ascii.ppm", "P3\n2 1\n255\n255 0 0 0 255 0\n")
write("texture/seed_rle.tga", tga_rle())
write("texture/seed_flat.hdr", hdr_flat())

# --- MTL: every statement the loader maps, textures that exist (t.ppm) ----------
write("mtl/all_statements.mtl", """newmtl full
Ka 0.1 0.1 0.1
Kd 0.5 0.4 0.3
Ks 0.9 0.9 0.9
Ke 1 1 1
Ns 250
Ni 1.5
d 0.5
Tr 0.5
illum 5
map_Kd t.ppm
map_Ks t.ppm
map_Ke t.ppm
map_d t.ppm
map_bump -bm 0.5 t.ppm
norm t.ppm
bump t.ppm
newmtl glass
Kd 1 1 1
illum 7
Ni 1.33
newmtl pbr
Pr 0.5
Pm 1
Ps 0.2
Pc 0.3
Pcr 0.1
aniso 0.5
anisor 0.2
map_Pr t.ppm
map_Pm t.ppm
""")

# --- OBJ: material library and texture next to the input -------------------------
write("obj/with_mtllib.obj", "mtllib input.obj\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
                             "f 1/1/1 2/1/1 3/1/1\ng group\ns 1\no object\nf -3 -2 -1\nl 1 2\np 1\n")

# --- glTF: external buffer and image that exist in the harness's directory -------
quad = {
    "asset": {"version": "2.0"},
    "buffers": [{"uri": "buf.bin", "byteLength": 60}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                    {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                  {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    "images": [{"uri": "t.ppm"}],
    "samplers": [{"wrapS": 33071, "wrapT": 33648}],
    "textures": [{"source": 0, "sampler": 0}],
    "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.5},
                   "normalTexture": {"index": 0}, "emissiveTexture": {"index": 0},
                   "alphaMode": "MASK",
                   "extensions": {"KHR_materials_ior": {"ior": 1.4},
                                  "KHR_materials_transmission": {"transmissionFactor": 0.5}}}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0},
                               {"attributes": {"POSITION": 0}, "mode": 5},
                               {"attributes": {"POSITION": 0}, "mode": 6}]}],
    "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
    "extensions": {"KHR_lights_punctual": {"lights": [{"type": "spot", "spot": {}}]}},
    "nodes": [{"mesh": 0, "children": [1, 2]},
              {"camera": 0, "translation": [0, 0, 5], "rotation": [0, 0, 0, 1], "scale": [1, 1, 1]},
              {"extensions": {"KHR_lights_punctual": {"light": 0}},
               "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 3, 0, 1]}],
    "scenes": [{"nodes": [0]}],
    "scene": 0,
}
write("gltf/external_files.gltf", json.dumps(quad, indent=1))

# GLB: the same quad with the buffer in the BIN chunk.
glb_json = dict(quad)
glb_json["buffers"] = [{"byteLength": 60}]
glb_json.pop("images"), glb_json.pop("textures"), glb_json.pop("samplers")
glb_json["materials"] = [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1]}}]
positions = struct.pack("<12f", 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0)
indices = struct.pack("<6H", 0, 1, 2, 0, 2, 3)
chunk_json = json.dumps(glb_json, separators=(",", ":")).encode()
chunk_json += b" " * (-len(chunk_json) % 4)
chunk_bin = positions + indices
chunk_bin += b"\0" * (-len(chunk_bin) % 4)
glb = (struct.pack("<II", len(chunk_json), 0x4E4F534A) + chunk_json +
       struct.pack("<II", len(chunk_bin), 0x004E4942) + chunk_bin)
write("glb/quad.glb", struct.pack("<4sII", b"glTF", 2, 12 + len(glb)) + glb)

# --- JSON scenes referencing the harness's files and every section ----------------
write("json_scene/references.json", json.dumps({
    "materials": {"red": {"base_color": [0.8, 0.1, 0.1], "roughness": 0.5, "metallic": 0.2,
                          "base_color_texture": "t.ppm"},
                  "lamp": {"emission": [1, 1, 1], "emission_strength": 10}},
    "meshes": [{"file": "m.obj", "material": "red", "transform": {"translate": [0, 0, 1], "scale": 2}},
               {"file": "m.ply", "transform": {"rotate": {"axis": [0, 1, 0], "degrees": 45}}},
               {"file": "builtin:cornell"},
               {"file": "m.obj", "material": "lamp"}],
    "camera": {"eye": [0, 2, 20], "target": [0, 1, 0], "up": [0, 1, 0], "fov": 35},
    "lights": [{"type": "point", "position": [0, 8, 0], "intensity": 50}],
    "environment": {"color": [0.1, 0.2, 0.3], "map": "t.ppm", "strength": 2, "rotation_deg": 30},
    "render": {"width": 32, "height": 24, "spp": 1, "integrator": "ao", "max_depth": 2, "ao_radius": 0.5},
}, indent=1))

# --- animations (Scene::set_time after loading) -------------------------------------
# GLB: the glTF animation fixture (skin, morph targets, TRS channels) with its
# buffer in the BIN chunk.
import base64

ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
with open(os.path.join(ROOT, "tests/data/gltf_anim/anim_basic.gltf")) as f:
    anim = json.load(f)
anim_bin = base64.b64decode(anim["buffers"][0]["uri"].split(",", 1)[1])
anim["buffers"] = [{"byteLength": len(anim_bin)}]
chunk_json = json.dumps(anim, separators=(",", ":")).encode()
chunk_json += b" " * (-len(chunk_json) % 4)
anim_bin += b"\0" * (-len(anim_bin) % 4)
glb = (struct.pack("<II", len(chunk_json), 0x4E4F534A) + chunk_json +
       struct.pack("<II", len(anim_bin), 0x004E4942) + anim_bin)
write("glb/animation_skin_morph.glb", struct.pack("<4sII", b"glTF", 2, 12 + len(glb)) + glb)


def gltf_interpolations():
    """A quad on a node with CUBICSPLINE translation, STEP rotation, LINEAR scale and weights."""
    times = struct.pack("<3f", 0, 1, 2)
    cubic = struct.pack("<27f", *([0, 0, 0, 0, 0, 0, 1, 0, 0] + [1, 0, 0, 2, 1, 0, 0, 1, 0] + [0, 0, 0, 3, 0, 0, 0, 0, 0]))
    rot = struct.pack("<12f", 0, 0, 0, 1, 0, 0.7071068, 0, 0.7071068, 0, 1, 0, 0)
    scale = struct.pack("<9f", 1, 1, 1, 2, 2, 2, 1, 1, 1)
    weights = struct.pack("<3f", 0, 1, 0.5)
    pos = struct.pack("<12f", 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0)
    delta = struct.pack("<12f", 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1)
    idx = struct.pack("<6H", 0, 1, 2, 0, 2, 3) + b"\0\0"
    parts = [times, cubic, rot, scale, weights, pos, delta, idx]
    views, offset = [], 0
    for p in parts:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(p)})
        offset += len(p)
    views[-1]["byteLength"] = 12
    data = b"".join(parts)
    acc = [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "SCALAR", "min": [0], "max": [2]},
           {"bufferView": 1, "componentType": 5126, "count": 9, "type": "VEC3"},
           {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"},
           {"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3"},
           {"bufferView": 4, "componentType": 5126, "count": 3, "type": "SCALAR"},
           {"bufferView": 5, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
           {"bufferView": 6, "componentType": 5126, "count": 4, "type": "VEC3"},
           {"bufferView": 7, "componentType": 5123, "count": 6, "type": "SCALAR"}]
    return {
        "asset": {"version": "2.0"},
        "buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode(),
                     "byteLength": len(data)}],
        "bufferViews": views, "accessors": acc,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 5}, "indices": 7, "targets": [{"POSITION": 6}]}],
                    "weights": [0.25]}],
        "nodes": [{"name": "parent", "children": [1]}, {"name": "quad", "mesh": 0}],
        "scenes": [{"nodes": [0]}], "scene": 0,
        "animations": [{"samplers": [{"input": 0, "output": 1, "interpolation": "CUBICSPLINE"},
                                     {"input": 0, "output": 2, "interpolation": "STEP"},
                                     {"input": 0, "output": 3, "interpolation": "LINEAR"},
                                     {"input": 0, "output": 4}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                                     {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
                                     {"sampler": 2, "target": {"node": 1, "path": "scale"}},
                                     {"sampler": 3, "target": {"node": 1, "path": "weights"}}]}],
    }


write("gltf/animation_interpolations.gltf", json.dumps(gltf_interpolations(), indent=1))

# JSON: step keys on a referenced file, linear keys with every rotation form, a mesh without keys.
write("json_scene/animation_step_and_files.json", json.dumps({
    "meshes": [{"file": "m.obj", "animation": {"interpolation": "step", "keys": [
                   {"time": 0, "translate": [0, 0, 0]}, {"time": 0.5, "translate": [0, 1, 0]},
                   {"time": 3, "translate": [0, 2, 0], "scale": [1, 1, 2]}]}},
               {"file": "m.ply", "transform": {"translate": [2, 0, 0]}, "animation": {"keys": [
                   {"time": -1, "rotate": {"axis": [1, 0, 0], "degrees": -90}},
                   {"time": 1, "rotate": {"quaternion": [0, 0, 0, 1]}, "scale": 0.5},
                   {"time": 4, "rotate": {"axis": [0, 0, 1], "degrees": 720}, "scale": 3}]}},
               {"file": "builtin:triangle"}],
}, indent=1))

# AFF: nested animated blocks, rot/scale/visibility keys with tension/continuity/bias,
# a tpa mesh with three keys, a camera on transl keys only.
write("aff/animation_nested.aff", """% nested animated blocks, tcb keys, tpa, camera path
a 0 4 41
v
from 0 0 10
at 0 0 0
up 0 1 0
angle 40
hither 0.1
resolution 16 16
x outer
{
  xs 1 1 1  0 0 1 0  1 0 0
  {
    x inner
    {
      p 3
      0 0 0
      1 0 0
      0 1 0
    }
  }
  tpa 3
    0
    0 0 0  0 0 1
    1 0 0  0 0 1
    0 1 0  0 0 1
    1
    0 0 1  0 0 1
    1 0 1  0 0 1
    0 1 1  0 1 0
    4
    0 0 2  0 0 1
    2 0 2  0 0 1
    0 2 2  0 0 0
}
k outer
{
  rot 5
  0 0 0 1 0     0 0 0
  1 0 0 1 90    0.5 0 0
  2 0 0 1 180   0 0.5 0
  3 0 0 1 270   0 0 0.5
  4 0 0 1 360   0 0 0
  scale 4
  0 1 1 1  0 0 0
  1 2 1 1  -1 0 0
  2 1 2 1  0 -1 0
  3 1 1 2  0 0 -1
  visibility 3
  0 1
  1 0
  2 1
}
k inner
{
  transl 4
  0 0 0 0  0 0 0
  0 0 0 0  0 0 0
  2 1 1 1  0 0 0
  1 2 2 2  0 0 0
}
k camera
{
  transl 4
  0 0 0 10  0 0 0
  1 0 0 12  0 0 0
  2 0 0 14  0 0 0
  3 0 0 16  0 0 0
}
""")


def gltf_with_accessors(accessors, extra):
    """A glTF with one data-URI buffer holding `accessors` ((struct format, values, accessor fields) each)."""
    data, views, accs = b"", [], []
    for fmt, values, fields in accessors:
        chunk = struct.pack("<%d%s" % (len(values), fmt), *values)
        chunk += b"\0" * (-len(chunk) % 4)
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(chunk)})
        accs.append(dict(fields, bufferView=len(views) - 1))
        data += chunk
    g = {"asset": {"version": "2.0"},
         "buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode(),
                      "byteLength": len(data)}],
         "bufferViews": views, "accessors": accs}
    g.update(extra)
    return g


F32 = 5126
ANIM_ACCESSORS = [
    ("f", [0, 0, 0, 1, 0, 0, 0, 1, 0], {"componentType": F32, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}),
    ("f", [0, 1], {"componentType": F32, "count": 2, "type": "SCALAR", "min": [0], "max": [1]}),
    ("H", [0, 1, 0, 0] * 3, {"componentType": 5123, "count": 3, "type": "VEC4"}),
    ("f", [0.5, 0.5, 0, 0] * 3, {"componentType": F32, "count": 3, "type": "VEC4"}),
    ("f", [0, 0, 1] * 3, {"componentType": F32, "count": 3, "type": "VEC3"}),
    ("f", [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1] * 2, {"componentType": F32, "count": 2, "type": "MAT4"}),
    ("f", [0, 0, 1, 0.5, 0, 0, 0, 0, 0.2, 1, 0, 0], {"componentType": F32, "count": 12, "type": "SCALAR"}),
    ("f", [0, 0, 0, 1, 0, 1, 0, 0], {"componentType": F32, "count": 2, "type": "VEC4"}),
]
# A mesh both skinned and morphed (cubic-spline weights), also used by a plain
# node; the skin's joints are the skinned node itself and a node outside the scene.
write("gltf/animation_skin_morph_shared_mesh.gltf", json.dumps(gltf_with_accessors(ANIM_ACCESSORS, {
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3},
                                "targets": [{"POSITION": 4}, {"POSITION": 4}]}]}],
    "skins": [{"joints": [1, 3], "inverseBindMatrices": 5}],
    "nodes": [{"children": [1, 2]}, {"mesh": 0, "skin": 0}, {"mesh": 0, "translation": [2, 0, 0]}, {"name": "outside"}],
    "scenes": [{"nodes": [0]}], "scene": 0,
    "animations": [{"samplers": [{"input": 1, "output": 6, "interpolation": "CUBICSPLINE"}, {"input": 1, "output": 7}],
                    "channels": [{"sampler": 0, "target": {"node": 1, "path": "weights"}},
                                 {"sampler": 1, "target": {"node": 3, "path": "rotation"}},
                                 {"sampler": 0, "target": {"node": 2, "path": "weights"}}]}]})))
# An animated node shared by two parents (glTF forbids it; the loader must stay consistent).
write("gltf/animation_shared_node.gltf", json.dumps(gltf_with_accessors(ANIM_ACCESSORS, {
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
    "nodes": [{"children": [2], "translation": [5, 0, 0]}, {"children": [2], "translation": [-5, 0, 0]}, {"mesh": 0}],
    "scenes": [{"nodes": [0, 1]}], "scene": 0,
    "animations": [{"samplers": [{"input": 1, "output": 7, "interpolation": "STEP"}],
                    "channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}]}]})))
