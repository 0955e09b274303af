#!/usr/bin/env python3
"""Writes a tessellated, gently displaced grid of about N triangles as binary
PLY (little endian, with normals) and as OBJ (v/vt/vn), for load-time
measurements: `python3 scripts/make-grid-mesh.py 1000000 /tmp/grid`
writes /tmp/grid.ply and /tmp/grid.obj. Deterministic; stdlib only."""
import math
import struct
import sys


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: make-grid-mesh.py TRIANGLES OUTPUT_PREFIX")
    target = int(sys.argv[1])
    prefix = sys.argv[2]
    n = max(1, int(math.sqrt(target / 2)))  # n x n quads, 2 triangles each
    verts = []
    for j in range(n + 1):
        for i in range(n + 1):
            x, z = i / n, j / n
            y = 0.05 * math.sin(12 * x) * math.cos(9 * z)
            verts.append((x, y, z, i / n, j / n))
    faces = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c, d = a + 1, a + n + 1, a + n + 2
            faces.append((a, c, b))
            faces.append((b, c, d))

    with open(prefix + ".ply", "wb") as f:
        header = ("ply\nformat binary_little_endian 1.0\n"
                  f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
                  "property float nx\nproperty float ny\nproperty float nz\n"
                  f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
        f.write(header.encode())
        vbuf = bytearray()
        for x, y, z, _, _ in verts:
            vbuf += struct.pack("<6f", x, y, z, 0.0, 1.0, 0.0)
        f.write(vbuf)
        fbuf = bytearray()
        for a, b, c in faces:
            fbuf += struct.pack("<B3i", 3, a, b, c)
        f.write(fbuf)

    with open(prefix + ".obj", "w") as f:
        lines = [f"# {len(faces)} triangles\n"]
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z, _, _ in verts]
        lines += [f"vt {u:.6f} {v:.6f}\n" for _, _, _, u, v in verts]
        lines.append("vn 0 1 0\n")
        lines += [f"f {a+1}/{a+1}/1 {b+1}/{b+1}/1 {c+1}/{c+1}/1\n" for a, b, c in faces]
        f.writelines(lines)
    print(f"{prefix}.ply, {prefix}.obj: {len(faces)} triangles, {len(verts)} vertices")


if __name__ == "__main__":
    main()
