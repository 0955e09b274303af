"""CUDA device arrays in place (__cuda_array_interface__, __dlpack__): World.trace_on_device,
occluded_on_device and RaycastingScene.cast_rays_on_device, test_occlusions_on_device.

Without a device: the argument checks on fake interfaces, and the one clear error of a CPU world.
With one (rayforge._DeviceBuffer, built with CUDA): the answers equal the host batches', through
both interfaces."""

import numpy as np
import pytest

import rayforge
from conftest import icosphere, random_rays


class FakeCudaArray:
    """An object with a __cuda_array_interface__ and no memory behind it (never dereferenced:
    the checks, or the CPU world's refusal, come first)."""

    def __init__(self, shape, typestr="<f4", readonly=False, strides=None, **extra):
        self.__cuda_array_interface__ = dict(shape=tuple(shape), typestr=typestr, data=(0xDEAD0000, readonly),
                                             strides=strides, version=3, **extra)


def cuda_available():
    return rayforge.cuda_backend_built() and any(d.startswith("cuda") for d in rayforge.devices())


def engine_rays(rays6):
    """(n, 6) rays as the engine's (n, 8) [ox, oy, oz, tmin, dx, dy, dz, tmax]."""
    n = len(rays6)
    out = np.empty((n, 8), np.float32)
    out[:, 0:3], out[:, 3], out[:, 4:7], out[:, 7] = rays6[:, 0:3], 0.0, rays6[:, 3:6], np.inf
    return out


@pytest.fixture
def cpu_world():
    vertices, triangles = icosphere(1)
    return rayforge.make_world(vertices, triangles)


def test_a_cpu_world_refuses_device_batches(cpu_world):
    with pytest.raises(rayforge.Error, match="runs on the CPU"):
        cpu_world.trace_on_device(FakeCudaArray((5, 8)), FakeCudaArray((5, 4)))
    with pytest.raises(rayforge.Error, match="runs on the CPU"):
        cpu_world.occluded_on_device(FakeCudaArray((5, 8)), FakeCudaArray((5,), "|u1"))
    scene = rayforge.RaycastingScene()
    scene.add_triangles(*icosphere(1))
    with pytest.raises(rayforge.Error, match="runs on the CPU"):
        scene.cast_rays_on_device(FakeCudaArray((5, 8)), FakeCudaArray((5, 4), "<u4"))


def test_device_array_arguments_are_checked(cpu_world):
    w = cpu_world
    with pytest.raises(ValueError, match=r"rays: expected shape \(n, 8\)"):
        w.trace_on_device(FakeCudaArray((5, 6)), FakeCudaArray((5, 4)))
    with pytest.raises(TypeError, match="rays: expected float32"):
        w.trace_on_device(FakeCudaArray((5, 8), "<f8"), FakeCudaArray((5, 4)))
    with pytest.raises(ValueError, match=r"hits: expected shape \(5, 4\), got \(4, 4\)"):
        w.trace_on_device(FakeCudaArray((5, 8)), FakeCudaArray((4, 4)))
    with pytest.raises(TypeError, match="hits: expected 4-byte elements"):
        w.trace_on_device(FakeCudaArray((5, 8)), FakeCudaArray((5, 4), "<f2"))
    with pytest.raises(ValueError, match="hits: the array is read-only"):
        w.trace_on_device(FakeCudaArray((5, 8)), FakeCudaArray((5, 4), readonly=True))
    with pytest.raises(ValueError, match="rays: expected a C-contiguous array"):
        w.trace_on_device(FakeCudaArray((5, 8), strides=(64, 4)), FakeCudaArray((5, 4)))
    with pytest.raises(ValueError, match="masked"):
        w.trace_on_device(FakeCudaArray((5, 8), mask=object()), FakeCudaArray((5, 4)))
    with pytest.raises(ValueError, match="stream 0 is ambiguous"):
        w.trace_on_device(FakeCudaArray((5, 8), stream=0), FakeCudaArray((5, 4)))
    with pytest.raises(TypeError, match="occluded: expected uint8 or bool"):
        w.occluded_on_device(FakeCudaArray((5, 8)), FakeCudaArray((5,), "<f4"))
    with pytest.raises(TypeError, match="malformed typestr"):
        w.trace_on_device(FakeCudaArray((5, 8), "<fx"), FakeCudaArray((5, 4)))
    # Host memory: numpy speaks DLPack, on the CPU; a list speaks neither.
    with pytest.raises(ValueError, match="the CPU: pass numpy arrays to the host batches"):
        w.trace_on_device(np.zeros((5, 8), np.float32), FakeCudaArray((5, 4)))
    with pytest.raises(TypeError, match="expected a CUDA device array"):
        w.trace_on_device([[0.0] * 8] * 5, FakeCudaArray((5, 4)))


@pytest.mark.skipif(not cuda_available(), reason="no CUDA device")
@pytest.mark.parametrize("interface", ["cuda_array_interface", "dlpack"])
def test_device_batches_equal_host_batches(rng, interface):
    vertices, triangles = icosphere(3)
    world = rayforge.make_world(vertices, triangles, device="cuda")
    rays6 = random_rays(rng, 50000)
    expected = world.trace(rays6)
    expected_blocked = world.occluded(rays6)

    class DlpackOnly:
        """Hides the buffer's __cuda_array_interface__, so the DLPack path is the one taken."""

        def __init__(self, buffer):
            self.buffer = buffer

        def __dlpack__(self, stream=None):
            return self.buffer.__dlpack__(stream=stream)

        def __dlpack_device__(self):
            return self.buffer.__dlpack_device__()

    wrap = (lambda b: b) if interface == "cuda_array_interface" else DlpackOnly
    rays = rayforge._DeviceBuffer(engine_rays(rays6))
    hits = rayforge._DeviceBuffer(np.zeros((len(rays6), 4), np.float32))
    blocked = rayforge._DeviceBuffer(np.zeros(len(rays6), np.uint8))
    world.trace_on_device(wrap(rays), wrap(hits))
    world.occluded_on_device(wrap(rays), wrap(blocked))
    out = hits.numpy()
    t = np.where(out[:, 3].view(np.uint32) == 0xFFFFFFFF, np.inf, out[:, 0])
    np.testing.assert_array_equal(t, expected["t_hit"])
    prim = out[:, 3].view(np.uint32)
    np.testing.assert_array_equal(prim, expected["triangle_ids"])
    np.testing.assert_array_equal(blocked.numpy().astype(bool), expected_blocked)

    scene = rayforge.RaycastingScene(device="cuda")
    scene.add_triangles(vertices, triangles)
    hits2 = rayforge._DeviceBuffer(np.zeros((len(rays6), 4), np.uint32))
    scene.cast_rays_on_device(wrap(rays), wrap(hits2))
    np.testing.assert_array_equal(hits2.numpy()[:, 3], expected["triangle_ids"])
