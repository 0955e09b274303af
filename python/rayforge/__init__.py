"""rayforge: a ray tracing engine for large scenes on CPUs and NVIDIA GPUs.

Ray queries with Open3D's RaycastingScene interface (and more: CUDA devices,
builders, refit), the engine's worlds (scenes with their acceleration
structures, moved through time), a progressive renderer and image output,
from numpy arrays. See docs/python.md.
"""

from ._rayforge import (  # noqa: F401
    Camera,
    Error,
    RaycastingScene,
    Renderer,
    World,
    __version__,
    build_bvh,
    cuda_backend_built,
    devices,
    load_mesh,
    make_world,
    open_world,
    write_image,
)

__all__ = [
    "Camera",
    "Error",
    "RaycastingScene",
    "Renderer",
    "World",
    "__version__",
    "build_bvh",
    "cuda_backend_built",
    "devices",
    "load_mesh",
    "make_world",
    "open_world",
    "write_image",
]
