"""rayforge.RaycastingScene against numpy brute force: every query, the shapes
and dtypes of Open3D 0.18's interface, the tie rule along shared edges,
signed distances on open meshes, refit, threads, and errors."""

import threading

import numpy as np
import pytest

import rayforge
from conftest import brute_force_distance, brute_force_hits, icosphere, random_rays, random_soup


def test_cast_rays_matches_brute_force(rng):
    vertices, triangles = random_soup(rng, 300)
    scene = rayforge.RaycastingScene()
    assert scene.add_triangles(vertices, triangles) == 0
    rays = random_rays(rng, 2000)
    got = scene.cast_rays(rays)
    t, _, _ = brute_force_hits(vertices, triangles, rays)
    expected_t = t.min(axis=1)
    expected_prim = t.argmin(axis=1)
    hit = np.isfinite(expected_t)
    agree = np.isfinite(got["t_hit"]) == hit
    assert agree.mean() > 0.999  # a ray grazing an edge may go either way between the two tests
    both = hit & np.isfinite(got["t_hit"])
    np.testing.assert_allclose(got["t_hit"][both], expected_t[both], rtol=1e-5)
    assert (got["primitive_ids"][both] == expected_prim[both]).mean() > 0.999
    assert np.all(got["geometry_ids"][both] == 0)
    assert np.all(got["geometry_ids"][~np.isfinite(got["t_hit"])] == rayforge.RaycastingScene.INVALID_ID)
    assert got["t_hit"].dtype == np.float32 and got["primitive_ids"].dtype == np.uint32
    assert got["primitive_uvs"].shape == (2000, 2) and got["primitive_normals"].shape == (2000, 3)
    # The normal is the hit triangle's unit geometric normal.
    i = np.nonzero(both)[0][0]
    a, b, c = vertices[triangles[got["primitive_ids"][i]]]
    n = np.cross(b - a, c - a)
    np.testing.assert_allclose(got["primitive_normals"][i], n / np.linalg.norm(n), atol=1e-5)


def test_leading_dimensions_are_kept(sphere_scene):
    scene, _, _ = sphere_scene
    rays = np.zeros((4, 5, 6), np.float32)
    rays[..., 2] = 3.0
    rays[..., 5] = -1.0
    got = scene.cast_rays(rays)
    assert got["t_hit"].shape == (4, 5)
    assert got["primitive_uvs"].shape == (4, 5, 2)
    np.testing.assert_allclose(got["t_hit"], 2.0, rtol=1e-3)
    assert scene.test_occlusions(rays).shape == (4, 5)
    assert scene.count_intersections(rays).shape == (4, 5)
    assert scene.compute_distance(rays[..., :3]).shape == (4, 5)
    assert scene.compute_closest_points(rays[..., :3])["points"].shape == (4, 5, 3)


def test_geometry_ids_of_several_meshes():
    scene = rayforge.RaycastingScene()
    a_v, a_t = icosphere(1, 0.5, (-2.0, 0.0, 0.0))
    b_v, b_t = icosphere(1, 0.5, (2.0, 0.0, 0.0))
    assert scene.add_triangles(a_v, a_t) == 0
    assert scene.add_triangles(b_v, b_t) == 1
    rays = np.array([[-2, 0, 5, 0, 0, -1], [2, 0, 5, 0, 0, -1], [0, 0, 5, 0, 0, -1]], np.float32)
    got = scene.cast_rays(rays)
    assert list(got["geometry_ids"]) == [0, 1, rayforge.RaycastingScene.INVALID_ID]
    assert got["primitive_ids"][0] < len(a_t) and got["primitive_ids"][1] < len(b_t)


def test_occlusions_respect_tnear_and_tfar(sphere_scene):
    scene, _, _ = sphere_scene
    rays = np.array([[0, 0, 5, 0, 0, -1]] * 3, np.float32)  # the sphere's surface at t = 4 and 6
    assert scene.test_occlusions(rays).tolist() == [True, True, True]
    assert scene.test_occlusions(rays, tfar=3.9).tolist() == [False] * 3
    assert scene.test_occlusions(rays, tnear=6.1).tolist() == [False] * 3
    assert scene.test_occlusions(rays, tnear=4.5, tfar=7.0).tolist() == [True] * 3
    assert scene.test_occlusions(rays).dtype == np.bool_


def test_count_and_list_intersections_match_brute_force(rng):
    vertices, triangles = random_soup(rng, 150)
    scene = rayforge.RaycastingScene()
    scene.add_triangles(vertices, triangles)
    rays = random_rays(rng, 500)
    t, _, _ = brute_force_hits(vertices, triangles, rays)
    expected = np.isfinite(t).sum(axis=1)
    counts = scene.count_intersections(rays)
    assert counts.dtype == np.int32
    assert (counts == expected).mean() > 0.995
    listed = scene.list_intersections(rays)
    splits = listed["ray_splits"]
    assert len(splits) == len(rays) + 1 and splits[0] == 0
    np.testing.assert_array_equal(np.diff(splits), counts)
    for r in range(0, len(rays), 17):
        lo, hi = splits[r], splits[r + 1]
        assert np.all(listed["ray_ids"][lo:hi] == r)
        ts = listed["t_hit"][lo:hi]
        assert np.all(np.diff(ts) >= 0)  # sorted along the ray
        if counts[r] == expected[r]:
            np.testing.assert_allclose(ts, np.sort(t[r][np.isfinite(t[r])]), rtol=1e-5)
            np.testing.assert_array_equal(np.sort(listed["primitive_ids"][lo:hi]), np.nonzero(np.isfinite(t[r]))[0])


def test_a_ray_through_a_shared_edge_or_vertex_crosses_once():
    # Two triangles sharing the edge x = 0, and a fan sharing a vertex at the origin.
    quad_v = np.array([[-1, -1, 0], [0, -1, 0], [0, 1, 0], [-1, 1, 0], [1, -1, 0], [1, 1, 0]], np.float32)
    quad_t = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]], np.uint32)
    scene = rayforge.RaycastingScene()
    scene.add_triangles(quad_v, quad_t)
    edge = np.array([[0, 0.25, 1, 0, 0, -1]], np.float32)  # straight through the shared edge x = 0
    vertex = np.array([[0, 1, 1, 0, 0, -1]], np.float32)  # through the vertex (0, 1) of three triangles
    assert scene.count_intersections(edge).tolist() == [1]
    assert scene.count_intersections(vertex).tolist() == [1]
    assert len(scene.list_intersections(edge)["t_hit"]) == 1
    # A closed sphere: a ray through a vertex of the mesh crosses it twice, in and out.
    vertices, triangles = icosphere(1)
    sphere = rayforge.RaycastingScene()
    sphere.add_triangles(vertices, triangles)
    through_vertex = np.array([np.concatenate([vertices[0] * 3.0, -vertices[0]])], np.float32)
    assert sphere.count_intersections(through_vertex).tolist() == [2]


def test_closest_points_and_distance_match_brute_force(rng):
    vertices, triangles = random_soup(rng, 200)
    scene = rayforge.RaycastingScene()
    scene.add_triangles(vertices, triangles)
    points = rng.uniform(-1.5, 1.5, size=(1000, 3)).astype(np.float32)
    expected, which = brute_force_distance(vertices, triangles, points)
    got = scene.compute_closest_points(points)
    distance = np.linalg.norm(got["points"] - points, axis=1)
    np.testing.assert_allclose(distance, expected, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(scene.compute_distance(points), expected, rtol=1e-4, atol=1e-6)
    assert (got["primitive_ids"] == which).mean() > 0.99  # ties between triangles at one distance
    # The point lies on its triangle, at its barycentrics.
    for i in range(0, 1000, 97):
        a, b, c = vertices[triangles[got["primitive_ids"][i]]].astype(np.float64)
        u, v = got["primitive_uvs"][i]
        np.testing.assert_allclose(a + u * (b - a) + v * (c - a), got["points"][i], atol=1e-4)


def test_signed_distance_and_occupancy_of_a_closed_sphere(sphere_scene):
    scene, _, _ = sphere_scene
    points = np.array([[0, 0, 0], [0.5, 0.2, 0.1], [2, 0, 0], [0, -3, 0]], np.float32)
    for sign in ("winding", "parity"):
        d = scene.compute_signed_distance(points, sign=sign)
        assert d[0] < 0 and d[1] < 0 and d[2] > 0 and d[3] > 0, sign
        np.testing.assert_allclose(abs(d), [1.0, 1 - np.linalg.norm(points[1]), 1.0, 2.0], atol=0.03)
        assert scene.compute_occupancy(points, sign=sign).tolist() == [1.0, 1.0, 0.0, 0.0]
    assert scene.compute_occupancy(points).dtype == np.float32


def test_the_winding_sign_is_right_where_parity_fails():
    # A sphere with a hole: rays through the hole count one crossing, so parity calls
    # inside points outside along them; the winding number stays near 1 inside.
    vertices, triangles = icosphere(3)
    centers = vertices[triangles].mean(axis=1)
    keep = centers[:, 2] < 0.9  # a cap cut off the top
    holed = triangles[keep]
    scene = rayforge.RaycastingScene()
    scene.add_triangles(vertices, holed)
    inside = np.array([[0, 0, z] for z in np.linspace(-0.8, 0.8, 9)], np.float32)
    outside = np.array([[0, 0, 1.5], [1.5, 0, 0], [0, -1.6, 0.3]], np.float32)
    assert np.all(scene.compute_signed_distance(inside) < 0)
    assert np.all(scene.compute_signed_distance(outside) > 0)
    assert np.all(scene.compute_occupancy(inside) == 1.0)
    # Parity along one fixed ray, through the hole from the axis points: wrong for some.
    parity = scene.compute_occupancy(inside, sign="parity", nsamples=1)
    winding = scene.compute_occupancy(inside)
    assert np.all(winding == 1.0)
    # The first parity direction is nearly +z: from the axis points above z = -0.5 it
    # leaves through the hole without a crossing, so parity calls them outside.
    assert np.count_nonzero(parity == 0.0) >= 5, parity


def test_refit_moves_the_geometry(sphere_scene):
    scene, vertices, _ = sphere_scene
    ray = np.array([[5, 0, 0, -1, 0, 0]], np.float32)
    np.testing.assert_allclose(scene.cast_rays(ray)["t_hit"], [4.0], rtol=1e-3)
    moved = vertices + np.array([1.0, 0, 0], np.float32)
    scene.refit(0, moved)
    np.testing.assert_allclose(scene.cast_rays(ray)["t_hit"], [3.0], rtol=1e-3)
    # The centre, now at x = 1: the faces of the tessellated unit sphere are a little closer than 1.
    np.testing.assert_allclose(scene.compute_distance(np.array([[1, 0, 0]], np.float32)), [1.0], rtol=3e-2)
    with pytest.raises(ValueError, match="vertex_positions"):
        scene.refit(0, moved[:-1])
    with pytest.raises(ValueError, match="geometry_id"):
        scene.refit(3, moved)


def test_results_do_not_depend_on_the_thread_count(rng):
    vertices, triangles = random_soup(rng, 300)
    scene = rayforge.RaycastingScene()
    scene.add_triangles(vertices, triangles)
    rays = random_rays(rng, 3000)
    points = rays[:, :3].copy()
    one = scene.cast_rays(rays, nthreads=1)
    two = scene.cast_rays(rays, nthreads=2)
    for key in one:
        np.testing.assert_array_equal(one[key], two[key])
    np.testing.assert_array_equal(scene.compute_signed_distance(points, nthreads=1),
                                  scene.compute_signed_distance(points, nthreads=2))


def cuda_available():
    return rayforge.cuda_backend_built() and any(d.startswith("cuda") for d in rayforge.devices())


@pytest.mark.parametrize("device", ["cpu", "cuda"])
def test_queries_from_several_python_threads(rng, device):
    # On CUDA each host batch has its own device buffers and stream (concurrent calls share none).
    if device == "cuda" and not cuda_available():
        pytest.skip("no CUDA device")
    vertices, triangles = icosphere(3)
    scene = rayforge.RaycastingScene(device=device)
    scene.add_triangles(vertices, triangles)
    rays = random_rays(rng, 4000)
    points = rays[:, :3].copy()
    expected_t = scene.cast_rays(rays)["t_hit"]
    expected_d = scene.compute_distance(points)
    failures = []

    def worker(k):
        try:
            for _ in range(5):
                if k % 2:
                    np.testing.assert_array_equal(scene.cast_rays(rays)["t_hit"], expected_t)
                else:
                    np.testing.assert_array_equal(scene.compute_distance(points), expected_d)
        except Exception as e:  # noqa: BLE001 - reported below
            failures.append(e)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures, failures


def test_errors_name_the_argument():
    scene = rayforge.RaycastingScene()
    with pytest.raises(ValueError, match="add_triangles first"):
        scene.cast_rays(np.zeros((1, 6), np.float32))
    v, t = icosphere(0)
    with pytest.raises(ValueError, match=r"vertex_positions: expected an array of shape \(\.\.\., 3\)"):
        scene.add_triangles(v[:, :2], t)
    with pytest.raises(TypeError, match="triangle_indices: expected integer indices"):
        scene.add_triangles(v, t.astype(np.float32))
    with pytest.raises(ValueError, match="triangle_indices: triangle 0 has index 99"):
        scene.add_triangles(v, np.array([[0, 1, 99]], np.uint32))
    bad = v.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="vertex_positions: row 3 is not finite"):
        scene.add_triangles(bad, t)
    scene.add_triangles(v, t)
    with pytest.raises(ValueError, match=r"rays: expected an array of shape \(\.\.\., 6\), got \(3, 5\)"):
        scene.cast_rays(np.zeros((3, 5), np.float32))
    with pytest.raises(TypeError, match="rays: expected float32"):
        scene.cast_rays(np.zeros((3, 6), np.int64))
    with pytest.raises(ValueError, match="nsamples"):
        scene.compute_signed_distance(np.zeros((1, 3), np.float32), nsamples=2, sign="parity")
    with pytest.raises(ValueError, match="sign"):
        scene.compute_occupancy(np.zeros((1, 3), np.float32), sign="majority")
    with pytest.raises(ValueError, match="nthreads"):
        scene.cast_rays(np.zeros((1, 6), np.float32), nthreads=-1)
    with pytest.raises(ValueError, match="device"):
        rayforge.RaycastingScene(device="gpu")
    with pytest.raises(ValueError, match="builder"):
        rayforge.RaycastingScene(builder="fastest")
    # float64 is accepted (converted), NaN rays hit nothing.
    rays = np.array([[0, 0, 5, 0, 0, -1], [np.nan, 0, 5, 0, 0, -1]], np.float64)
    got = scene.cast_rays(rays)
    assert np.isfinite(got["t_hit"][0]) and np.isinf(got["t_hit"][1])


def test_cuda_device_is_refused_or_used(rng):
    if cuda_available():
        vertices, triangles = icosphere(3)
        scene = rayforge.RaycastingScene(device="cuda")
        assert scene.device == "cuda:0"
        scene.add_triangles(vertices, triangles)
        on_cpu = rayforge.RaycastingScene()
        on_cpu.add_triangles(vertices, triangles)
        rays = random_rays(rng, 20000)
        a, b = scene.cast_rays(rays), on_cpu.cast_rays(rays)
        hit = np.isfinite(b["t_hit"])
        assert (np.isfinite(a["t_hit"]) == hit).mean() > 0.999
        both = hit & np.isfinite(a["t_hit"])
        np.testing.assert_allclose(a["t_hit"][both], b["t_hit"][both], rtol=1e-5)
        assert (scene.test_occlusions(rays) == on_cpu.test_occlusions(rays)).mean() > 0.999
        return
    with pytest.raises(rayforge.Error):
        rayforge.RaycastingScene(device="cuda")
