"""Ray casting with rayforge.RaycastingScene: a pinhole camera's rays at a mesh,
a depth image and a normal image written as PNG.

    python3 examples/python/raycast.py [MESH] [-o depth.png]

MESH is a mesh file or builtin:NAME (default builtin:bunny-like spheres: builtin:spheres).
"""
import argparse

import numpy as np

import rayforge


def pinhole_rays(eye, target, fov_degrees, width, height):
    """(height, width, 6) rays of a pinhole camera, as Open3D's create_rays_pinhole makes them."""
    eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(fov_degrees) / 2)
    x = ((np.arange(width) + 0.5) / width * 2 - 1) * half * width / height
    y = (1 - (np.arange(height) + 0.5) / height * 2) * half
    sx, sy = np.meshgrid(x, y)
    directions = forward + sx[..., None] * right + sy[..., None] * up
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    origins = np.broadcast_to(eye, directions.shape)
    return np.concatenate([origins, directions], axis=-1).astype(np.float32)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", nargs="?", default="builtin:spheres")
    parser.add_argument("-o", "--output", default="depth.png")
    parser.add_argument("--size", default="320x240")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))

    vertices, triangles = rayforge.load_mesh(args.mesh)
    scene = rayforge.RaycastingScene()
    scene.add_triangles(vertices, triangles)

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre, diagonal = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    eye = centre + np.array([0.4, 0.5, 1.0]) * diagonal * 0.8
    rays = pinhole_rays(eye, centre, 45.0, width, height)
    hits = scene.cast_rays(rays)  # (height, width) outputs: the rays' leading shape is kept

    t = hits["t_hit"]
    hit = np.isfinite(t)
    print(f"{args.mesh}: {len(triangles)} triangles, {hit.sum()} of {hit.size} rays hit")
    depth = np.zeros_like(t)
    if hit.any():
        near, far = t[hit].min(), t[hit].max()
        depth[hit] = 1.0 - 0.8 * (t[hit] - near) / max(far - near, 1e-6)
    rayforge.write_image(args.output, np.repeat(depth[..., None], 3, axis=2))
    normals = 0.5 * (hits["primitive_normals"] + 1.0) * hit[..., None]
    rayforge.write_image(args.output.replace(".png", "_normals.png"), normals.astype(np.float32))
    print(f"wrote {args.output} and {args.output.replace('.png', '_normals.png')} ({width}x{height})")


if __name__ == "__main__":
    main()
