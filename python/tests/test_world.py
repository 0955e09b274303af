"""rayforge.World (open_world, make_world), its queries against numpy brute
force and against the CLI, animation and moved vertices, and build_bvh's
canonical tree checked node by node."""

import json
import os
import subprocess
import threading

import numpy as np
import pytest

import rayforge
from conftest import brute_force_hits, icosphere, random_rays, random_soup


def closest_of(vertices, triangles, rays):
    t, u, v = brute_force_hits(vertices, triangles, rays)
    best = t.argmin(axis=1)
    rows = np.arange(len(rays))
    return t[rows, best], best, u[rows, best], v[rows, best]


@pytest.mark.parametrize("builder", ["binned", "sweep", "lbvh", "hlbvh2", "ploc", "sbvh"])
@pytest.mark.parametrize("layout", ["bvh2", "bvh4", "bvh8"])
def test_make_world_trace_matches_brute_force(rng, builder, layout):
    vertices, triangles = random_soup(rng, 250)
    world = rayforge.make_world(vertices, triangles, builder=builder, layout=layout, threads=2)
    rays = random_rays(rng, 1500)
    got = world.trace(rays)
    t, prim, u, v = closest_of(vertices, triangles, rays)
    hit = np.isfinite(t)
    got_hit = np.isfinite(got["t_hit"])
    assert (got_hit == hit).mean() > 0.998
    both = hit & got_hit
    np.testing.assert_allclose(got["t_hit"][both], t[both], rtol=1e-5)
    same = got["primitive_ids"][both] == prim[both]
    assert same.mean() > 0.998
    np.testing.assert_allclose(got["primitive_uvs"][both][same], np.stack([u, v], 1)[both][same], atol=1e-4)
    assert np.array_equal(got["triangle_ids"][both], got["primitive_ids"][both])  # one mesh: flat index = local
    blocked = world.occluded(rays)
    assert blocked.dtype == np.bool_
    assert (blocked == got_hit).all()
    # tfar shorter than the hit: not occluded; tnear beyond every hit: no hit.
    short = world.occluded(rays, tfar=0.0)
    assert not short.any()


@pytest.mark.parametrize("structure", ["bvh", "kdtree", "grid", "grid-proximity", "brute"])
def test_every_structure_answers_the_same(rng, structure):
    vertices, triangles = icosphere(3)
    rays = random_rays(rng, 1000, scale=3.0)
    reference = rayforge.make_world(vertices, triangles).trace(rays)
    got = rayforge.make_world(vertices, triangles, structure=structure).trace(rays)
    hit = np.isfinite(reference["t_hit"])
    assert (np.isfinite(got["t_hit"]) == hit).mean() > 0.998
    both = hit & np.isfinite(got["t_hit"])
    np.testing.assert_allclose(got["t_hit"][both], reference["t_hit"][both], rtol=1e-5)


def test_world_properties_and_stats():
    vertices, triangles = icosphere(2, 2.0, (1.0, 0.0, 0.0))
    world = rayforge.make_world(vertices, triangles)
    assert world.device == "cpu" and not world.paged and not world.animated
    lo, hi = world.bounds
    np.testing.assert_allclose(lo, (-1.0, -2.0, -2.0), atol=1e-5)
    np.testing.assert_allclose(hi, (3.0, 2.0, 2.0), atol=1e-5)
    assert world.stats()["last_commit"] == "none"
    s = world.commit()
    assert s["triangles"] == len(triangles) and s["last_commit"] == "build" and s["nodes"] > 0
    assert s["sah_cost"] > 0 and s["accel"]
    cam = world.camera()
    assert isinstance(cam, rayforge.Camera)


def test_set_vertices_refits_and_answers_for_the_new_positions(rng):
    vertices, triangles = icosphere(2)
    world = rayforge.make_world(vertices, triangles, update="refit")
    world.commit()
    rays = random_rays(rng, 800, scale=4.0)
    moved = (vertices * 1.5 + np.array([0.3, -0.2, 0.1], np.float32)).astype(np.float32)
    u = world.set_vertices(0, moved)
    assert u["updated"]
    assert world.stats()["last_commit"] in ("update", "none", "build")
    got = world.trace(rays)
    t, prim, _, _ = closest_of(moved, triangles, rays)
    hit = np.isfinite(t)
    assert (np.isfinite(got["t_hit"]) == hit).mean() > 0.998
    both = hit & np.isfinite(got["t_hit"])
    np.testing.assert_allclose(got["t_hit"][both], t[both], rtol=1e-5)
    assert world.stats()["update_method"] == "refit"


def test_animated_world_follows_time():
    world = rayforge.open_world("builtin:explode@20k#3", update="refit")
    assert world.animated
    start, end, fps = world.time_range
    assert end > start and fps > 0
    rays = random_rays(np.random.default_rng(1), 500, scale=3.0)
    before = world.trace(rays)["t_hit"]
    u = world.set_time(0.5 * (start + end))
    assert u["updated"] and world.time == pytest.approx(0.5 * (start + end))
    after = world.trace(rays)["t_hit"]
    assert not np.array_equal(np.isfinite(before), np.isfinite(after)) or not np.allclose(
        before[np.isfinite(before)], after[np.isfinite(before)])
    # The world's answer after the move equals a fresh world opened at that time.
    fresh = rayforge.open_world("builtin:explode@20k#3")
    fresh.set_time(0.5 * (start + end))
    np.testing.assert_allclose(fresh.trace(rays)["t_hit"], after, rtol=1e-5)


def test_open_world_scene_file_and_builtin():
    world = rayforge.open_world("builtin:cornell")
    assert world.stats()["triangles"] > 0
    data = os.environ.get("RAYFORGE_TEST_DATA") or os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data")
    cube = rayforge.open_world(os.path.join(data, "obj", "cube.obj"))
    assert cube.stats()["triangles"] == 12
    # A malformed file is one rayforge.Error naming the file and line.
    with pytest.raises(rayforge.Error, match=r"bad_face\.obj:4: bad vertex index in face"):
        rayforge.open_world(os.path.join(data, "obj", "bad_face.obj"))


def test_build_bvh_is_a_valid_tree(rng):
    vertices, triangles = random_soup(rng, 500)
    for builder in ["binned", "sweep", "lbvh", "hlbvh2", "ploc"]:
        bvh = rayforge.build_bvh(vertices, triangles, builder=builder, leaf_size=4)
        nodes, prims = bvh["nodes"], bvh["prim_indices"]
        assert nodes.dtype.names == ("lo", "hi", "first", "count")
        assert nodes.dtype.itemsize == 32
        assert sorted(prims.tolist()) == list(range(len(triangles)))
        tri = vertices[triangles]
        # Every node's box holds its subtree's triangles; every triangle sits in exactly one leaf.
        seen = np.zeros(len(triangles), int)
        stack = [0]
        inner = 0
        while stack:
            i = stack.pop()
            lo, hi = nodes["lo"][i], nodes["hi"][i]
            if nodes["count"][i] == 0:
                inner += 1
                for c in (nodes["first"][i], nodes["first"][i] + 1):
                    assert np.all(nodes["lo"][c] >= lo - 1e-6) and np.all(nodes["hi"][c] <= hi + 1e-6)
                    stack.append(c)
            else:
                first, count = nodes["first"][i], nodes["count"][i]
                assert count <= 4
                for p in prims[first:first + count]:
                    seen[p] += 1
                    assert np.all(tri[p].min(axis=0) >= lo - 1e-6) and np.all(tri[p].max(axis=0) <= hi + 1e-6)
        assert np.all(seen == 1)
        assert bvh["leaves"] == len(nodes) - inner
        # The SAH cost as documented: sum over inner A/A_root + sum over leaves A/A_root * count.
        ext = nodes["hi"] - nodes["lo"]
        area = ext[:, 0] * ext[:, 1] + ext[:, 1] * ext[:, 2] + ext[:, 2] * ext[:, 0]
        weight = np.where(nodes["count"] == 0, 1, nodes["count"])
        reachable = np.zeros(len(nodes), bool)
        stack = [0]
        while stack:
            i = stack.pop()
            reachable[i] = True
            if nodes["count"][i] == 0:
                stack += [nodes["first"][i], nodes["first"][i] + 1]
        cost = float(np.sum((area * weight)[reachable]) / area[0])
        assert bvh["sah_cost"] == pytest.approx(cost, rel=1e-4)


def test_build_bvh_sah_builders_beat_morton_ones(rng):
    vertices, triangles = random_soup(rng, 2000)
    binned = rayforge.build_bvh(vertices, triangles, builder="sweep")["sah_cost"]
    lbvh = rayforge.build_bvh(vertices, triangles, builder="lbvh")["sah_cost"]
    assert binned < lbvh


def test_concurrent_traces_on_one_world(rng):
    vertices, triangles = random_soup(rng, 400)
    world = rayforge.make_world(vertices, triangles)
    world.commit()
    rays = random_rays(rng, 4000)
    expected = world.trace(rays)["t_hit"]
    results = [None] * 4

    def work(k):
        results[k] = world.trace(rays)["t_hit"]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        np.testing.assert_array_equal(r, expected)


def test_paged_world_from_a_converted_file(tmp_path):
    cli = os.environ.get("RAYFORGE_CLI")
    if not cli:
        pytest.skip("RAYFORGE_CLI not set (run through ctest)")
    pack = tmp_path / "spheres.rfpack"
    subprocess.run([cli, "convert", "builtin:spheres", "-o", str(pack)], check=True, capture_output=True)
    paged = rayforge.open_world(str(pack), memory_budget="64M")
    assert paged.paged
    in_core = rayforge.open_world("builtin:spheres")
    rays = random_rays(np.random.default_rng(5), 2000, scale=12.0)
    a, b = paged.trace(rays), in_core.trace(rays)
    hit = np.isfinite(b["t_hit"])
    assert (np.isfinite(a["t_hit"]) == hit).mean() > 0.998
    both = hit & np.isfinite(a["t_hit"])
    # Paged vertices are quantised (about 1e-5 of the scene's extent).
    np.testing.assert_allclose(a["t_hit"][both], b["t_hit"][both], rtol=1e-4, atol=2e-3)
    # The paged file keeps no input ids: triangle_ids is the paged id, geometry_ids
    # the file's instance (the spheres share a mesh, paged once and placed by
    # instances; the ground is a world-space page), primitive ids unknown.
    assert np.all(a["primitive_ids"] == 0xFFFFFFFF)
    assert np.all(a["geometry_ids"][~np.isfinite(a["t_hit"])] == 0xFFFFFFFF)
    instanced = a["geometry_ids"][both] != 0xFFFFFFFF
    assert instanced.any() and (~instanced).any()
    # Hits on the same in-core instance of a sphere land on one paged instance.
    sphere = (b["geometry_ids"][both] != b["geometry_ids"][both][~instanced][0]) & instanced
    pairs = set(zip(b["geometry_ids"][both][sphere].tolist(), a["geometry_ids"][both][sphere].tolist()))
    assert len(pairs) == len({p[0] for p in pairs})
    assert np.all(a["triangle_ids"][both] != 0xFFFFFFFF)
    assert np.all(np.isnan(a["primitive_normals"][both]))
    np.testing.assert_array_equal(paged.occluded(rays), np.isfinite(a["t_hit"]))
    with pytest.raises(ValueError, match="set_vertices"):
        paged.set_vertices(0, np.zeros((3, 3), np.float32))
