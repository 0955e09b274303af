#!/usr/bin/env python3
"""Writes the OBJ/MTL fixtures for obj_loader_test.cpp (python3 stdlib only).

Run from anywhere: python3 tests/data/obj/make_fixtures.py
The texture names in cube.mtl use a Windows separator and the wrong letter
case on purpose (as Crytek and Dabrovic Sponza do).
"""
import os
import sys

sys.dont_write_bytecode = True  # keep tests/data free of __pycache__

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "textures"))
from make_fixtures import png_bytes  # noqa: E402


def write(name, text):
    with open(os.path.join(HERE, name), "w", newline="\n") as f:
        f.write(text)


def main():
    # A unit quad in z = 0, no normals, no material: 2 triangles, normals computed (+z).
    write("quad.obj", """# unit quad
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
f 1 2 3 4
""")

    # Unit cube centred at the origin: 8 positions, 4 uvs, 6 normals, 6 quads.
    # Faces 1-4 use 'checker' (textured, alpha-masked), faces 5-6 'lamp' (emissive).
    write("cube.obj", """mtllib cube.mtl
o cube
v -0.5 -0.5 -0.5
v  0.5 -0.5 -0.5
v  0.5  0.5 -0.5
v -0.5  0.5 -0.5
v -0.5 -0.5  0.5
v  0.5 -0.5  0.5
v  0.5  0.5  0.5
v -0.5  0.5  0.5
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 -1
vn 0 0 1
vn -1 0 0
vn 1 0 0
vn 0 -1 0
vn 0 1 0
usemtl checker
f 4/1/1 3/2/1 2/3/1 1/4/1
f 5/1/2 6/2/2 7/3/2 8/4/2
f 1/1/3 5/2/3 8/3/3 4/4/3
f 2/1/4 3/2/4 7/3/4 6/4/4
usemtl lamp
f 1/1/5 2/2/5 6/3/5 5/4/5
f 4/1/6 8/2/6 7/3/6 3/4/6
""")
    write("cube.mtl", """# Windows separators and wrong case, like the Sponza exports
newmtl checker
Kd 0.588 0.588 0.588
Ks 0 0 0
Ns 10
map_Kd textures\\Checker.PNG
map_d textures\\mask.png

newmtl lamp
Kd 0.1 0.1 0.1
Ke 4 3 2
""")
    # 2x2 RGB checker and a 2x2 gray mask (opaque left column, transparent right column).
    with open(os.path.join(HERE, "textures", "checker.png"), "wb") as f:
        f.write(png_bytes(2, 2, 3, [255, 255, 255, 0, 0, 0, 0, 0, 0, 255, 255, 255]))
    with open(os.path.join(HERE, "textures", "mask.png"), "wb") as f:
        f.write(png_bytes(2, 2, 1, [255, 0, 255, 0]))

    # Materials mapped by the MTL heuristics (one triangle each).
    write("materials.obj", """mtllib materials.mtl
v 0 0 0
v 1 0 0
v 0 1 0
usemtl mirror
f 1 2 3
usemtl glass
f 1 2 3
usemtl veil
f 1 2 3
usemtl plastic
f 1 2 3
usemtl undefined_in_mtl
f 1 2 3
""")
    write("materials.mtl", """newmtl mirror
Kd 0.01 0.01 0.01
Ks 0.95 0.9 0.85
Ns 1000
illum 5

newmtl glass
Kd 0.01 0.01 0.01
Ks 0.3 0.3 0.3
Ns 200
Ni 1.33
illum 7

newmtl veil
Kd 0.2 0.4 0.6
d 0.25
illum 2

newmtl plastic
Kd 0.5 0.25 0.125
Ks 0.5 0.5 0.5
Ns 98
illum 2
""")

    # Negative (relative) indices, v//vn corners, and faces before any usemtl.
    write("negative_indices.obj", """v 0 0 0
v 1 0 0
v 1 1 0
vn 0 0 1
f -3//-1 -2//-1 -1//-1
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
f -4 -3 -2 -1
""")

    # A hexagon (4 triangles) and a pentagon (3), with CRLF line endings and tabs.
    write("polygon.obj", "v 0 0 0\r\nv 2 0 0\r\nv 3 1 0\r\nv 2 2 0\r\nv 0 2 0\r\nv -1 1 0\r\n"
          "f\t1 2 3 4 5 6\r\nf 1 2 3 4 5\r\n")

    # A texture that is not there: a warning, the material keeps its factor.
    write("missing_texture.obj", "mtllib missing_texture.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
          "vt 0 0\nvt 1 0\nvt 0 1\nusemtl ghost\nf 1/1 2/2 3/3\n")
    write("missing_texture.mtl", "newmtl ghost\nKd 0.25 0.5 0.75\nmap_Kd does_not_exist.png\n")

    # Malformed files: each must fail with the file name and line.
    write("out_of_range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n# comment\nf 1 2 9\n")
    write("negative_out_of_range.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\n")
    write("zero_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    write("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    write("bad_number.obj", "v 0 0 0\nv 1 0 0\nv 0 1x 0\nf 1 2 3\n")
    write("bad_face.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 three\n")
    write("uv_out_of_range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n")
    write("no_faces.obj", "v 0 0 0\nv 1 0 0\n")


if __name__ == "__main__":
    main()
