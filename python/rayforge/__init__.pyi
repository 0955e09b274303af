"""Type stubs of the rayforge package (the extension rayforge._rayforge). See docs/python.md."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

class Error(RuntimeError):
    """An error of the engine (a file, an option, a budget, a device): its message is one line."""

def cuda_backend_built() -> bool:
    """Whether this build contains the CUDA backend."""

def devices() -> List[str]:
    """The devices this process can use: 'cpu', then 'cuda:N' for each CUDA device."""

class Camera:
    """A perspective camera: eye, target, up and the vertical field of view in degrees."""

    eye: Tuple[float, float, float]
    target: Tuple[float, float, float]
    up: Tuple[float, float, float]
    fov: float
    aperture_radius: float
    focus_distance: float
    def __init__(
        self,
        eye: Sequence[float] = ...,
        target: Sequence[float] = ...,
        up: Sequence[float] = ...,
        fov: float = 45.0,
    ) -> None: ...
    @staticmethod
    def parse(text: str) -> "Camera":
        """The CLI's --camera form 'ex,ey,ez,tx,ty,tz,ux,uy,uz,fov'; ValueError otherwise."""

class World:
    """A scene with its triangles and acceleration structure on one device, kept current as time moves.

    Made by open_world or make_world (docs/world.md)."""

    @property
    def device(self) -> str: ...
    @property
    def paged(self) -> bool: ...
    @property
    def animated(self) -> bool: ...
    @property
    def time(self) -> float: ...
    @property
    def time_range(self) -> Tuple[float, float, float]:
        """(start, end, frames per second) of the animation."""
    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]: ...
    @property
    def notes(self) -> List[str]:
        """Defaults the device replaced (a scene file's update method), one line each."""
    def camera(self) -> Camera:
        """The scene's own camera at the current time (or one framing it)."""
    def stats(self) -> Dict[str, Any]:
        """triangles, host_bytes, device_bytes, load_ms, last_commit, commit_ms, commits, accel, sah_cost, nodes, update_method."""
    def commit(self) -> Dict[str, Any]:
        """Builds the structure now (otherwise at the first query or renderer); returns stats()."""
    def set_time(self, t: float) -> Dict[str, Any]:
        """Moves an animated world to time t in seconds; the structure follows. Returns updated, update_ms, layout_ms, sah_cost."""
    def set_vertices(self, mesh: int, positions: npt.ArrayLike) -> Dict[str, Any]:
        """New (n, 3) vertex positions for one mesh; the structure follows by the world's update method."""
    def trace(self, rays: npt.ArrayLike, tnear: float = 0.0, tfar: float = ...) -> Dict[str, np.ndarray]:
        """Closest hits of (..., 6) rays: t_hit, geometry_ids, primitive_ids, primitive_uvs, primitive_normals, triangle_ids."""
    def occluded(self, rays: npt.ArrayLike, tnear: float = 0.0, tfar: float = ...) -> np.ndarray:
        """Whether anything lies on each ray between tnear and tfar (bool, the rays' leading shape)."""
    def trace_on_device(self, rays: Any, hits: Any, *, stream: Optional[int] = None) -> None:
        """Closest hits of CUDA-resident rays (n, 8) float32 [ox, oy, oz, tmin, dx, dy, dz, tmax] written into
        CUDA-resident hits (n, 4) [t, u, v, prim as uint32 bits]: objects with __cuda_array_interface__ or __dlpack__."""
    def occluded_on_device(self, rays: Any, occluded: Any, *, stream: Optional[int] = None) -> None:
        """Any hits of CUDA-resident rays into CUDA-resident occluded (n,) uint8 or bool."""

def open_world(
    path: str,
    *,
    device: str = "cpu",
    structure: str = "bvh",
    builder: str = "binned",
    layout: str = "bvh8",
    gpu_kernel: Optional[str] = None,
    update: Optional[str] = None,
    threads: int = 0,
    memory_budget: Optional[str] = None,
    animation: str = "",
) -> World:
    """Opens a scene file (.obj, .ply, .gltf, .glb, .aff, .json), builtin:NAME or a paged .rfpack as a World."""

def make_world(
    vertices: npt.ArrayLike,
    triangles: npt.ArrayLike,
    *,
    normals: Optional[npt.ArrayLike] = None,
    uvs: Optional[npt.ArrayLike] = None,
    material_ids: Optional[npt.ArrayLike] = None,
    materials: Optional[List[Dict[str, Any]]] = None,
    environment: Optional[Sequence[float]] = None,
    device: str = "cpu",
    structure: str = "bvh",
    builder: str = "binned",
    layout: str = "bvh8",
    gpu_kernel: Optional[str] = None,
    update: Optional[str] = None,
    threads: int = 0,
) -> World:
    """A World of one mesh from numpy arrays (vertices (n, 3) float32, triangles (m, 3) integers)."""

def load_mesh(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """A scene file or builtin:NAME as one world-space mesh: (vertices (n, 3) float32, triangles (m, 3) uint32)."""

def build_bvh(
    vertices: npt.ArrayLike, triangles: npt.ArrayLike, *, builder: str = "binned", leaf_size: int = 4, threads: int = 0
) -> Dict[str, Any]:
    """The canonical binary BVH of a builder: nodes (structured: lo, hi, first, count), prim_indices, sah_cost, leaves."""

class Renderer:
    """A progressive renderer of a World on the world's device; options are the CLI's render options."""

    def __init__(self, world: World, camera: Optional[Camera] = None, **options: Any) -> None: ...
    @property
    def passes(self) -> int: ...
    @property
    def device(self) -> str: ...
    def render_pass(self) -> bool:
        """Adds one sample per pixel (the GIL is released meanwhile)."""
    def render(self) -> np.ndarray:
        """Runs passes until spp are done (or time_budget is spent) and returns the image."""
    def image(self) -> np.ndarray:
        """The mean of the passes: float32 (height, width, 3), linear radiance."""
    def albedo(self) -> np.ndarray: ...
    def normal(self) -> np.ndarray: ...
    def depth(self) -> np.ndarray: ...
    def set_camera(self, camera: Camera) -> None: ...
    def set_options(self, **options: Any) -> None: ...
    def stats(self) -> Dict[str, Any]: ...

def write_image(path: str, image: npt.ArrayLike, *, exposure: float = 1.0, tonemap: str = "clamp") -> None:
    """Writes a float (height, width, 3) image: .png (exposure, tone curve, sRGB), .exr or .pfm (linear)."""

class RaycastingScene:
    """Ray queries with Open3D 0.18's RaycastingScene interface; numpy arrays in and out.

    cast_rays and test_occlusions run on `device`; the other queries run on the CPU."""

    INVALID_ID: int
    def __init__(self, nthreads: int = 0, *, device: str = "cpu", builder: str = "binned", layout: str = "bvh8") -> None: ...
    @property
    def device(self) -> str: ...
    @property
    def geometry_count(self) -> int: ...
    def add_triangles(self, vertex_positions: npt.ArrayLike, triangle_indices: npt.ArrayLike) -> int:
        """Adds a mesh (vertex_positions (n, 3) float32, triangle_indices (m, 3) uint32); returns its geometry id."""
    def refit(self, geometry_id: int, vertex_positions: npt.ArrayLike) -> None:
        """New vertex positions for a geometry (same count): the structure is refitted, not rebuilt."""
    def cast_rays(self, rays: npt.ArrayLike, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """t_hit, geometry_ids, primitive_ids, primitive_uvs, primitive_normals of (..., 6) rays."""
    def test_occlusions(
        self, rays: npt.ArrayLike, tnear: float = 0.0, tfar: float = ..., nthreads: int = 0
    ) -> np.ndarray: ...
    def cast_rays_on_device(self, rays: Any, hits: Any, *, stream: Optional[int] = None) -> None:
        """Beyond Open3D: World.trace_on_device for a scene made with device='cuda'."""
    def test_occlusions_on_device(self, rays: Any, occluded: Any, *, stream: Optional[int] = None) -> None:
        """Beyond Open3D: World.occluded_on_device for a scene made with device='cuda'."""
    def count_intersections(self, rays: npt.ArrayLike, nthreads: int = 0) -> np.ndarray:
        """int32: hits along each ray (a crossing of a shared edge or vertex counted once)."""
    def list_intersections(self, rays: npt.ArrayLike, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """ray_splits, ray_ids, t_hit, geometry_ids, primitive_ids, primitive_uvs of every hit, sorted by t per ray."""
    def compute_closest_points(self, query_points: npt.ArrayLike, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """points, geometry_ids, primitive_ids, primitive_uvs, primitive_normals of (..., 3) points."""
    def compute_distance(self, query_points: npt.ArrayLike, nthreads: int = 0) -> np.ndarray: ...
    def compute_signed_distance(
        self, query_points: npt.ArrayLike, nthreads: int = 0, nsamples: int = 1, sign: str = "winding"
    ) -> np.ndarray:
        """Distance, negative inside: sign='winding' (generalised winding number >= 1/2) or 'parity' (Open3D's)."""
    def compute_occupancy(
        self, query_points: npt.ArrayLike, nthreads: int = 0, nsamples: int = 1, sign: str = "winding"
    ) -> np.ndarray:
        """1.0 inside, 0.0 outside (float32)."""
