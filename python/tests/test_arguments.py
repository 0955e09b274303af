"""Randomized arguments (hypothesis): arrays of any shape, dtype, memory layout
and content, and odd scalars, into every entry point. Each call either
succeeds with outputs of the documented shapes or raises ValueError,
TypeError or rayforge.Error; nothing crashes the interpreter."""

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

import rayforge  # noqa: E402
from conftest import icosphere  # noqa: E402

EXPECTED = (ValueError, TypeError, rayforge.Error, OverflowError)
SETTINGS = settings(max_examples=150, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

dtypes = st.sampled_from([np.float32, np.float64, np.float16, np.int32, np.int64, np.uint32, np.uint8, np.bool_,
                          np.complex64])
shapes = hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=7)
floats = st.floats(allow_nan=True, allow_infinity=True, width=32)


@st.composite
def arrays(draw, last=None):
    dtype = draw(dtypes)
    shape = draw(shapes)
    if last is not None and draw(st.booleans()):
        shape = tuple(shape[:-1]) + (last,) if shape else (last,)
    if np.issubdtype(dtype, np.floating) or np.issubdtype(dtype, np.complexfloating):
        elements = st.floats(allow_nan=True, allow_infinity=True, width=16 if dtype == np.float16 else 32)
    else:
        elements = None
    a = draw(hnp.arrays(dtype, shape, elements=elements))
    if a.ndim >= 2 and draw(st.booleans()):
        a = np.swapaxes(a, 0, 1)  # not C-contiguous
    return a


odd_values = st.one_of(st.none(), st.integers(-5, 5), st.text(max_size=5), st.lists(floats, max_size=7),
                       st.just(object()))


@pytest.fixture(scope="module")
def scene():
    v, t = icosphere(1)
    s = rayforge.RaycastingScene(nthreads=2)
    s.add_triangles(v, t)
    return s


@SETTINGS
@given(rays=st.one_of(arrays(last=6), odd_values), tnear=floats, tfar=floats, nthreads=st.integers(-2, 3))
def test_ray_queries(scene, rays, tnear, tfar, nthreads):
    for call in (lambda: scene.cast_rays(rays, nthreads=nthreads),
                 lambda: scene.test_occlusions(rays, tnear=tnear, tfar=tfar, nthreads=nthreads),
                 lambda: scene.count_intersections(rays, nthreads=nthreads),
                 lambda: scene.list_intersections(rays, nthreads=nthreads)):
        try:
            out = call()
        except EXPECTED:
            continue
        leading = np.shape(rays)[:-1]
        if isinstance(out, dict) and "t_hit" in out and "ray_splits" not in out:
            assert out["t_hit"].shape == leading
        elif not isinstance(out, dict):
            assert out.shape == leading


@SETTINGS
@given(points=st.one_of(arrays(last=3), odd_values), nsamples=st.integers(-1, 4),
       sign=st.sampled_from(["winding", "parity", "x"]))
def test_point_queries(scene, points, nsamples, sign):
    for call in (lambda: scene.compute_closest_points(points),
                 lambda: scene.compute_distance(points),
                 lambda: scene.compute_signed_distance(points, nsamples=nsamples, sign=sign),
                 lambda: scene.compute_occupancy(points, nsamples=nsamples, sign=sign)):
        try:
            out = call()
        except EXPECTED:
            continue
        leading = np.shape(points)[:-1]
        assert (out["points"] if isinstance(out, dict) else out).shape[:len(leading)] == leading


@SETTINGS
@given(vertices=st.one_of(arrays(last=3), odd_values), triangles=st.one_of(arrays(last=3), odd_values))
def test_meshes(vertices, triangles):
    s = rayforge.RaycastingScene()
    try:
        s.add_triangles(vertices, triangles)
    except EXPECTED:
        pass
    try:
        rayforge.make_world(vertices, triangles)
    except EXPECTED:
        pass
    try:
        rayforge.build_bvh(vertices, triangles, leaf_size=4)
    except EXPECTED:
        pass


@SETTINGS
@given(device=st.text(max_size=8) | st.sampled_from(["cpu", "cuda", "cuda:1", "cuda:-1", "cuda:99999999999"]),
       builder=st.text(max_size=6) | st.sampled_from(["binned", "ploc", "gridbvh"]),
       layout=st.text(max_size=5) | st.sampled_from(["bvh2", "bvh8"]),
       leaf=st.integers(-3, 100), threads=st.integers(-3, 3))
def test_options(device, builder, layout, leaf, threads):
    v, t = icosphere(0)
    for call in (lambda: rayforge.make_world(v, t, device=device, builder=builder, layout=layout, threads=threads),
                 lambda: rayforge.RaycastingScene(threads, device=device, builder=builder, layout=layout),
                 lambda: rayforge.build_bvh(v, t, builder=builder, leaf_size=leaf, threads=threads),
                 lambda: rayforge.Camera.parse(device + "," + builder)):
        try:
            call()
        except EXPECTED:
            pass


@SETTINGS
@given(options=st.dictionaries(st.sampled_from(["width", "height", "spp", "integrator", "max_depth", "seed",
                                                "clamp", "ao_samples", "bogus"]),
                               st.one_of(st.integers(-3, 40), st.text(max_size=4), st.floats(width=32)),
                               max_size=4))
def test_renderer_options(options):
    world = rayforge.open_world("builtin:triangle")
    options.setdefault("width", 8)
    options.setdefault("height", 6)
    if isinstance(options["width"], int) and isinstance(options["height"], int):
        if options["width"] * options["height"] > 2000:
            options["width"] = 8
    try:
        r = rayforge.Renderer(world, **options)
        r.render_pass()
    except EXPECTED:
        pass


@st.composite
def cuda_interfaces(draw):
    """Fake __cuda_array_interface__ dicts, well formed or not (their memory is never read:
    the checks or the CPU world's refusal come first)."""
    class Fake:
        pass

    fake = Fake()
    interface = {
        "shape": draw(st.one_of(st.tuples(st.integers(-2, 9)), st.tuples(st.integers(-2, 9), st.integers(-2, 9)),
                                odd_values)),
        "typestr": draw(st.one_of(st.sampled_from(["<f4", "<u4", "|u1", "|b1", "<f8", ">f4", "<f", "x"]), odd_values)),
        "data": draw(st.one_of(st.tuples(st.integers(0, 2**40), st.booleans()), odd_values)),
        "version": 3,
    }
    if draw(st.booleans()):
        interface["strides"] = draw(st.one_of(st.none(), st.tuples(st.integers(-8, 64), st.integers(-8, 64)), odd_values))
    if draw(st.booleans()):
        interface["stream"] = draw(st.one_of(st.none(), st.integers(-1, 3), odd_values))
    fake.__cuda_array_interface__ = draw(st.one_of(st.just(interface), odd_values))
    return fake


@SETTINGS
@given(rays=st.one_of(cuda_interfaces(), arrays(last=8), odd_values),
       out=st.one_of(cuda_interfaces(), arrays(last=4), odd_values), stream=st.one_of(st.none(), st.integers(-1, 3)))
def test_device_array_queries_on_a_cpu_world(scene, rays, out, stream):
    # A CPU scene: every call ends in one of the expected errors, whatever the arguments.
    for call in (lambda: scene.cast_rays_on_device(rays, out, stream=stream),
                 lambda: scene.test_occlusions_on_device(rays, out, stream=stream)):
        with pytest.raises(EXPECTED):
            call()
