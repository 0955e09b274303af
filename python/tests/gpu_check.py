"""The Python module on a CUDA device, without pytest (scripts/gpu-run.sh's python step):
a CUDA RaycastingScene against the CPU's, the device batches through __cuda_array_interface__
and DLPack against the host batches, queries from four threads at once, and cast_rays_on_device
on 10M rays over the Stanford Dragon when shared/ has it (else a sphere), timed end to end.
Prints one line per check; exits 1 at the first failure."""

import sys
import threading
import time

import numpy as np

import rayforge


def check(condition, what):
    print(("ok    " if condition else "FAIL  ") + what, flush=True)
    if not condition:
        sys.exit(1)


def icosphere_soup(n=200000, seed=1):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1, 1, size=(n, 1, 3))
    vertices = (centres + rng.normal(scale=0.01, size=(n, 3, 3))).reshape(-1, 3).astype(np.float32)
    return vertices, np.arange(3 * n, dtype=np.uint32).reshape(-1, 3)


def engine_rays(rays6):
    out = np.empty((len(rays6), 8), np.float32)
    out[:, 0:3], out[:, 3], out[:, 4:7], out[:, 7] = rays6[:, 0:3], 0.0, rays6[:, 3:6], np.inf
    return out


def random_rays(rng, count, lo, hi):
    origins = rng.uniform(lo, hi, size=(count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return np.concatenate([origins, directions], axis=1).astype(np.float32)


def main():
    print(f"rayforge {rayforge.__version__}, devices {rayforge.devices()}")
    check(rayforge.cuda_backend_built() and "cuda:0" in rayforge.devices(), "a CUDA device is visible")
    try:
        vertices, triangles = rayforge.load_mesh("../shared/scenes/stanford-dragon/dragon_vrip.ply")
        mesh = "the Stanford Dragon"
    except rayforge.Error:
        vertices, triangles = icosphere_soup()
        mesh = "a 200K-triangle soup"
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    rng = np.random.default_rng(7)
    rays6 = random_rays(rng, 200000, lo, hi)

    gpu = rayforge.RaycastingScene(device="cuda")
    gpu.add_triangles(vertices, triangles)
    cpu = rayforge.RaycastingScene()
    cpu.add_triangles(vertices, triangles)
    a, b = gpu.cast_rays(rays6), cpu.cast_rays(rays6)
    same = np.isfinite(a["t_hit"]) == np.isfinite(b["t_hit"])
    both = np.isfinite(a["t_hit"]) & np.isfinite(b["t_hit"])
    close = np.abs(a["t_hit"][both] - b["t_hit"][both]) <= 1e-5 * np.maximum(1, np.abs(b["t_hit"][both]))
    check(same.mean() > 0.999 and close.mean() > 0.999, f"cast_rays on cuda:0 = the CPU's on {mesh} "
          f"(hit/miss {same.mean():.5f}, t {close.mean():.5f})")

    world = rayforge.make_world(vertices, triangles, device="cuda")
    expected = world.trace(rays6)
    rays = rayforge._DeviceBuffer(engine_rays(rays6))

    class DlpackOnly:
        def __init__(self, buffer):
            self.buffer = buffer

        def __dlpack__(self, stream=None):
            return self.buffer.__dlpack__(stream=stream)

        def __dlpack_device__(self):
            return self.buffer.__dlpack_device__()

    for name, wrap in (("__cuda_array_interface__", lambda x: x), ("DLPack", DlpackOnly)):
        hits = rayforge._DeviceBuffer(np.zeros((len(rays6), 4), np.float32))
        world.trace_on_device(wrap(rays), wrap(hits))
        out = hits.numpy()
        prim = out[:, 3].view(np.uint32)
        check(np.array_equal(prim, expected["triangle_ids"]), f"trace_on_device through {name} = trace")

    failures = []

    def worker(k):
        for _ in range(3):
            got = gpu.cast_rays(rays6)["t_hit"]
            if not np.array_equal(got, a["t_hit"]):
                failures.append(k)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    check(not failures, "four threads' cast_rays on one CUDA scene = one thread's")

    big = rayforge._DeviceBuffer(engine_rays(random_rays(rng, 10_000_000, lo, hi)))
    big_hits = rayforge._DeviceBuffer(np.zeros((10_000_000, 4), np.float32))
    gpu.cast_rays_on_device(big, big_hits)  # warm-up
    times = []
    for _ in range(5):
        start = time.perf_counter()
        gpu.cast_rays_on_device(big, big_hits)
        times.append(time.perf_counter() - start)
    median = sorted(times)[2]
    print(f"cast_rays_on_device: 10M random rays over {mesh}: {median * 1e3:.1f} ms, {10 / median:.0f} Mrays/s "
          "(median of 5, end to end from Python)")


if __name__ == "__main__":
    main()
