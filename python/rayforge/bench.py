"""python3 -m rayforge.bench: the Python module's throughput against the
C++ API and Embree, in one run, on the same mesh, rays and points.

Rows (each the median of --reps runs, --threads threads):
  cast_rays        RaycastingScene.cast_rays (the five outputs) | World::intersect + the same five arrays in C++ | Embree rtcIntersect1
  test_occlusions  RaycastingScene.test_occlusions              | World::occluded                                | Embree rtcOccluded1
  closest_points   RaycastingScene.compute_closest_points       | MeshQueries::closest_points                    | -
  signed_distance  RaycastingScene.compute_signed_distance      | closest_points + winding_numbers               | -
over two sets each: coherent (primary rays of a 1000x1000 pinhole camera;
points on a grid over the mesh's middle slice) and incoherent (one
cosine-weighted bounce from the primary hits; points uniform in the box
enlarged by 10 %), plus the build times. The C++ rows start from rays and
points already in the engine's layout; the Python rows time the whole call
(argument checks, conversion, outputs). Before printing, the rows are
checked to agree (Python and C++ hits bit for bit, distances within 1e-5
relative; Embree's hits within 1e-4 on at least the printed share).

The C++ and Embree rows need rayforge._rayforge_bench, built in the CMake
build tree (with Embree found) and not installed; without it only the
Python rows are printed. Results: docs/benchmarks.md.
"""

import argparse
import json
import os
import pathlib
import statistics
import sys
import time

import numpy as np

import rayforge

DRAGON = pathlib.Path("scenes/stanford-dragon/dragon_vrip.ply")


def find_default_mesh():
    """The Stanford Dragon under $RAYFORGE_SHARED or a shared/ folder next to or above the working directory."""
    roots = [pathlib.Path(os.environ["RAYFORGE_SHARED"])] if "RAYFORGE_SHARED" in os.environ else []
    here = pathlib.Path.cwd().resolve()
    for folder in [here, *here.parents]:
        roots += [folder / "shared", folder.parent / "shared"]
    for root in roots:
        if (root / DRAGON).is_file():
            return str(root / DRAGON)
    return None


def primary_rays(vertices, count):
    """A square pinhole camera's rays (count rounded to a square), looking at the mesh's box centre."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre, diagonal = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    eye = centre + np.array([0.35, 0.25, 1.0]) / np.linalg.norm([0.35, 0.25, 1.0]) * 1.3 * diagonal
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    side = int(round(np.sqrt(count)))
    s = np.tan(np.radians(40.0) / 2) * ((np.arange(side) + 0.5) / side * 2 - 1)
    sx, sy = np.meshgrid(s, -s)
    directions = forward + sx[..., None] * right + sy[..., None] * up
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    origins = np.broadcast_to(eye, directions.shape)
    return np.concatenate([origins, directions], axis=-1).reshape(-1, 6).astype(np.float32)


def bounce_rays(scene, primary, rng):
    """One cosine-weighted bounce from each primary hit; rays that missed start at random points in the box."""
    hits = scene.cast_rays(primary)
    hit = np.isfinite(hits["t_hit"])
    normals = hits["primitive_normals"].astype(np.float64)
    incoming = primary[:, 3:6].astype(np.float64)
    flip = np.sum(normals * incoming, axis=1) > 0
    normals[flip] *= -1
    origins = primary[:, :3] + primary[:, 3:6] * np.where(hit, hits["t_hit"], 0)[:, None]
    lo, hi = primary[:, :3].min(axis=0), primary[:, :3].max(axis=0)
    origins[~hit] = rng.uniform(lo, hi, size=(int((~hit).sum()), 3))
    normals[~hit] = rng.normal(size=(int((~hit).sum()), 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # Cosine-weighted about the normal: a unit vector plus the normal, normalised.
    v = rng.normal(size=normals.shape)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    directions = normals + v
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = origins + 1e-4 * np.linalg.norm(hi - lo) * normals
    return np.concatenate([origins, directions], axis=1).astype(np.float32)


def slice_points(vertices, count):
    """A square grid over the box's middle slice (normal z), the box enlarged by 10 %."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    margin = 0.05 * (hi - lo)
    lo, hi = lo - margin, hi + margin
    side = int(round(np.sqrt(count)))
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], side), np.linspace(lo[1], hi[1], side))
    z = np.full_like(x, (lo[2] + hi[2]) / 2)
    return np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)


def uniform_points(vertices, count, rng):
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    margin = 0.05 * (hi - lo)
    return rng.uniform(lo - margin, hi + margin, size=(count, 3)).astype(np.float32)


def median_seconds(run, reps):
    """Median wall time of run() over reps runs and the last result; run returns its result."""
    times, result = [], None
    for _ in range(reps):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def median_reported(run, reps):
    """Median of the seconds run() reports itself (first of its (seconds, result) tuple) and the last result."""
    results = [run() for _ in range(reps)]
    return statistics.median(r[0] for r in results), results[-1][1]


def same_hits(a, b):
    """Python and C++ t values equal bit for bit (inf for misses)."""
    return np.array_equal(a, b)


def close_distances(a, b):
    """Distances equal up to the rounding of their last subtraction (1e-5 relative)."""
    return np.allclose(a, b, rtol=1e-5, atol=1e-7)


def close_hits(a, b):
    """The fraction of rays on which two engines agree: both miss, or both hit within 1e-4 relative."""
    both = np.isfinite(a) & np.isfinite(b)
    with np.errstate(invalid="ignore"):  # inf - inf on misses, masked out by `both`
        agree = (~np.isfinite(a) & ~np.isfinite(b)) | (both & (np.abs(a - b) <= 1e-4 * np.maximum(1.0, np.abs(b))))
    return float(agree.mean())


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python3 -m rayforge.bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--mesh", help="a mesh file or builtin:NAME (default: the Stanford Dragon from shared/)")
    parser.add_argument("--rays", type=int, default=1_000_000, help="rays per set (default 1M)")
    parser.add_argument("--points", type=int, default=100_000, help="query points per set (default 100K)")
    parser.add_argument("--threads", type=int, default=2, help="threads for every row (default 2)")
    parser.add_argument("--reps", type=int, default=3, help="runs per row; the median is reported (default 3)")
    parser.add_argument("--json", help="also write the results to this file")
    args = parser.parse_args(argv)
    if args.rays < 1 or args.points < 1 or args.threads < 1 or args.reps < 1:
        parser.error("--rays, --points, --threads and --reps must be positive")
    mesh = args.mesh or find_default_mesh()
    if mesh is None:
        parser.error("no --mesh given and no shared/scenes/stanford-dragon/dragon_vrip.ply found "
                     "(set RAYFORGE_SHARED to the shared folder)")
    try:
        from rayforge import _rayforge_bench as reference
    except ImportError:
        reference = None
        print("note: rayforge._rayforge_bench is not here (it is built in the CMake build tree only): "
              "Python rows only", file=sys.stderr)

    vertices, triangles = rayforge.load_mesh(mesh)
    print(f"mesh {mesh}: {len(triangles):,} triangles; {args.threads} threads, median of {args.reps}")
    rng = np.random.default_rng(2014)
    results = {"mesh": mesh, "triangles": int(len(triangles)), "threads": args.threads, "reps": args.reps,
               "rows": [], "builds": {}}

    scene = rayforge.RaycastingScene(nthreads=args.threads)
    start = time.perf_counter()
    scene.add_triangles(vertices, triangles)
    scene.test_occlusions(np.zeros((1, 6), np.float32))  # the world is built at the first query
    results["builds"]["python_world_ms"] = 1e3 * (time.perf_counter() - start)
    start = time.perf_counter()
    scene.compute_distance(np.zeros((1, 3), np.float32))  # and the mesh queries at the first point query
    results["builds"]["python_mesh_queries_ms"] = 1e3 * (time.perf_counter() - start)
    cpp = embree = None
    if reference is not None:
        cpp = reference.CppScene(vertices, triangles, args.threads)
        results["builds"]["cpp_world_ms"] = cpp.world_ms
        results["builds"]["cpp_mesh_queries_ms"] = cpp.queries_ms
        if reference.embree_available():
            embree = reference.EmbreeScene(vertices, triangles, args.threads, "medium")
            results["builds"]["embree_medium_ms"] = embree.build_ms
            results["embree"] = reference.embree_version()

    primary = primary_rays(vertices, args.rays)
    sets = {
        "rays": {"coherent": primary, "incoherent": bounce_rays(scene, primary, rng)},
        "points": {"coherent": slice_points(vertices, args.points),
                   "incoherent": uniform_points(vertices, args.points, rng)},
    }
    queries = [
        ("cast_rays", "rays", lambda a: scene.cast_rays(a)["t_hit"], "cast_rays", "intersect", same_hits),
        ("test_occlusions", "rays", scene.test_occlusions, "test_occlusions", "occluded", np.array_equal),
        ("closest_points", "points",
         lambda a: np.linalg.norm(scene.compute_closest_points(a)["points"] - a, axis=1).astype(np.float32),
         "closest_points", None, close_distances),
        ("signed_distance", "points", scene.compute_signed_distance, "signed_distance", None, close_distances),
    ]
    header = f"{'query':16} {'set':10} {'count':>9} {'python ms':>10} {'c++ ms':>9} {'overhead':>9} " \
             f"{'embree ms':>10} {'python M/s':>11}"
    print(header)
    print("-" * len(header))
    for name, kind, python_call, cpp_method, embree_method, agree in queries:
        for set_name, data in sets[kind].items():
            row = {"query": name, "set": set_name, "count": int(len(data))}
            python_s, python_result = median_seconds(lambda: python_call(data), args.reps)
            row["python_ms"] = 1e3 * python_s
            text = f"{name:16} {set_name:10} {len(data):9,} {row['python_ms']:10.1f} "
            if cpp is not None:
                cpp_s, cpp_result = median_reported(lambda: getattr(cpp, cpp_method)(data), args.reps)
                row["cpp_ms"] = 1e3 * cpp_s
                row["python_overhead"] = python_s / cpp_s - 1.0
                expected = cpp_result.astype(bool) if python_result.dtype == bool else cpp_result
                if not agree(python_result, expected):
                    sys.exit(f"rayforge.bench: the Python and C++ results of {name} ({set_name}) differ")
                text += f"{row['cpp_ms']:9.1f} {100 * row['python_overhead']:8.1f}% "
            else:
                text += f"{'-':>9} {'-':>9} "
            if embree is not None and embree_method is not None:
                embree_s, embree_result = median_reported(lambda: getattr(embree, embree_method)(data), args.reps)
                row["embree_ms"] = 1e3 * embree_s
                if embree_method == "intersect":
                    row["embree_agreement"] = close_hits(python_result, embree_result)
                else:
                    row["embree_agreement"] = float(np.mean(python_result == embree_result.astype(bool)))
                text += f"{row['embree_ms']:10.1f} "
            else:
                text += f"{'-':>10} "
            text += f"{len(data) / python_s * 1e-6:11.2f}"
            print(text)
            results["rows"].append(row)
    print("builds (ms): " + ", ".join(f"{k} {v:.0f}" for k, v in results["builds"].items()))
    agreements = [r["embree_agreement"] for r in results["rows"] if "embree_agreement" in r]
    if agreements:
        print(f"Embree {results.get('embree', '')} agrees on at least {100 * min(agreements):.3f} % of the rays")
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
