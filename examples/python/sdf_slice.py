"""A signed-distance slice through a sphere with a hole: the robust sign
(generalised winding number) against Open3D's parity rule, plotted with
matplotlib (or written with rayforge.write_image when matplotlib is missing).

    python3 examples/python/sdf_slice.py [-o sdf_slice.png] [--resolution 200]
"""
import argparse

import numpy as np

import rayforge


def icosphere(subdivisions):
    """A unit icosphere: (vertices float32, triangles uint32), outward-wound."""
    t = (1.0 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
         [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    vertices = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdivisions):
        cache, faces = {}, []

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = vertices[a] + vertices[b]
                vertices.append(m / np.linalg.norm(m))
                cache[key] = len(vertices) - 1
            return cache[key]

        for a, b, c in f:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = faces
    return np.array(vertices, np.float32), np.array(f, np.uint32)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default="sdf_slice.png")
    parser.add_argument("--resolution", type=int, default=200)
    args = parser.parse_args()

    vertices, triangles = icosphere(4)
    centres = vertices[triangles].mean(axis=1)
    holed = triangles[centres[:, 2] < 0.85]  # a cap cut off at +z: the mesh is open
    scene = rayforge.RaycastingScene()
    scene.add_triangles(vertices, holed)

    n = args.resolution
    # A slice at y = 0.05 through the hole: x to the right, z up.
    x, y = np.meshgrid(np.linspace(-1.5, 1.5, n), np.linspace(1.5, -1.5, n))
    points = np.stack([x, np.full_like(x, 0.05), y], axis=-1).astype(np.float32)  # (n, n, 3)
    winding = scene.compute_signed_distance(points)                      # (n, n)
    parity = scene.compute_signed_distance(points, sign="parity", nsamples=1)
    # Inside the sphere below the opening (z < 0.5) every point is inside; parity's
    # first ray points almost along +z and leaves through the hole for many of them.
    inside = (np.hypot(x, y) < 0.95) & (y < 0.5)
    print(f"inside, below the opening: the winding sign calls {np.mean(winding[inside] < 0):.1%} of points inside, "
          f"the parity sign {np.mean(parity[inside] < 0):.1%}")

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        plt = None
    if plt is not None:
        figure, axes = plt.subplots(1, 2, figsize=(10, 4.6))
        limit = float(np.abs(winding).max())
        for ax, field, title in ((axes[0], winding, "winding number sign"), (axes[1], parity, "parity sign (Open3D)")):
            image = ax.imshow(field, extent=(-1.5, 1.5, -1.5, 1.5), cmap="RdBu", vmin=-limit, vmax=limit)
            ax.contour(x, y, field, levels=[0.0], colors="k", linewidths=0.8)
            ax.set_title(title)
        figure.colorbar(image, ax=axes, shrink=0.8, label="signed distance")
        figure.savefig(args.output, dpi=100)
    else:
        def colour(field):
            s = np.clip(field / np.abs(field).max(), -1, 1)[..., None]
            return np.where(s < 0, [1.0, 0.3, 0.2] * -s, [0.2, 0.4, 1.0] * s).astype(np.float32)
        rayforge.write_image(args.output, np.concatenate([colour(winding), colour(parity)], axis=1))
    print(f"wrote {args.output}" + ("" if plt else " (matplotlib not installed: a plain image)"))


if __name__ == "__main__":
    main()
