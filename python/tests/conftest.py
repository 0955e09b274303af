"""Shared meshes and numpy brute-force references for the rayforge tests.

Everything is checked against brute force written here in numpy (every ray
against every triangle, every point against every triangle); Debian's
python3-open3d is no oracle on these machines (its RaycastingScene misses a
ray straight at a triangle)."""

import numpy as np
import pytest

import rayforge


def icosphere(subdivisions=2, radius=1.0, center=(0.0, 0.0, 0.0)):
    """A closed sphere, triangles wound outwards."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
         (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
         (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    faces = list(f)
    for _ in range(subdivisions):
        cache = {}

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    vertices = (np.array(verts) * radius + np.array(center)).astype(np.float32)
    return vertices, np.array(faces, dtype=np.uint32)


def random_soup(rng, count=200, scale=1.0):
    """Unconnected random triangles in a cube."""
    centers = rng.uniform(-scale, scale, size=(count, 1, 3))
    vertices = (centers + rng.normal(scale=0.15 * scale, size=(count, 3, 3))).reshape(-1, 3).astype(np.float32)
    return vertices, np.arange(3 * count, dtype=np.uint32).reshape(-1, 3)


def random_rays(rng, count, scale=2.0):
    """Rays from points around the scene towards points inside it (unit directions)."""
    origins = rng.uniform(-scale, scale, size=(count, 3))
    targets = rng.uniform(-0.5 * scale, 0.5 * scale, size=(count, 3))
    d = targets - origins
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.concatenate([origins, d], axis=1).astype(np.float32)


def brute_force_hits(vertices, triangles, rays):
    """Every (ray, triangle) hit by Moller-Trumbore in float64: t (rays, tris) with inf for a miss, u, v."""
    v = vertices.astype(np.float64)[triangles.astype(np.int64)]
    o = rays[:, None, :3].astype(np.float64)
    d = rays[:, None, 3:].astype(np.float64)
    e1 = v[None, :, 1] - v[None, :, 0]
    e2 = v[None, :, 2] - v[None, :, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v[None, :, 0]
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        w = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
    hit = (np.abs(det) > 1e-12) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t >= 0)
    return np.where(hit, t, np.inf), u, w


def closest_point_on_triangles(points, tri):
    """Closest points of (n, 3) points on every triangle (tris, 3, 3), by projection onto the plane and the edges."""
    p = points[:, None, :]
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]

    def on_segment(x, y):
        d = y - x
        denom = np.maximum(np.sum(d * d, axis=-1, keepdims=True), 1e-30)
        s = np.clip(np.sum((p - x) * d, axis=-1, keepdims=True) / denom, 0.0, 1.0)
        return x + s * d

    n = np.cross(b - a, c - a)
    nn = np.maximum(np.sum(n * n, axis=-1, keepdims=True), 1e-30)
    proj = p - np.sum((p - a) * n, axis=-1, keepdims=True) / nn * n
    def inside_edge(x, y):
        return np.sum(np.cross(y - x, proj - x) * n, axis=-1) >= 0
    inside = inside_edge(a, b) & inside_edge(b, c) & inside_edge(c, a) & (nn[..., 0] > 1e-30)
    candidates = [on_segment(a, b), on_segment(b, c), on_segment(c, a)]
    best = candidates[0]
    best_d = np.sum((best - p) ** 2, axis=-1)
    for cand in candidates[1:]:
        d = np.sum((cand - p) ** 2, axis=-1)
        take = d < best_d
        best = np.where(take[..., None], cand, best)
        best_d = np.minimum(d, best_d)
    proj_d = np.sum((proj - p) ** 2, axis=-1)
    use_proj = inside & (proj_d <= best_d)
    return np.where(use_proj[..., None], proj, best)


def brute_force_distance(vertices, triangles, points):
    tri = vertices.astype(np.float64)[triangles.astype(np.int64)]
    cp = closest_point_on_triangles(points.astype(np.float64), tri)
    d = np.linalg.norm(cp - points[:, None, :].astype(np.float64), axis=-1)
    return d.min(axis=1), d.argmin(axis=1)


@pytest.fixture
def rng():
    return np.random.default_rng(7)


@pytest.fixture
def sphere_scene():
    vertices, triangles = icosphere(2)
    scene = rayforge.RaycastingScene(nthreads=2)
    scene.add_triangles(vertices, triangles)
    return scene, vertices, triangles
